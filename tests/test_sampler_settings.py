"""One set of decoding settings: the sampler config group that `intermask generate` and the
evaluation compose holds the library's defaults."""

from __future__ import annotations

import re
from dataclasses import asdict
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from intermask import generate
from intermask.data.synthetic.scene import FPS
from intermask.interm.decoding import Decoding, SettingsError
from intermask.momask.sampler import MoMaskDecoding
from intermask.train import CONFIG_DIR

# the one code statement of the defaults, Decoding's fields: the library's callers that change
# single settings (the training module's samples, `make bench`) decode with the rest of these
LIBRARY = asdict(Decoding())


def test_generate_and_eval_compose_the_library_defaults():
    assert list(Decoding.__dataclass_fields__) == list(generate.default_settings()["sampler"])
    assert generate.default_settings()["sampler"] == LIBRARY
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
    assert asdict(Decoding(**demo.sampler)) == dict(demo.sampler)  # the demo's rules hold


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


def test_the_settings_check_their_rules_when_made():
    """Each family's settings refuse a value out of range or two that do not go together when
    they are made, with the messages the decoding gave; the rules that need the model or the
    request are checked where those are known."""
    refused = {
        "iterations must be at least 1, got 0": {"iterations": 0},
        "remask_noise (1.0) draws each sample's noise from its own seed; it needs "
        "noise='per_sample', got 'reference'": {"remask_noise": 1.0, "noise": "reference"},
        "revisits must be >= 0 and needs persons='in_turn', got 1 with 'together'": {"revisits": 1},
        "schedule must be one of ('paper', 'reference'), got 'x'": {"schedule": "x"},
    }
    for message, changes in refused.items():
        with pytest.raises(SettingsError) as error:
            Decoding(**changes)
        assert str(error.value) == message
    together = Decoding(partner_scale=1.0)  # fine for a reaction, not for an interaction
    together.check_for(modeling="collaborative", reaction=True)
    with pytest.raises(SettingsError, match=r"partner_scale \(1.0\) needs one person decoded"):
        together.check_for(modeling=None, reaction=False)
    with pytest.raises(SettingsError, match=r"revisits \(1\) re-decode a collaborative model"):
        Decoding(persons="in_turn", revisits=1).check_for(modeling="alternative", reaction=False)
    with pytest.raises(ValueError, match=r"schedule must be one of .* and noise one of"):
        MoMaskDecoding(noise="global")
    with pytest.raises(ValueError, match="residual_temperature must be >= 0, got -1"):
        MoMaskDecoding(residual_temperature=-1)
