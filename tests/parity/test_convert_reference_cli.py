"""``intermask convert-reference`` as users run it: the console script in a fresh process, from
another working directory, on a release laid out as the authors publish it (rebuilt from the
parity fixture at reduced widths); a failure at any point leaves no output behind."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from fixtures_io import load_fixture
from intermask_release import _generator_options, write_release

from intermask.convert import convert_reference

CONSOLE = Path(sys.executable).parent / "intermask"


def _convert(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    environment = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    return subprocess.run(
        [str(CONSOLE), "convert-reference", *args],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_console_script_converts_a_release_in_a_fresh_process(release, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    done = _convert(elsewhere, "--vq", str(release["vq_interx"]), "--generator",
                    str(release["generator"]), "--out", "converted")  # fmt: skip
    assert done.returncode == 0, done.stderr
    out = elsewhere / "converted"
    assert f"generator run: {Path('converted') / 'gen'}" in done.stdout
    assert "computed here (1): position_enc.positional_encoding.inv_freq" in done.stdout
    vq_keys = len(load_fixture("intermask_models")["vq_interx"]["recipe"])  # all of them
    assert f"vq: loaded {vq_keys} tensor(s) from the release" in done.stdout
    assert sorted(p.name for p in out.iterdir()) == ["gen", "vq"]
    stored = torch.load(out / "gen" / "checkpoints" / "last.ckpt", weights_only=True)
    assert stored["hyper_parameters"]["reference_options"]["n_heads"] == "6"
    config = (out / "gen" / "config.yaml").read_text()
    assert f"vq_ckpt: {out / 'vq' / 'checkpoints' / 'last.ckpt'}" in config
    assert "heads: 6" in config and "width: 96" in config


def test_a_failing_second_model_leaves_no_output(release, tmp_path):
    """The generator's opt.txt asks for 7 heads over 96 channels: refused, nothing written."""
    bad = release["generator"].parent.parent.parent / "bad_generator"
    state = torch.load(release["generator"], weights_only=True)["t2m_transformer"]
    write_release(bad, "t2m_transformer", state, {**_generator_options(6), "n_heads": "7"})
    done = _convert(tmp_path, "--vq", str(release["vq_interx"]), "--generator",
                    str(bad / "model" / "net_best_fid.tar"), "--out", "out")  # fmt: skip
    assert done.returncode == 2
    assert "n_heads: 7 (7 heads do not divide latent_dim 96)" in done.stderr
    assert "Traceback" not in done.stderr
    assert sorted(os.listdir(tmp_path)) == []


def test_a_write_that_fails_on_the_second_run_folder_leaves_nothing_and_a_rerun_works(
    release, tmp_path, monkeypatch
):
    """The disk fills while the generator's checkpoint is written: the tokenizer's run folder,
    already complete in the staging folder, does not appear either."""
    import intermask.convert as convert

    writes = []
    real_save = convert.atomic_torch_save

    def full_disk_on_second(payload, path):
        writes.append(path)
        if len(writes) == 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real_save(payload, path)

    monkeypatch.setattr(convert, "atomic_torch_save", full_disk_on_second)
    out = tmp_path / "out"
    with pytest.raises(OSError, match="No space left on device"):
        convert_reference(vq=release["vq_interx"], generator=release["generator"], out=out)
    assert [path.parent.parent.name for path in writes] == ["vq", "gen"]
    assert sorted(os.listdir(tmp_path)) == []  # no out, no staging folder
    monkeypatch.setattr(convert, "atomic_torch_save", real_save)
    done = convert_reference(vq=release["vq_interx"], generator=release["generator"], out=out)
    assert (done.gen_run / "checkpoints" / "last.ckpt").is_file()
    assert sorted(os.listdir(tmp_path)) == ["out"]
