"""The train_arflow job end to end on a small synthetic dataset, and its paper configuration."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import open_dict

from intermask.reaction import ARFlowModule, Guidance, ReactionDecoder, sample_reactions
from intermask.train import CONFIG_DIR, count_parameters, train


def _compose(overrides: list[str]):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose("train_arflow", overrides=[*overrides, "paths.output_dir=/tmp/unused"])


def _config(data: str, data_root: Path, output_dir: Path):
    cfg = _compose(
        [
            f"data={data}",
            f"data.root={data_root}",
            "debug=arflow",
            f"text.cache_dir={output_dir / 'text_cache'}",
        ]
    )
    with open_dict(cfg):
        cfg.paths.output_dir = str(output_dir)
    return cfg


def test_train_arflow_fits_checkpoints_and_samples(synthetic_interhuman_root, tmp_path):
    metrics = train(_config("synthetic", synthetic_interhuman_root, tmp_path))
    for name in ("val/loss", "val/reconstruction", "val/interaction", "train/loss"):
        assert torch.isfinite(torch.tensor(metrics[name])) and metrics[name] > 0
    for name in ("real_penetration", "generated_penetration", "guided_penetration"):
        assert metrics[f"val_samples/{name}"] >= 0
    assert 0 < metrics["val_samples/generated_mpjpe_mm"] < 5000
    checkpoint = torch.load(tmp_path / "checkpoints" / "last.ckpt", weights_only=True)
    assert checkpoint["global_step"] == 2
    state = checkpoint["state_dict"]
    # the trainable network and the feature statistics; the frozen text tower stays out
    assert {key.split(".")[0] for key in state} == {"net", "space"}
    assert float(state["space.std"].min()) > 0 and not torch.all(state["space.std"] == 1)

    # the checkpoint rebuilds a module that samples a validation batch
    cfg = _config("synthetic", synthetic_interhuman_root, tmp_path)
    module: ARFlowModule = instantiate(cfg.model)
    module.load_state_dict(state)
    datamodule = instantiate(cfg.data)
    datamodule.setup("validate")
    batch = next(iter(datamodule.val_dataloader()))
    sample = sample_reactions(module, batch, steps=2, guidance=Guidance(), seeds=[0, 1, 2, 3])
    assert sample.features.shape == (4, 40, 262) and sample.joints.shape == (4, 40, 2, 22, 3)
    assert torch.isfinite(sample.joints).all()


@pytest.mark.slow
def test_train_arflow_on_interx(synthetic_interx_root, tmp_path):
    metrics = train(_config("synthetic_interx", synthetic_interx_root, tmp_path))
    assert torch.isfinite(torch.tensor(metrics["val/loss"]))
    state = torch.load(tmp_path / "checkpoints" / "last.ckpt", weights_only=True)["state_dict"]
    assert state["space.std"].shape == (56, 6) and torch.all(state["space.std"] == 1)


def test_paper_setting():
    cfg = _compose(["experiment=arflow_interhuman"])
    net = cfg.model.net
    assert (net.width, net.depth, net.causal, net.feature_dim) == (512, 8, True, 262)
    assert cfg.model.text is None and net.text_dim is None  # unconstrained
    assert cfg.data.dataset == "interhuman" and cfg.data.batch_size == 32
    assert cfg.trainer.max_steps == 500_000 and cfg.model.lambda_inter == 1.0
    assert cfg.model.sample_steps == 5
    assert dict(cfg.model.guidance) == {
        "mode": "improved",
        "lambda_pene": 2.0,
        "zeta": 0.5,
        "w": 0.7,
        "beta": 0.0,
        "points_per_bone": 2,
    }
    total, trainable = count_parameters(instantiate(cfg.model))
    assert total == trainable == 26_165_510


@pytest.mark.parametrize("data", ["synthetic", "synthetic_interx", "interhuman", "interx"])
def test_composes_for_every_dataset(data):
    cfg = _compose([f"data={data}", "experiment=arflow_demo"])
    assert cfg.model.net.feature_dim == (336 if "interx" in data else 262)
    assert cfg.model.representation == ("interx" if "interx" in data else "interhuman")
    assert cfg.model.net.text_dim == 64 and cfg.trainer.accelerator == "cpu"


def test_module_rejects_mismatched_parts():
    def module(**overrides):
        settings = {
            "net": ReactionDecoder(feature_dim=262, width=8, depth=1, heads=2, ff=8),
            "representation": "interhuman",
            "text": None,
            "optimizer": torch.optim.AdamW,
            **overrides,
        }
        return ARFlowModule(**settings)

    assert module().space.dim == 262
    with pytest.raises(ValueError, match="text and net.text_dim go together"):
        module(net=ReactionDecoder(feature_dim=262, width=8, depth=1, heads=2, ff=8, text_dim=4))
    with pytest.raises(ValueError, match=r"net.feature_dim \(262\) must equal the interx"):
        module(representation="interx")
    with pytest.raises(ValueError, match=r"sigma_min must lie in \(0, 1\), got 1.0"):
        module(sigma_min=1.0)
    with pytest.raises(ValueError, match="guidance mode must be"):
        module(guidance={"mode": "strong"})
