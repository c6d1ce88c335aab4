"""`intermask generate` with MoMask runs: single-person samples from tiny untrained run folders."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from hydra.utils import instantiate

from intermask import generate as gen
from intermask.cli import main
from intermask.generate import momask as momask_job
from intermask.momask.load import load_momask_sampler
from intermask.momask.sampler import MoMaskDecoding
from intermask.motion import humanml3d as hml
from intermask.utils.files import file_hash
from intermask.utils.fingerprint import weights_digest
from tests.momask.momask_tiny import (
    CODES,
    LAYERS,
    TEXT,
    TINY,
    VQ_NET,
    make_mask_net,
    make_residual_net,
    save_run,
)

CAPTION = "a person walks forward"


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Untrained tiny runs: a HumanML3D tokenizer with statistics, a masked transformer and a
    residual transformer trained (in name) on it, and a two-person Inter-M run config."""
    root = tmp_path_factory.mktemp("momask_runs")
    torch.manual_seed(0)
    vq = instantiate(VQ_NET)
    generator = torch.Generator().manual_seed(1)
    mean = torch.randn(hml.FEATURE_DIM, generator=generator) * 0.1
    std = torch.rand(hml.FEATURE_DIM, generator=generator) + 0.5
    vq.view.set_statistics(mean, std)
    vq.train()(torch.randn(4, 64, hml.FEATURE_DIM))  # initialise the codebooks from data
    vq.eval()
    vq_run = save_run(root / "vq", {"model": {"net": VQ_NET}}, vq.state_dict())
    vq_ckpt = str(vq_run / "checkpoints" / "last.ckpt")
    hyper = {"codebook_size": CODES, "text_dim": 64, "vq_digest": weights_digest(vq)}

    def config(module: str, net: str) -> dict:
        return {
            "vq_ckpt": vq_ckpt,
            "data": {"dataset": "humanml3d"},
            "text": TEXT,
            "model": {
                "_target_": f"intermask.momask.module.{module}",
                "net": {"_target_": f"intermask.momask.model.{net}", "_partial_": True, **TINY},
            },
        }

    mask = save_run(
        root / "mask",
        config("MaskTransformerModule", "MaskedTransformer"),
        make_mask_net().state_dict(),
        **hyper,
    )
    residual = save_run(
        root / "residual",
        config("ResidualTransformerModule", "ResidualTransformer"),
        make_residual_net().state_dict(),
        num_quantizers=LAYERS,
        **hyper,
    )
    interm = root / "interm"
    (interm / "checkpoints").mkdir(parents=True)
    (interm / "checkpoints" / "last.ckpt").write_bytes(b"")  # only its config is read
    model = {"_target_": "intermask.interm.module.InterMModule"}
    (interm / "config.yaml").write_text(yaml.safe_dump({"model": model}))
    return {"vq": vq_run, "mask": mask, "residual": residual, "interm": interm}


def _generate(runs: dict[str, Path], out: Path, *options: str, residual: bool = True) -> int:
    argv = ["generate", "--checkpoint", str(runs["mask"]), "--out", str(out), *options]
    if residual:
        argv += ["--residual", str(runs["residual"])]
    return main(argv)


def test_samples_hold_one_person_decoded_from_the_seeded_sampler(runs, tmp_path, capsys):
    argv = ["--text", CAPTION, "--seconds", "1.9", "--samples", "2", "--seed", "5", "--no-render"]
    assert _generate(runs, tmp_path, *argv) == 0, capsys.readouterr().err
    folders = sorted(tmp_path.iterdir())
    assert [f.name for f in folders] == [
        "a_person_walks_forward_00-00",
        "a_person_walks_forward_00-01",
    ]
    sampler, _ = load_momask_sampler(runs["mask"], runs["residual"])
    for k, folder in enumerate(folders):
        assert sorted(p.name for p in folder.iterdir()) == [
            "features.npy",
            "joints.npy",
            "sample.json",
        ]
        features, joints = np.load(folder / "features.npy"), np.load(folder / "joints.npy")
        assert features.shape == (1, 36, 263) and features.dtype == np.float32  # 38 -> 36 frames
        assert joints.shape == (36, 1, 22, 3) and joints.dtype == np.float32
        # the sampler's normalized output, de-normalized with the tokenizer's statistics
        generator = torch.Generator().manual_seed(5 + k)
        out = sampler([CAPTION], torch.tensor([36]), generator=generator)
        expected = sampler.vq.view.denormalize(out.features)
        np.testing.assert_allclose(features, expected.numpy(), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(
            joints[:, 0], hml.recover_from_ric(torch.from_numpy(features[0])).numpy(), atol=1e-5
        )
        assert (out.tokens[:, 1:] >= 0).all()  # the residual layers were predicted
    first, second = (np.load(f / "joints.npy") for f in folders)
    assert not np.array_equal(first, second)  # each sample its own seed
    printed = capsys.readouterr().out
    assert "MoMask (base + residual layers), 36 frames (1.8 s), seed 6" in printed


def test_the_record_names_the_checkpoints_settings_and_rate(runs, tmp_path, capsys):
    argv = ["--text", CAPTION, "--length-frames", "20", "--cfg-scale", "3", "--no-render"]
    argv += [
        "--iterations",
        "4",
        "--residual-temperature",
        "0.5",
        "--top-k",
        "0.5",
        "--device",
        "cpu",
    ]
    assert _generate(runs, tmp_path, *argv) == 0, capsys.readouterr().err
    (folder,) = tmp_path.iterdir()
    record = json.loads((folder / "sample.json").read_text())
    last = {role: runs[role] / "checkpoints" / "last.ckpt" for role in ("mask", "residual", "vq")}
    assert record == {
        "caption": CAPTION,
        "mode": "text_to_motion",
        "model": "momask",
        "sample": 0,
        "seed": 0,
        "frames": 20,
        "fps": 20.0,
        "settings": {
            "iterations": 4,
            "mask_cfg_scale": 3.0,
            "residual_cfg_scale": 5.0,
            "top_k_ratio": 0.5,
            "temperature": 1.0,
            "residual_temperature": 0.5,
            "schedule": "paper",
            "noise": "per_sample",
        },
        "mask": {"path": str(last["mask"]), "sha256": file_hash(last["mask"])},
        "residual": {"path": str(last["residual"]), "sha256": file_hash(last["residual"])},
        "vq": {"path": str(last["vq"]), "sha256": file_hash(last["vq"])},
        "text_encoder": record["text_encoder"],
    }
    assert "intermask-tiny-text" in record["text_encoder"]


def test_a_seed_reproduces_its_sample_whatever_was_generated_with_it(runs, tmp_path, capsys):
    common = ["--seconds", "1", "--no-render"]
    assert _generate(runs, tmp_path / "a", "--text", CAPTION, "--samples", "3", *common) == 0
    again = ["--text", "someone jumps", "--text", CAPTION, "--seed", "1", *common]
    assert _generate(runs, tmp_path / "b", *again) == 0, capsys.readouterr().err
    first = np.load(tmp_path / "a" / "a_person_walks_forward_00-02" / "joints.npy")  # seed 2
    second = np.load(tmp_path / "b" / "a_person_walks_forward_01-00" / "joints.npy")  # 1 + 1
    np.testing.assert_array_equal(first, second)
    records = [
        json.loads((tmp_path / f / "sample.json").read_text())
        for f in (
            "a/a_person_walks_forward_00-02",
            "b/a_person_walks_forward_01-00",
            "b/someone_jumps_00-00",
        )
    ]
    assert [(r["caption"], r["seed"]) for r in records] == [
        (CAPTION, 2),
        (CAPTION, 2),
        ("someone jumps", 1),
    ]


def test_without_a_residual_run_the_base_layer_alone_is_decoded(runs, tmp_path, capsys):
    argv = ["--text", CAPTION, "--seconds", "1", "--no-render"]
    assert _generate(runs, tmp_path, *argv, residual=False) == 0, capsys.readouterr().err
    (folder,) = tmp_path.iterdir()
    record = json.loads((folder / "sample.json").read_text())
    assert record["residual"] is None and record["settings"]["iterations"] == 10
    sampler, paths = load_momask_sampler(runs["mask"])
    assert set(paths) == {"mask", "vq"}
    out = sampler([CAPTION], torch.tensor([20]), generator=torch.Generator().manual_seed(0))
    assert (out.tokens[:, 1:] == -1).all()
    expected = sampler.vq.view.denormalize(out.features).numpy()
    np.testing.assert_allclose(np.load(folder / "features.npy"), expected, rtol=1e-5, atol=1e-6)
    assert "MoMask (base layer), 20 frames (1.0 s)" in capsys.readouterr().out


def test_renders_show_the_one_person_at_20_fps(runs, tmp_path, capsys):
    argv = ["--text", CAPTION, "--length-frames", "12", "--iterations", "2"]
    assert _generate(runs, tmp_path, *argv) == 0, capsys.readouterr().err
    (folder,) = tmp_path.iterdir()
    for name in ("animation.gif", "animation.mp4", "viewer.html"):
        assert (folder / name).stat().st_size > 1000
    from PIL import Image

    with Image.open(folder / "animation.gif") as gif:
        assert gif.n_frames == 12 and gif.info["duration"] == 50  # 20 fps
    page = (folder / "viewer.html").read_text()
    assert '"fps":20.0,"frames":12,"persons":1,"reference":null' in page


def test_the_defaults_are_momask_s_humanml3d_settings():
    defaults = gen.default_settings()
    assert defaults["momask"] == {
        "iterations": 10,
        "mask_cfg_scale": 4.0,
        "residual_cfg_scale": 5.0,
        "top_k_ratio": 0.1,
        "temperature": 1.0,
        "residual_temperature": 0.0,
        "schedule": "paper",
        "noise": "per_sample",
    }
    assert defaults["momask_fps"] == float(hml.FPS)
    settings = momask_job.settings(gen.Request(checkpoint="run"), defaults)
    assert settings == momask_job.Settings(MoMaskDecoding(**defaults["momask"]), float(hml.FPS))
    given = gen.Request(checkpoint="run", sampler={"cfg_scale": 3.0, "iterations": 4}, fps=25.0)
    assert momask_job.settings(given, defaults) == momask_job.Settings(
        MoMaskDecoding(**{**defaults["momask"], "mask_cfg_scale": 3.0, "iterations": 4}), 25.0
    )
    assert gen.MAX_FRAMES["humanml3d"] == 196


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("--persons", "in_turn"),
        ("--schedule", "reference"),
        ("--noise", "reference"),
        ("--reaction", "person1.npy"),
        ("--batch-size", "8"),
    ],
)
def test_two_person_options_are_refused_with_a_momask_run(runs, tmp_path, capsys, option, value):
    code = _generate(runs, tmp_path, "--text", CAPTION, option, value)
    assert code == 2
    err = capsys.readouterr().err
    assert f"error: {option} does not apply to a MoMask run: --checkpoint {runs['mask']}" in err
    assert not tmp_path.exists() or not any(tmp_path.iterdir())


def test_edit_options_are_refused_with_a_momask_run(runs, tmp_path):
    request = gen.Request(
        checkpoint=str(runs["mask"]), text=[CAPTION], edit="pair.npy", frames_range=(0, 8)
    )
    with pytest.raises(ValueError, match=r"^--edit does not apply to a MoMask run"):
        gen.run(request)
    with pytest.raises(ValueError, match=r"^--person does not apply to a MoMask run"):
        gen.run(gen.Request(checkpoint=str(runs["mask"]), text=[CAPTION], person=2))


def test_bf16_decoding_is_refused_with_a_momask_run(runs, tmp_path, capsys):
    code = _generate(runs, tmp_path, "--text", CAPTION, "--precision", "bf16")
    assert code == 2
    err = capsys.readouterr().err
    assert (
        f"error: --precision bf16: MoMask runs decode in fp32 only (--checkpoint {runs['mask']})"
        in err
    )
    assert not tmp_path.exists() or not any(tmp_path.iterdir())


def test_run_kinds_are_checked(runs, tmp_path):
    mask, residual, interm = (str(runs[k]) for k in ("mask", "residual", "interm"))
    with pytest.raises(ValueError) as error:
        gen.run(gen.Request(checkpoint=interm, residual=residual, text=[CAPTION]))
    assert str(error.value) == (
        f"--residual applies to MoMask runs only; --checkpoint {interm} is not a MoMask masked "
        "transformer run (its model is intermask.interm.module.InterMModule)"
    )
    with pytest.raises(ValueError, match="^--residual-temperature applies to MoMask runs only"):
        gen.run(
            gen.Request(checkpoint=interm, sampler={"residual_temperature": 1.0}, text=[CAPTION])
        )
    with pytest.raises(ValueError) as error:
        gen.run(gen.Request(checkpoint=residual, text=[CAPTION]))
    assert str(error.value) == (
        f"--checkpoint {residual}: a MoMask residual transformer run; pass the masked "
        "transformer run as --checkpoint and this one as --residual"
    )
    with pytest.raises(ValueError) as error:
        gen.run(gen.Request(checkpoint=mask, residual=mask, text=[CAPTION]))
    assert str(error.value) == (
        f"--residual {mask}: not a MoMask residual transformer run (its model is "
        "intermask.momask.module.MaskTransformerModule, not "
        "intermask.momask.module.ResidualTransformerModule)"
    )
    with pytest.raises(FileNotFoundError, match="nope: generator checkpoint not found"):
        gen.run(gen.Request(checkpoint=mask, residual=str(tmp_path / "nope"), text=[CAPTION]))


def test_captions_and_lengths_are_checked_before_loading(runs, tmp_path, monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("the networks were loaded")

    monkeypatch.setattr(momask_job, "load_momask_sampler", never)
    mask = str(runs["mask"])
    with pytest.raises(ValueError, match=r"give captions with --text or --prompts \(one of them\)"):
        gen.run(gen.Request(checkpoint=mask, out=tmp_path))
    with pytest.raises(
        ValueError,
        match=r"length 200 frames is out of range: .*8\.\.196 frames \(9\.8 s at 20 fps\)",
    ):
        gen.run(gen.Request(checkpoint=mask, text=[CAPTION], seconds=10.0, out=tmp_path))
    (tmp_path / "a_person_walks_forward_00-00").mkdir()
    with pytest.raises(
        FileExistsError, match="a_person_walks_forward_00-00: a sample folder already exists"
    ):
        gen.run(gen.Request(checkpoint=mask, text=[CAPTION], out=tmp_path))


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--residual-cfg-scale", "-1", "expected a finite number >= 0, got -1"),
        ("--residual-temperature", "nan", "expected a finite number >= 0, got nan"),
    ],
)
def test_cli_checks_the_momask_numbers_before_any_work(tmp_path, capsys, option, value, message):
    argv = ["generate", "--checkpoint", str(tmp_path / "nope.ckpt"), "--text", "hi"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, option, value])
    assert exit_info.value.code == 2
    assert f"argument {option}: {message}" in capsys.readouterr().err
