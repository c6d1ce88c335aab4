"""One set of decoding settings: the sampler config group that `intermask generate` and the
evaluation compose holds the library's defaults."""

from __future__ import annotations

import re
from pathlib import Path

from hydra import compose, initialize_config_dir

from intermask import generate
from intermask.data.synthetic.scene import FPS
from intermask.interm.decoding import (
    CFG_SCALE,
    ITERATIONS,
    NOISE,
    PARTNER_SCALE,
    PERSONS,
    REMASK_NOISE,
    REVISITS,
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
    "revisits": REVISITS,
    "partner_scale": PARTNER_SCALE,
    "remask_noise": REMASK_NOISE,
}


def test_generate_and_eval_compose_the_library_defaults():
    assert generate.default_settings()["sampler"] == LIBRARY
    assert {k: getattr(generate.Settings(), k) for k in LIBRARY} == LIBRARY
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        paper = compose("eval", overrides=["eval_ckpt=x.ckpt"])
        demo = compose("eval", overrides=["eval_ckpt=x.ckpt", "experiment=eval_demo"])
    assert dict(paper.sampler) == LIBRARY
    # the demo's changes (docs/decisions.md: sampler.persons, sampler.cfg_scale, sampler.revisits,
    # sampler.remask_noise): persons in turn, 5 iterations each, a weaker guidance, two revisits
    # (A given B, then B given the new A) and randomised re-masking
    assert dict(demo.sampler) == {
        **LIBRARY,
        "iterations": 5,
        "persons": "in_turn",
        "cfg_scale": 1.5,
        "revisits": 2,
        "remask_noise": 2.0,
    }


def test_demo_samples_are_decoded_as_the_demo_table():
    """`make demo` draws its samples with the decoding its table was measured with."""
    makefile = (Path(__file__).resolve().parents[1] / "Makefile").read_text()
    line = re.search(r"^DEMO_DECODING := (.*)$", makefile, re.MULTILINE)
    assert line is not None, "Makefile: DEMO_DECODING is gone"
    flags = dict(re.findall(r"--([a-z-]+) (\S+)", line.group(1)))
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        demo = compose("eval", overrides=["eval_ckpt=x.ckpt", "experiment=eval_demo"])
    assert int(flags["iterations"]) == demo.sampler.iterations
    assert float(flags["cfg-scale"]) == demo.sampler.cfg_scale
    assert flags["persons"] == demo.sampler.persons
    assert int(flags["revisits"]) == demo.sampler.revisits
    assert float(flags["remask-noise"]) == demo.sampler.remask_noise
    assert round(float(flags["seconds"]) * FPS) == demo.data.max_length  # the crops' frames
