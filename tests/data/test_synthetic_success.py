"""The generator shows what it labels: every clip passes its action's interaction-success
predicate (intermask.metrics.interaction, the metric the evaluation protocol reports)."""

from __future__ import annotations

import pytest

from intermask.data.common import single_threaded
from intermask.data.synthetic import ACTIONS, generate_clip
from intermask.metrics.interaction import SuccessThresholds, measure, passes

SEED, CLIPS_PER_ACTION = 23, 2


@pytest.mark.parametrize("action", ACTIONS)
def test_every_generated_clip_passes_its_predicate(action):
    thresholds = SuccessThresholds()
    for index in range(CLIPS_PER_ACTION):
        with single_threaded():
            clip = generate_clip(seed=SEED, index=index, action=action)
        joints = clip.positions.transpose(0, 1)  # (T, 2, 22, 3) world frame, any heading
        actor = clip.actor - 1
        assert passes(joints, action=action, actor=actor, thresholds=thresholds), (
            action,
            index,
            measure(joints, action=action, actor=actor, thresholds=thresholds),
        )
