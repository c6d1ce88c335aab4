"""The MoMask model configs compose with a training job and build their modules."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf

from intermask.momask.module import MaskTransformerModule, ResidualTransformerModule
from intermask.train import CONFIG_DIR
from tests.momask.momask_tiny import make_vq


def _compose(name: str):
    overrides = [
        "~model/gen@model",
        f"+model/momask@model={name}",
        "text=tiny_random",
        "vq_ckpt=runs/vq/checkpoints/last.ckpt",
        "paths.output_dir=runs/x",
    ]
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose("train_gen", overrides=overrides)


@pytest.mark.parametrize("name", ["mask", "residual"])
def test_paper_configs_hold_the_paper_values(name):
    model = OmegaConf.to_container(_compose(name).model, resolve=True)
    assert {key: model["net"][key] for key in ("width", "depth", "heads", "ff", "dropout")} == {
        "width": 384,
        "depth": 6,
        "heads": 6,
        "ff": 1024,
        "dropout": 0.2,
    }
    assert model["optimizer"]["lr"] == 2.0e-4 and model["condition_drop"] == 0.1
    assert model["vq_ckpt"] == "runs/vq/checkpoints/last.ckpt"


@pytest.mark.parametrize(
    ("name", "kind"),
    [("mask_demo", MaskTransformerModule), ("residual_demo", ResidualTransformerModule)],
)
def test_demo_configs_build_cpu_sized_modules(name, kind, text_cache):
    cfg = _compose(name)
    assert cfg.model.net.width == 128 and cfg.model.net.depth == 4
    vq = make_vq()
    module = instantiate(cfg.model, text=text_cache, vq=vq, vq_ckpt=None)
    assert isinstance(module, kind)
    assert module.net.codebook_size == 16 and module.net.text_dim == 64  # from the VQ and text
    assert module.vq is vq and sum(p.numel() for p in module.parameters()) < 2_000_000
