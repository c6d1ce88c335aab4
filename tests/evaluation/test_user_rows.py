"""The evaluation's ``rows`` seam (docs/extending.md): rows of your own are built by their
``_target_`` with the evaluation's device and the dataset's normalizer, recorded in the header,
named apart from every other row, and refused with a message naming the entry when they are not
rows. The tutorial itself runs end to end in tests/test_extending.py."""

from __future__ import annotations

import pytest
import torch
from hydra import compose, initialize_config_dir

from intermask.evaluate import _check_config, build_sources, user_rows
from intermask.evaluation.protocol import MotionSource
from intermask.train import CONFIG_DIR

HERE = __name__  # this module, as the rows' _target_ names it


class Still(MotionSource):
    """A row that stands both persons still at the batch's lengths."""

    generates = True

    def __init__(self, *, device, normalizer, name="Still", frames=4):
        self.device, self.normalizer, self.name, self.frames = device, normalizer, name, frames

    def __call__(self, batch, seeds):
        return torch.zeros(len(seeds), 2, self.frames, 262), batch["length"]


def not_a_row(*, device, normalizer):
    return {"device": device}


def _eval(*overrides: str):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose("eval", overrides=["eval_ckpt=unused", *overrides])


def test_a_row_of_yours_is_built_with_the_device_and_normalizer_and_recorded():
    cfg = _eval(
        f"+rows.still._target_={HERE}.Still",
        "+rows.still.frames=8",
        "+rows.off=null",  # left out
    )
    normalizer, checkpoints = object(), {}
    rows = user_rows(cfg, normalizer, torch.device("cpu"), checkpoints)
    assert len(rows) == 1 and isinstance(rows[0], Still)
    assert rows[0].device == torch.device("cpu") and rows[0].normalizer is normalizer
    assert rows[0].frames == 8
    assert checkpoints == {"rows.still": {"_target_": f"{HERE}.Still", "frames": 8}}


def test_with_only_rows_of_your_own_no_generator_is_needed():
    cfg = _eval(f"+rows.still._target_={HERE}.Still")  # gen_ckpt left null
    sources, checkpoints = build_sources(cfg, None, torch.device("cpu"))
    assert [source.name for source in sources] == ["Still"]
    assert list(checkpoints) == ["rows.still"]
    with pytest.raises(ValueError, match=r"mode=interaction needs gen_ckpt=<train_gen run"):
        build_sources(_eval(), None, torch.device("cpu"))  # and without any row it is refused


def test_rows_are_named_apart():
    twice = _eval(f"+rows.a._target_={HERE}.Still", f"+rows.b._target_={HERE}.Still")
    with pytest.raises(ValueError, match=r"two rows of the table would be named \['Still'\]"):
        build_sources(twice, None, torch.device("cpu"))
    truth = _eval(f"+rows.a._target_={HERE}.Still", "+rows.a.name=Ground Truth")
    with pytest.raises(ValueError, match=r"would be named \['Ground Truth'\]: name each row"):
        build_sources(truth, None, torch.device("cpu"))


def test_an_entry_that_is_not_a_row_is_refused_by_name():
    untargeted = _eval("+rows.mine.checkpoint=outputs/mine")
    with pytest.raises(
        ValueError,
        match=r"rows\.mine: expected a config with a _target_ .*got \{'checkpoint': 'outputs/mine'\}",
    ):
        user_rows(untargeted, None, torch.device("cpu"), {})
    wrong = _eval(f"+rows.mine._target_={HERE}.not_a_row")
    with pytest.raises(
        TypeError,
        match=rf"rows\.mine: {HERE}\.not_a_row returned a dict, not a MotionSource",
    ):
        user_rows(wrong, None, torch.device("cpu"), {})


def test_the_reference_loop_takes_no_rows_of_yours():
    cfg = _eval("order=reference", f"+rows.still._target_={HERE}.Still")
    with pytest.raises(
        ValueError, match=r"without reconstruction_row or rows of your own.*rows=\['still'\]"
    ):
        _check_config(cfg)
    assert _check_config(_eval("order=reference")) == "reference"
