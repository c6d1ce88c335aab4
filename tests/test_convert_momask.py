"""``intermask convert-reference`` on a MoMask release, as users run it: the console script in a
fresh process, from another working directory, on a release laid out as the authors publish it
(rebuilt from the parity fixture at reduced widths). The run folders load into the sampler that
``intermask generate`` and the evaluation use; a failure at the last model leaves no output."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).parent / "parity"))
from fixtures_io import load_fixture  # noqa: E402
from test_parity_momask import FIXTURE, write_release  # noqa: E402

import intermask.convert_momask as convert_momask  # noqa: E402
from intermask.momask.load import load_momask_sampler  # noqa: E402

CONSOLE = Path(sys.executable).parent / "intermask"


@pytest.fixture(scope="module")
def case() -> dict:
    fixture = load_fixture(FIXTURE)
    return {"case": fixture["cases"]["small"], "seed": fixture["seed"]}


def _convert(cwd: Path, root: Path, paths: dict[str, Path]) -> subprocess.CompletedProcess:
    environment = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    environment["INTERMASK_ROOT"] = str(root)  # the runs' text cache, not the repository's
    arguments = ["--vq", paths["vq"], "--generator", paths["mask"], "--residual",
                 paths["residual"], "--out", "converted", "--text", "tiny_random"]  # fmt: skip
    return subprocess.run(
        [str(CONSOLE), "convert-reference", *map(str, arguments)],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_console_script_converts_a_momask_release_into_runs_that_generate(
    case, tmp_path, monkeypatch
):
    paths = write_release(tmp_path / "release", case["case"], case["seed"])
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    done = _convert(elsewhere, tmp_path, paths)
    assert done.returncode == 0, done.stderr
    out = elsewhere / "converted"
    assert sorted(p.name for p in out.iterdir()) == ["mask", "residual", "vq"]
    for name in ("vq", "mask", "residual"):
        assert f"{name} run: {Path('converted') / name}" in done.stdout
    assert "vq: loaded 70 tensor(s) from the release" in done.stdout
    assert "computed here (2): backbone.condition_projection.weight, backbone.positions.pe" \
        in done.stdout  # fmt: skip
    assert "computed here (4): layer_embedding.weight, backbone.condition_projection.weight" \
        in done.stdout  # fmt: skip
    stored = torch.load(out / "residual" / "checkpoints" / "last.ckpt", weights_only=True)
    assert stored["hyper_parameters"]["reference_options"]["share_weight"] == "True"
    assert stored["hyper_parameters"]["num_quantizers"] == 4
    config = (out / "mask" / "config.yaml").read_text()
    assert f"vq_ckpt: {out / 'vq' / 'checkpoints' / 'last.ckpt'}" in config
    assert "heads: 4" in config and "width: 64" in config and "bert_mask_prob: 0.88" in config

    monkeypatch.setenv("INTERMASK_ROOT", str(tmp_path))
    sampler, runs = load_momask_sampler(out / "mask", out / "residual")
    assert runs["vq"] == out / "vq" / "checkpoints" / "last.ckpt"
    sample = sampler(["a person walks."], torch.tensor([32]), generator=torch.Generator())
    assert tuple(sample.tokens.shape) == (1, 4, 1, 8)
    assert bool((sample.tokens >= 0).all()) and bool((sample.tokens < 64).all())
    assert tuple(sample.features.shape) == (1, 32, 263)
    assert bool(torch.isfinite(sample.features).all())


def test_a_failing_last_model_leaves_no_output(case, tmp_path):
    """The residual transformer's opt.txt asks for 5 heads over 64 channels: refused by name,
    after the tokenizer and the masked transformer converted; nothing is written."""
    residual = {**case["case"]["residual"]["options"], "n_heads": "5"}
    paths = write_release(tmp_path / "release", case["case"], case["seed"],
                          options={"residual": residual})  # fmt: skip
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    done = _convert(cwd, tmp_path, paths)
    assert done.returncode == 2
    assert "rtrans_small/opt.txt: option(s) this framework cannot build:" in done.stderr
    assert "n_heads: 5 (5 heads do not divide latent_dim 64)" in done.stderr
    assert "Traceback" not in done.stderr
    assert sorted(os.listdir(cwd)) == []


def test_a_write_that_fails_at_the_last_run_folder_leaves_nothing(case, tmp_path, monkeypatch):
    paths = write_release(tmp_path / "release", case["case"], case["seed"])
    monkeypatch.setenv("INTERMASK_ROOT", str(tmp_path))
    import intermask.convert as convert  # its write_run writes every converted run

    real_save = convert.atomic_torch_save

    def failing_save(payload, path):
        if Path(path).parent.parent.name == "residual":
            raise OSError(28, "No space left on device")
        real_save(payload, path)

    monkeypatch.setattr(convert, "atomic_torch_save", failing_save)
    out = tmp_path / "out"
    with pytest.raises(OSError, match="No space left on device"):
        convert_momask.convert_momask(vq=paths["vq"], mask=paths["mask"],
                                      residual=paths["residual"], out=out, text="tiny_random")  # fmt: skip
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["release"]
