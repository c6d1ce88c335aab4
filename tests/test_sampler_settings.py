"""One set of decoding settings: the sampler config group that `intermask generate` and the
evaluation compose holds the library's defaults."""

from __future__ import annotations

from hydra import compose, initialize_config_dir

from intermask import generate
from intermask.interm.decoding import (
    CFG_SCALE,
    ITERATIONS,
    NOISE,
    PERSONS,
    SCHEDULE,
    TEMPERATURE,
    TOP_K_RATIO,
)
from intermask.train import CONFIG_DIR

LIBRARY = {
    "iterations": ITERATIONS,
    "cfg_scale": CFG_SCALE,
    "top_k_ratio": TOP_K_RATIO,
    "temperature": TEMPERATURE,
    "schedule": SCHEDULE,
    "noise": NOISE,
    "persons": PERSONS,
}


def test_generate_and_eval_compose_the_library_defaults():
    assert generate.default_settings()["sampler"] == LIBRARY
    assert {k: getattr(generate.Settings(), k) for k in LIBRARY} == LIBRARY
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        paper = compose("eval", overrides=["eval_ckpt=x.ckpt"])
        demo = compose("eval", overrides=["eval_ckpt=x.ckpt", "experiment=eval_demo"])
    assert dict(paper.sampler) == LIBRARY
    # the demo's changes: persons in turn, 5 iterations each (the passes of 10 together)
    assert dict(demo.sampler) == {**LIBRARY, "iterations": 5, "persons": "in_turn"}
