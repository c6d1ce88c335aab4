"""Every experiment file composes with its job and resolves completely: a broken defaults entry,
a value left missing or an interpolation to nothing fails here, not in a user's long run."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from intermask.train import CONFIG_DIR

JOBS = {
    "vq": "train_vq",
    "overfit_vq": "train_vq",
    "gen": "train_gen",
    "overfit_gen": "train_gen",
    "evaluator": "train_evaluator",
    "arflow": "train_arflow",
    "eval": "eval",
    "momask_rvq": "train_vq",
    "momask_mask": "train_gen",
    "momask_residual": "train_gen",
    "overfit_momask_rvq": "train_vq",
    "overfit_momask_mask": "train_gen",
    "overfit_momask_residual": "train_gen",
}
# the values a user (or intermask.overfit) must give on the command line
REQUIRED = {
    "train_gen": ["vq_ckpt=runs/vq/checkpoints/last.ckpt"],
    "eval": ["eval_ckpt=runs/evaluator/checkpoints/best.ckpt"],
}
EXPERIMENTS = sorted(path.stem for path in Path(CONFIG_DIR, "experiment").glob("*.yaml"))


def _job(experiment: str) -> str:
    matches = [p for p in JOBS if experiment == p or experiment.startswith(f"{p}_")]
    prefix = max(matches, key=len)
    return JOBS[prefix]


def test_every_experiment_file_has_a_job():
    assert len(EXPERIMENTS) == 39
    assert {_job(name) for name in EXPERIMENTS} == set(JOBS.values())


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_experiment_composes_and_resolves(experiment):
    job = _job(experiment)
    overrides = [f"experiment={experiment}", "paths.output_dir=runs/x", *REQUIRED.get(job, [])]
    if experiment.startswith("overfit_"):
        overrides.append("data.root=data/overfit")
    if "synthetic_long" in experiment:
        overrides.append("callbacks.protocol.evaluator=runs/evaluator/best.ckpt")
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(job, overrides=overrides)
    container = OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
    assert container["task_name"] == job
    if job != "eval":
        assert isinstance(container["trainer"]["max_epochs"], int)
        assert container["model"]["_target_"].startswith("intermask.")


@pytest.mark.parametrize("debug", ["vq", "gen", "evaluator", "arflow"])
def test_debug_group_composes_a_seconds_long_cpu_run(debug):
    job = f"train_{debug}"
    overrides = [f"debug={debug}", "paths.output_dir=runs/x", *REQUIRED.get(job, [])]
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(job, overrides=overrides)
    container = OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)
    trainer = container["trainer"]
    assert trainer["accelerator"] == "cpu" and trainer["max_epochs"] == 1
    assert (
        trainer["limit_train_batches"] <= 3 and container["callbacks"]["rich_progress_bar"] is None
    )
    assert sorted(p.stem for p in Path(CONFIG_DIR, "debug").glob("*.yaml")) == sorted(
        ["vq", "gen", "evaluator", "arflow"]
    )
