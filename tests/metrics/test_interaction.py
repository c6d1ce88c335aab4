"""The geometric interaction predicates on generated clips: each passes on its clip and fails
when the clip is spoiled (reactor frozen, pushed 3 m away, roles swapped), whatever the frame."""

from __future__ import annotations

import math

import pytest
import torch

from intermask.data.common import single_threaded
from intermask.data.synthetic import ACTIONS as SYNTHETIC_ACTIONS
from intermask.data.synthetic import CONTACT_ACTIONS, generate_clip
from intermask.metrics.interaction import (
    ACTIONS,
    CHECKS,
    THRESHOLD_NAMES,
    Check,
    SuccessThresholds,
    failed_checks,
    interaction_judgements,
    interaction_success,
    measure,
    passes,
)
from intermask.motion.rotations import rotation_about_axis

THRESHOLDS = SuccessThresholds()


def _clip(action: str, index: int = 0) -> tuple[torch.Tensor, int]:
    """(T, 2, 22, 3) joints of a generated clip and its actor index (0 or 1)."""
    clip = generate_clip(seed=5, index=index, action=action)
    return clip.positions.transpose(0, 1).double(), clip.actor - 1


@pytest.fixture(scope="module")
def clips() -> dict[str, tuple[torch.Tensor, int]]:
    with single_threaded():  # tiny tensors: intra-op threads only cost time
        return {action: _clip(action) for action in ACTIONS}


def _frozen(joints: torch.Tensor, person: int) -> torch.Tensor:
    out = joints.clone()
    out[:, person] = joints[:1, person]
    return out


def _moved_away(joints: torch.Tensor, actor: int, metres: float) -> torch.Tensor:
    """The reactor shifted ``metres`` further away from the actor (horizontally)."""
    out = joints.clone()
    axis = joints[0, 1 - actor, 0] - joints[0, actor, 0]
    axis[1] = 0
    out[:, 1 - actor] += metres * axis / axis.norm()
    return out


def test_actions_match_the_synthetic_dataset_and_thresholds_exist():
    assert ACTIONS == SYNTHETIC_ACTIONS
    for action in ACTIONS:
        assert {check.threshold for check in CHECKS[action]} <= THRESHOLD_NAMES


@pytest.mark.parametrize("action", ACTIONS)
def test_every_predicate_passes_on_its_clip_and_fails_with_a_frozen_reactor(clips, action):
    joints, actor = clips[action]
    assert passes(joints, action=action, actor=actor, thresholds=THRESHOLDS)
    frozen = _frozen(joints, 1 - actor)
    assert not passes(frozen, action=action, actor=actor, thresholds=THRESHOLDS)
    assert not passes(frozen, action=action, actor=None, thresholds=THRESHOLDS)


@pytest.mark.parametrize("action", CONTACT_ACTIONS)
def test_contact_actions_fail_three_metres_apart(clips, action):
    joints, actor = clips[action]
    apart = _moved_away(joints, actor, 3.0)
    assert not passes(apart, action=action, actor=actor, thresholds=THRESHOLDS)


@pytest.mark.parametrize("action", ACTIONS)
def test_every_action_fails_when_the_bodies_pass_through_each_other(clips, action):
    joints, actor = clips[action]
    start = float((joints[0, 0, 0] - joints[0, 1, 0])[[0, 2]].norm())
    inside = _moved_away(joints, actor, 0.05 - start)  # pelvises 5 cm apart at frame 0
    pelvis = inside[:, :, 0][..., [0, 2]]
    closest = float((pelvis[:, 0] - pelvis[:, 1]).norm(dim=-1).min())
    signals = measure(inside, action=action, actor=actor, thresholds=THRESHOLDS)
    assert signals["spacing"] == pytest.approx(closest) and closest <= 0.05 + 1e-9
    failing = [c.signal for c in CHECKS[action] if not c.passes(signals, THRESHOLDS)]
    assert "spacing" in failing
    assert not passes(inside, action=action, actor=None, thresholds=THRESHOLDS)


@pytest.mark.parametrize("action", ["wave", "bow", "dance"])
def test_distant_actions_fail_when_the_pair_stands_too_close(clips, action):
    joints, actor = clips[action]
    distance = float((joints[0, 0, 0] - joints[0, 1, 0])[[0, 2]].norm())
    close = _moved_away(joints, actor, 0.5 - distance)  # pelvises 0.5 m apart
    assert not passes(close, action=action, actor=actor, thresholds=THRESHOLDS)


@pytest.mark.parametrize("action", ["handshake", "push", "wave", "chase"])
def test_the_reactor_must_not_move_first(clips, action):
    joints, actor = clips[action]
    swapped = measure(joints, action=action, actor=1 - actor, thresholds=THRESHOLDS)
    assert swapped.get("lead", swapped.get("arrival_lead")) < 0 or not passes(
        joints, action=action, actor=1 - actor, thresholds=THRESHOLDS
    )
    assert not passes(joints, action=action, actor=1 - actor, thresholds=THRESHOLDS)
    # with the actor unknown, either assignment may pass: the right one does
    assert passes(joints, action=action, actor=None, thresholds=THRESHOLDS)


@pytest.mark.parametrize("action", ["kick_block", "hug", "bow"])
def test_a_frozen_actor_fails(clips, action):
    joints, actor = clips[action]
    assert not passes(_frozen(joints, actor), action=action, actor=actor, thresholds=THRESHOLDS)


def test_handshake_and_high_five_differ_by_height(clips):
    for action, other in (("handshake", "high_five"), ("high_five", "handshake")):
        joints, actor = clips[action]
        assert not passes(joints, action=other, actor=actor, thresholds=THRESHOLDS)


@pytest.mark.parametrize("action", ACTIONS)
def test_signals_do_not_change_under_a_turn_about_y_and_a_translation(clips, action):
    joints, actor = clips[action]
    turn = rotation_about_axis(torch.tensor(2.1, dtype=torch.float64), "y")
    moved = joints @ turn.T + torch.tensor([3.0, 0.4, -7.0], dtype=torch.float64)
    before = measure(joints, action=action, actor=actor, thresholds=THRESHOLDS)
    after = measure(moved, action=action, actor=actor, thresholds=THRESHOLDS)
    assert before.keys() == after.keys()
    for name, value in before.items():
        assert math.isclose(value, after[name], abs_tol=1e-9), name


def test_batch_function_uses_lengths_actor_annotations_and_unknown_actors(clips):
    joints, actor = clips["handshake"]
    frames = joints.shape[0]
    batch = torch.zeros(3, frames + 7, 2, 22, 3, dtype=torch.float64)
    batch[:, :frames] = joints
    batch[:, frames:] = joints[-1]
    lengths = torch.tensor([frames, 20, frames])  # 20 frames: before the hands meet
    ids = torch.full((3,), ACTIONS.index("handshake"))
    actors = torch.tensor([actor + 1, actor + 1, 2 - actor])  # the last one names the reactor
    assert interaction_success(batch, lengths, ids, actors).tolist() == [True, False, False]
    unknown = torch.tensor([0, 0, 0])
    assert interaction_success(batch, lengths, ids, unknown).tolist() == [True, False, True]
    assert interaction_success(batch, lengths, ids, None).tolist() == [True, False, True]


def test_bad_inputs_are_reported():
    joints = torch.zeros(2, 10, 2, 22, 3)
    lengths, ids = torch.tensor([10, 10]), torch.tensor([0, 1])
    with pytest.raises(
        ValueError, match=r"joints of shape \(B, T, 2, 22, 3\), got \(2, 10, 22, 3\)"
    ):
        interaction_success(joints[:, :, 0], lengths, ids)
    with pytest.raises(ValueError, match=r"lengths must have shape \(2,\).*got \(3,\)"):
        interaction_success(joints, torch.tensor([10, 10, 10]), ids)
    with pytest.raises(ValueError, match=r"lengths must lie in \[2, 10\].*2..11"):
        interaction_success(joints, torch.tensor([2, 11]), ids)
    with pytest.raises(ValueError, match=r"action_ids must lie in \[0, 13\], got 0..14"):
        interaction_success(joints, lengths, torch.tensor([0, 14]))
    with pytest.raises(ValueError, match=r"actors must be 1 or 2.*or 0 \(unknown\), got \[1, 3\]"):
        interaction_success(joints, lengths, ids, torch.tensor([1, 3]))
    with pytest.raises(ValueError, match="meet_gap_low .* must not exceed meet_gap_high"):
        SuccessThresholds(meet_gap_low=2.0, meet_gap_high=1.0)
    with pytest.raises(ValueError, match="unknown action 'tango'"):
        measure(joints[0], action="tango", actor=0, thresholds=THRESHOLDS)


def _names(checks: tuple[Check, ...]) -> list[str]:
    return [check.name for check in checks]


def test_failed_checks_name_what_a_motion_misses(clips):
    joints, actor = clips["handshake"]
    assert failed_checks(joints, action="handshake", actor=actor, thresholds=THRESHOLDS) == ()
    # a handshake read as a high five misses only the height of the contact
    for who in (actor, None):
        missed = failed_checks(joints, action="high_five", actor=who, thresholds=THRESHOLDS)
        assert _names(missed) == ["contact_height>=high_contact"]
    # the roles swapped: the reactor's hand arrives first
    swapped = failed_checks(joints, action="handshake", actor=1 - actor, thresholds=THRESHOLDS)
    assert _names(swapped) == ["arrival_lead>=lead"]
    # a frozen reactor: no contact, and with the roles given, the actor's hand is not there first;
    # with the actor unknown the reading with fewer failures is reported
    frozen = _frozen(joints, 1 - actor)
    given = failed_checks(frozen, action="handshake", actor=actor, thresholds=THRESHOLDS)
    assert _names(given) == ["hand_gap<=hand_gap", "arrival_lead>=lead"]
    unknown = failed_checks(frozen, action="handshake", actor=None, thresholds=THRESHOLDS)
    assert _names(unknown) == ["hand_gap<=hand_gap"]


def test_failures_are_bits_of_the_actions_checks(clips):
    assert all(len(set(checks)) == len(checks) for checks in CHECKS.values())
    handshake, actor = clips["handshake"]
    high_five, high_five_actor = clips["high_five"]
    frames = max(len(handshake), len(high_five))
    joints = torch.zeros(3, frames, 2, 22, 3, dtype=torch.float64)
    joints[0, : len(handshake)] = handshake
    joints[1, : len(handshake)] = _frozen(handshake, 1 - actor)
    joints[2, : len(high_five)] = high_five
    lengths = torch.tensor([len(handshake), len(handshake), len(high_five)])
    action_ids = torch.full((3,), ACTIONS.index("handshake"))
    actors = torch.tensor([actor + 1, actor + 1, high_five_actor + 1])
    failures, _ = interaction_judgements(joints, lengths, action_ids, actors, thresholds=THRESHOLDS)
    # handshake checks: hand_gap (bit 0), arrival_lead (1), contact_height (2), spacing (3)
    assert _names(CHECKS["handshake"]) == [
        "hand_gap<=hand_gap",
        "arrival_lead>=lead",
        "contact_height<=low_contact",
        "spacing>=spacing",
    ]
    assert failures.tolist() == [0, 0b0011, 0b0100]
    success = interaction_success(joints, lengths, action_ids, actors, thresholds=THRESHOLDS)
    assert success.tolist() == [True, False, False]
