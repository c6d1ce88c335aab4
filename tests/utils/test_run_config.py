"""Run configs build only the framework's own classes: a payload in a shared run folder is
refused, naming the file, before anything is called."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
import yaml
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from payloads import exec_target

from intermask.evaluator.load import load_evaluator
from intermask.interm.load import load_generator
from intermask.reaction.load import load_arflow
from intermask.train import CONFIG_DIR
from intermask.utils.run_config import LOADABLE_TARGETS, UnsafeRunConfig, check_targets
from intermask.vq.load import load_vq


def _compose(name: str, *overrides: str):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose(name, overrides=["data=synthetic", *overrides])


@pytest.mark.parametrize(
    ("config_name", "overrides", "sections"),
    [
        ("train_vq", (), ("model.net",)),
        ("train_vq", ("data=synthetic_interx",), ("model.net",)),
        ("train_gen", ("vq_ckpt=unused", "text=tiny_random"), ("model.net", "text")),
        ("train_evaluator", (), ("model.net",)),
        ("train_evaluator", ("data=synthetic_interx",), ("model.net",)),
        ("train_arflow", ("text=tiny_random",), ("model",)),
    ],
)
def test_every_section_a_loader_builds_passes_the_check(config_name, overrides, sections):
    # the allowlist cannot drift from the configs: what our own runs save must load
    cfg = _compose(config_name, *overrides)
    for section in sections:
        node = OmegaConf.select(cfg, section)
        checked = check_targets(node, source="composed")
        assert checked["_target_"] in LOADABLE_TARGETS


def _run_folder(tmp_path: Path, config: dict) -> Path:
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    # a "net." key: what the evaluator loader recognises as one of our runs
    torch.save({"state_dict": {"net.x": torch.zeros(1)}}, run / "checkpoints" / "last.ckpt")
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    return run


@pytest.mark.parametrize(
    ("loader", "config"),
    [
        (load_vq, lambda p: {"model": {"net": p}}),
        (load_generator, lambda p: {"vq_ckpt": "x.ckpt", "model": {"net": p}}),
        (
            load_arflow,
            lambda p: {"model": {"_target_": "intermask.reaction.module.ARFlowModule", "net": p}},
        ),
        (load_evaluator, lambda p: {"model": {"net": p}}),
    ],
)
def test_a_payload_in_a_run_config_is_refused_before_it_runs(tmp_path, loader, config):
    marker = tmp_path / "marker"
    run = _run_folder(tmp_path, config(exec_target(marker)))
    with pytest.raises(UnsafeRunConfig) as refused:
        loader(run / "checkpoints" / "last.ckpt")
    message = str(refused.value)
    assert str(run / "config.yaml") in message
    assert "refusing to build 'builtins.exec' (at model" in message
    assert not marker.exists()


def test_the_text_tower_section_is_checked_before_anything_is_read(tmp_path):
    marker = tmp_path / "marker"
    net = OmegaConf.to_container(
        _compose("train_gen", "vq_ckpt=unused", "text=tiny_random").model.net, resolve=True
    )
    run = _run_folder(
        tmp_path, {"vq_ckpt": "x.ckpt", "model": {"net": net}, "text": exec_target(marker)}
    )
    with pytest.raises(
        UnsafeRunConfig, match=r"refusing to build 'builtins.exec' \(at text._target_\)"
    ):
        load_generator(run)  # refused before the (missing) VQ checkpoint is looked for
    assert not marker.exists()


def test_a_nested_payload_and_an_escaped_interpolation_are_refused():
    nested = {
        "_target_": "intermask.vq.model.MotionVQVAE",
        "encoder": {"_target_": "torch.load", "f": "x", "weights_only": False},
    }
    with pytest.raises(UnsafeRunConfig, match=r"'torch.load' \(at encoder._target_\)"):
        check_targets(nested, source="run/config.yaml")
    listed = {"_target_": "torch.optim.AdamW", "params": [{"_target_": "os.system"}]}
    with pytest.raises(UnsafeRunConfig, match=r"'os.system' \(at params\[0\]._target_\)"):
        check_targets(listed, source="run/config.yaml")
    # OmegaConf keeps "\${...}" as the literal "${...}"; instantiate would then resolve it, and
    # oc.create could build a new _target_ after the check
    escaped = OmegaConf.create(
        {"_target_": "torch.optim.Adam", "lr": "\\${oc.create:{_target_: os.system}}"}
    )
    with pytest.raises(UnsafeRunConfig, match="at lr: a run config holds resolved values"):
        check_targets(escaped, source="run/config.yaml")
