"""The train_gen job end to end: a tiny tokenizer run, then Inter-M on its frozen tokens."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import open_dict
from test_train_vq import _config as vq_config
from test_train_vq import _last

from intermask.train import CONFIG_DIR, train
from intermask.vq.load import load_vq


@pytest.fixture(scope="module")
def vq_checkpoint(synthetic_interhuman_root, tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("vq_run")
    train(vq_config(synthetic_interhuman_root, run))
    return run / "checkpoints" / "last.ckpt"


def _gen_config(
    data_root: Path,
    vq_ckpt: Path,
    output_dir: Path,
    data: str = "synthetic",
    extra: tuple[str, ...] = (),
):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "train_gen",
            overrides=[
                f"data={data}",
                f"data.root={data_root}",
                "debug=gen",
                f"text.cache_dir={output_dir / 'text_cache'}",
                f"vq_ckpt={vq_ckpt}",
                *extra,
            ],
        )
    with open_dict(cfg):
        cfg.paths.output_dir = str(output_dir)
    return cfg


def test_train_gen_learns_on_frozen_tokens(synthetic_interhuman_root, vq_checkpoint, tmp_path):
    vq_before = load_vq(vq_checkpoint).state_dict()
    metrics = train(_gen_config(synthetic_interhuman_root, vq_checkpoint, tmp_path))
    assert torch.isfinite(torch.tensor(metrics["val/loss"])) and metrics["val/loss"] > 0
    # validation decoded a few generated samples and logged their statistics next to the GT's
    for source in ("generated", "real"):
        assert 0.0 < metrics[f"val_samples/{source}_root_distance"] < 10.0
        assert metrics[f"val_samples/{source}_joint_speed"] > 0.0
    # two steps in, the captions tell the network almost nothing yet: CE near ln(32 codes)
    assert 2.5 < metrics["val/fully_masked_ce"] < 4.5
    assert abs(metrics["val/condition_gain"]) < 0.5
    # the GT skeleton is rigid; the decoded one of a barely trained VQ-VAE is not
    assert metrics["val_samples/real_bone_length_std"] < 1.0
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = next((tmp_path / "tensorboard").rglob("events.out.tfevents.*"))
    accumulator = EventAccumulator(str(events.parent))
    accumulator.Reload()
    assert "samples/two people shake hands" in accumulator.Tags()["images"]  # SampleAnimations
    checkpoint = _last(tmp_path)
    assert checkpoint["global_step"] == 2
    assert all(key.startswith("net.") for key in checkpoint["state_dict"])  # frozen parts stay out
    vq_after = load_vq(vq_checkpoint).state_dict()
    assert all(torch.equal(vq_before[key], vq_after[key]) for key in vq_before)


def test_train_gen_trains_under_cpu_bf16_autocast(
    synthetic_interhuman_root, vq_checkpoint, tmp_path
):
    """`precision: auto` picks bf16-mixed on a CPU with native bf16; the generator's first
    validation step once died there (the text cache stacked fp16 entries under CPU autocast)."""
    extra = ("trainer.accelerator=cpu", "trainer.precision=bf16-mixed")
    metrics = train(_gen_config(synthetic_interhuman_root, vq_checkpoint, tmp_path, extra=extra))
    assert torch.isfinite(torch.tensor(metrics["val/loss"])) and metrics["val/loss"] > 0
    record = json.loads((tmp_path / "run_record.json").read_text())
    assert record["precision"]["precision"] == "bf16-mixed"
    assert _last(tmp_path)["global_step"] == 2


def test_a_generator_with_code_vectors_loads_them_with_its_weights(
    synthetic_interhuman_root, vq_checkpoint, tmp_path
):
    from intermask.interm.load import load_generator

    config = _gen_config(
        synthetic_interhuman_root, vq_checkpoint, tmp_path, extra=("model.code_vectors=true",)
    )
    train(config)
    stored = _last(tmp_path)
    assert stored["hyper_parameters"]["code_dim"] == 16  # the debug tokenizer's code width
    loaded = load_generator(tmp_path)
    assert loaded.net.code_dim == 16
    base = loaded.vq.quantizer.layers[0].codebook
    torch.testing.assert_close(loaded.net.code_vectors[:32], base / base.pow(2).mean().sqrt())
    torch.testing.assert_close(loaded.net.code_vectors, stored["state_dict"]["net.code_vectors"])


def test_warmup_is_a_quarter_of_the_first_epoch():
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose("train_gen", overrides=["vq_ckpt=unused", "paths.output_dir=/tmp/unused"])
    assert cfg.model.warmup_fraction == pytest.approx(0.25 / 500)
    assert cfg.model.optimizer.weight_decay == 1e-5 and cfg.data.batch_size == 52
    assert cfg.model.net.width == 384 and cfg.model.net.depth == 6 and cfg.model.net.heads == 6


def test_load_vq_names_what_is_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.ckpt: VQ checkpoint not found"):
        load_vq(tmp_path / "nowhere.ckpt")
    lonely = tmp_path / "run" / "checkpoints" / "last.ckpt"
    lonely.parent.mkdir(parents=True)
    lonely.write_bytes(b"")
    with pytest.raises(
        FileNotFoundError, match=r"run/config.yaml: the run config of the VQ checkpoint is missing"
    ):
        load_vq(lonely)


def test_a_generator_refuses_a_tokenizer_it_was_not_trained_on(
    synthetic_interhuman_root, vq_checkpoint, tmp_path
):
    from types import SimpleNamespace

    from intermask.interm.load import check_vq_matches, load_generator

    train(_gen_config(synthetic_interhuman_root, vq_checkpoint, tmp_path / "gen"))
    loaded = load_generator(tmp_path / "gen")  # its own tokenizer: fine
    assert loaded.vq_checkpoint == vq_checkpoint
    # the network was built with the VQ's codebook size, which the checkpoint records
    assert loaded.net.codebook_size == loaded.vq.quantizer.codebook_size == 32
    gen_checkpoint = tmp_path / "gen" / "checkpoints" / "last.ckpt"
    stored = torch.load(gen_checkpoint, map_location="cpu", weights_only=True)
    del stored["hyper_parameters"]["codebook_size"]
    unsized = tmp_path / "unsized" / "checkpoints" / "last.ckpt"
    unsized.parent.mkdir(parents=True)
    torch.save(stored, unsized)
    (unsized.parent.parent / "config.yaml").write_text(
        (tmp_path / "gen" / "config.yaml").read_text()
    )
    with pytest.raises(
        ValueError,
        match=r"unsized/checkpoints/last.ckpt: its config leaves the "
        r"codebook size to the VQ-VAE, but the checkpoint records none",
    ):
        load_generator(unsized)
    # the same architecture with other weights (another run, or a later epoch of it)
    other_run = tmp_path / "other_vq"
    (other_run / "checkpoints").mkdir(parents=True)
    (other_run / "config.yaml").write_text(
        (vq_checkpoint.parent.parent / "config.yaml").read_text()
    )
    stored = torch.load(vq_checkpoint, map_location="cpu", weights_only=True)
    codebook = next(k for k in stored["state_dict"] if "codebook" in k)
    stored["state_dict"][codebook] = stored["state_dict"][codebook] + 0.5
    torch.save(stored, other_run / "checkpoints" / "last.ckpt")
    with pytest.raises(ValueError, match=r"last.ckpt: not the VQ-VAE .* was trained on"):
        load_generator(tmp_path / "gen", vq_checkpoint=other_run / "checkpoints" / "last.ckpt")
    # another codebook size or token layout
    for codes, rows in ((64, 5), (32, 1)):
        net = SimpleNamespace(codebook_size=codes, rows=rows)
        with pytest.raises(
            ValueError, match=rf"with 32 codes x 5 rows cannot decode .*{codes} codes x {rows} rows"
        ):
            check_vq_matches(net, loaded.vq, {}, Path("gen.ckpt"), vq_checkpoint)
    # resuming the run with the other tokenizer is refused too
    resume = _gen_config(
        synthetic_interhuman_root, other_run / "checkpoints" / "last.ckpt", tmp_path / "resumed"
    )
    with open_dict(resume):
        resume.ckpt_path = str(tmp_path / "gen" / "checkpoints" / "last.ckpt")
        resume.trainer.max_epochs = 2
    with pytest.raises(
        ValueError, match="the checkpoint was trained on the VQ-VAE with weights digest"
    ):
        train(resume)


def test_bad_data_is_reported_before_the_model_is_built(synthetic_interhuman_root, tmp_path):
    import shutil

    import numpy as np

    from intermask.data.errors import DataError

    root = tmp_path / "data"
    shutil.copytree(synthetic_interhuman_root, root)
    clip = (root / "split" / "train.txt").read_text().split()[0]
    broken = root / "motions_processed" / "person1" / f"{clip}.npy"
    motion = np.load(broken)
    motion[3, 5] = np.nan
    np.save(broken, motion)
    # the VQ checkpoint does not exist either: the model build would fail on it, so the data
    # error can only come first if the data is read before the model is built
    cfg = _gen_config(root, tmp_path / "missing_vq.ckpt", tmp_path / "run")
    with pytest.raises(DataError, match=rf"{clip}.npy"):
        train(cfg)
    assert not (tmp_path / "run" / "checkpoints").exists()


def test_the_interx_chain_trains_tokenizer_then_generator(synthetic_interx_root, tmp_path):
    """Inter-X end to end: its tokenizer (selected by reconstruction, no body model) and Inter-M
    on its tokens, each writing checkpoints."""
    train(vq_config(synthetic_interx_root, tmp_path / "vq", data="synthetic_interx"))
    vq_ckpt = tmp_path / "vq" / "checkpoints" / "last.ckpt"
    gen_cfg = _gen_config(synthetic_interx_root, vq_ckpt, tmp_path / "gen", data="synthetic_interx")
    metrics = train(gen_cfg)
    assert torch.isfinite(torch.tensor(metrics["val/loss"]))
    assert _last(tmp_path / "gen")["global_step"] == 2
