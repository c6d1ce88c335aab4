"""Geometric success predicates of the 14 synthetic interactions (no learned evaluator).

A predicate reads one two-person motion, 22 SMPL joints per person in metres, Y up, and says
whether it shows its action: the contacts touch, the gestures are made, the walkers end where
they should and the reactor answers after the actor. Wrists (joints 20 / 21) stand in for palms.
Every quantity is a distance, a height difference, an angle to the vertical or a time, so the
result does not change under a turn about Y or a translation (generated motion is decoded in a
canonical frame, ground truth need not be).

Each action is a conjunction of checks (:class:`Check`): a named *signal* of the motion
(``measure``) compared with a named threshold of :class:`SuccessThresholds`. The thresholds sit
only there; ``intermask.evaluation.success_stats.success_statistics`` measures the signals on a
dataset's ground truth, which is where the defaults come from (see the comments on the fields).
A predicate judges the frames it is given: a crop that starts after the actor's part, or ends
before the reactor's, can fail for the ground truth too (success-stats says how often).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import torch

# action id = position; the synthetic dataset that writes the labels owns the list
from intermask.motion import interhuman
from intermask.motion.actions import ACTIONS

NUM_JOINTS = 22
PELVIS, L_HIP, R_HIP, L_ANKLE, R_ANKLE, CHEST, NECK, HEAD = 0, 1, 2, 7, 8, 9, 12, 15
SHOULDERS, WRISTS = (16, 17), (20, 21)


@dataclass(frozen=True)
class SuccessThresholds:
    """Every threshold of the predicates; metres, seconds, radians.

    Measured with ``intermask data success-stats data/synthetic/interhuman --max-length 300``
    (the embedded dataset, 1000 clips, seed 0, all splits, full clips; see
    :mod:`intermask.evaluation.success_stats`): an "above" threshold is 0.75 x the GT signal's 1st
    percentile, a "below" one 1.25 x its 99th, rounded outward to 0.01 and taken over every
    signal that shares it; the comments give the percentiles. The GT passes by construction and
    a model gets a quarter of the GT's value as tolerance. The last block is definitions.
    """

    hand_gap: float = 0.31  # wrist-to-wrist contact; q99 .241 handshake, .228 pass, .181 high five
    hug_reach: float = 0.31  # all 4 wrists to the partner's chest joint at one frame; q99 .242
    hug_distance: float = 0.53  # pelvis distance at that frame, at most; q99 .418
    push_reach: float = 0.39  # both actor wrists to the reactor's chest joint; q99 .308
    push_recoil: float = 0.41  # reactor's pelvis then moves away, at least; q01 .559
    punch_near: float = 0.76  # the actor's wrist comes this close to the reactor's head; q99 .603
    punch_miss: float = 0.20  # ...but never closer than this; q01 .271
    dodge: float = 0.18  # reactor's pelvis moves back (punch, kick); q01 .287 punch, .242 kick
    apart: float = 1.00  # pelvis distance throughout; q01 2.10 wave, 1.84 bow, 1.33 dance
    raise_height: float = 0.07  # a wrist above the shoulders (wave); q01 .106 actor, .116 reactor
    bow_pitch: float = 0.12  # range of the pelvis->head pitch; q01 .217 actor, .171 reactor
    walked: float = 0.48  # pelvis travel; q01 1.01 / .643 walk_meet actor / reactor, 1.46 beckon
    meet_gap_low: float = 0.69  # pelvis distance when walk_meet ends, at least; q01 .926
    meet_gap_high: float = 1.77  # ...and at most; q99 1.410
    bounce: float = 0.03  # pelvis height range of each dancer; q01 .048
    gesture: float = 0.34  # extent of the beckoning wrist's path in the body frame; q01 .466
    dance_speed: float = 0.26  # mean wrist speed (m/s) in the body frame, both dancers; q01 .350
    kick_height: float = 0.26  # one ankle above the other; q01 .353
    run: float = 1.54  # chaser's and fleer's travel in the chase direction; q01 2.07
    escape: float = 0.94  # the fleer is never closer to the chaser than this; q01 1.26
    pat_reach: float = 0.26  # a wrist to the partner's shoulder joint, both ways; q99 .185, .200
    spacing: float = 0.24  # pelvis distance throughout (every action); q01 .331 hug, .711 handshake
    # Definitions, not measured (success_stats.UNMEASURED):
    fps: float = float(interhuman.FPS)  # frame rate of the motion (Inter-X's is the same)
    moving_speed: float = 0.1  # m/s: a joint faster than this moves (idle sway stays below 0.06)
    arrival: float = 0.30  # a wrist this close to the meeting point has arrived there
    lead: float = 0.0  # s the reactor may start before the actor: never (ties pass); q01 .167
    low_contact: float = 0.0  # handshake / pass meet below the shoulders; q99 -.224
    high_contact: float = 0.0  # a high five meets above them; q01 .119
    still: float = 0.30  # pelvis travel of one who stays (dance, beckon's actor): half a step

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ValueError(f"SuccessThresholds: fps must be > 0, got {self.fps}")
        if self.meet_gap_low > self.meet_gap_high:
            raise ValueError(
                f"SuccessThresholds: meet_gap_low ({self.meet_gap_low}) must not exceed "
                f"meet_gap_high ({self.meet_gap_high})"
            )


THRESHOLD_NAMES = frozenset(f.name for f in fields(SuccessThresholds))


class Check(NamedTuple):
    """``signal >= threshold`` (above) or ``signal <= threshold`` (below)."""

    signal: str
    above: bool
    threshold: str

    def passes(self, signals: dict[str, float], thresholds: SuccessThresholds) -> bool:
        value, limit = signals[self.signal], getattr(thresholds, self.threshold)
        return value >= limit if self.above else value <= limit

    @property
    def name(self) -> str:
        """``signal>=threshold`` or ``signal<=threshold``: the check's name in reports."""
        return f"{self.signal}{'>=' if self.above else '<='}{self.threshold}"


def _above(signal: str, threshold: str) -> Check:
    return Check(signal, True, threshold)


def _below(signal: str, threshold: str) -> Check:
    return Check(signal, False, threshold)


_ORDER = _above("lead", "lead")  # the reactor moves after the actor (every action)
# Two bodies never stand in each other (every action): without it, two persons walking through
# each other bring their wrists together and pass a handshake.
_SPACED = _above("spacing", "spacing")
_TOUCH = (_below("hand_gap", "hand_gap"), _above("arrival_lead", "lead"))
_APART = _above("min_distance", "apart")
_CHECKS: dict[str, tuple[Check, ...]] = {
    "handshake": (*_TOUCH, _below("contact_height", "low_contact")),
    "hug": (_below("hug_reach", "hug_reach"), _below("hug_distance", "hug_distance"), _ORDER),
    "push": (_below("push_reach", "push_reach"), _above("recoil", "push_recoil"), _ORDER),
    "punch_dodge": (
        _below("punch_gap", "punch_near"),
        _above("punch_gap", "punch_miss"),
        _above("retreat", "dodge"),
        _ORDER,
    ),
    "wave": (
        _APART,
        _above("actor_raise", "raise_height"),
        _above("reactor_raise", "raise_height"),
        _ORDER,
    ),
    "bow": (
        _APART,
        _above("actor_bow", "bow_pitch"),
        _above("reactor_bow", "bow_pitch"),
        _ORDER,
    ),
    "walk_meet": (
        _above("actor_travel", "walked"),
        _above("reactor_travel", "walked"),
        _above("end_distance", "meet_gap_low"),
        _below("end_distance", "meet_gap_high"),
        _ORDER,
    ),
    "dance": (
        _APART,
        _above("bounce", "bounce"),
        _above("arm_speed", "dance_speed"),
        _below("travel", "still"),
        _ORDER,
    ),
    "pass_object": (*_TOUCH, _below("contact_height", "low_contact")),
    "high_five": (*_TOUCH, _above("contact_height", "high_contact")),
    "kick_block": (_above("kick", "kick_height"), _above("retreat", "dodge"), _ORDER),
    "chase": (_above("chase_run", "run"), _above("min_distance", "escape"), _ORDER),
    "pat_shoulder": (_below("pat_gap", "pat_reach"), _below("pat_back_gap", "pat_reach"), _ORDER),
    "beckon": (
        _above("actor_gesture", "gesture"),
        _below("actor_travel", "still"),
        _above("approach", "walked"),
        _ORDER,
    ),
}
CHECKS: dict[str, tuple[Check, ...]] = {
    action: (*checks, _SPACED) for action, checks in _CHECKS.items()
}
MAX_CHECKS = max(len(checks) for checks in CHECKS.values())  # slots of a per-sample row


def _horizontal(vectors: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 2) the x and z components."""
    return vectors[..., [0, 2]]


class Pair:
    """One motion with named roles: ``joints (T, 2, 22, 3)``, ``actor`` 0 or 1 (an index)."""

    def __init__(self, joints: torch.Tensor, actor: int, *, fps: float, moving_speed: float):
        self.joints = joints.double()
        self.a, self.r = actor, 1 - actor
        self.fps, self.moving_speed = fps, moving_speed
        self.pelvis = _horizontal(self.joints[:, :, PELVIS])  # (T, 2, 2)
        self.frames = joints.shape[0]

    def distance(self) -> torch.Tensor:
        """(T,) horizontal pelvis distance."""
        return torch.linalg.vector_norm(self.pelvis[:, 0] - self.pelvis[:, 1], dim=-1)

    def away(self, frame: int = 0) -> torch.Tensor:
        """(2,) horizontal unit vector from the actor's pelvis to the reactor's at ``frame``."""
        axis = self.pelvis[frame, self.r] - self.pelvis[frame, self.a]
        return axis / torch.linalg.vector_norm(axis).clamp_min(1e-9)

    def travel(self, person: int) -> torch.Tensor:
        """(T,) horizontal pelvis distance from the first frame."""
        return torch.linalg.vector_norm(self.pelvis[:, person] - self.pelvis[:1, person], dim=-1)

    def onset(self, person: int) -> int:
        """First frame at which some joint moves faster than ``moving_speed`` (T if never)."""
        steps = self.joints[1:, person] - self.joints[:-1, person]  # (T-1, 22, 3)
        speed = torch.linalg.vector_norm(steps, dim=-1).amax(-1) * self.fps
        first = _first(speed > self.moving_speed)
        return first if first < len(speed) else self.frames

    def wrist_gaps(self, person: int, joints: tuple[int, ...]) -> torch.Tensor:
        """(T, 2, len(joints)) distances from ``person``'s wrists to the partner's ``joints``."""
        wrists = self.joints[:, person, list(WRISTS)]
        targets = self.joints[:, 1 - person, list(joints)]
        return torch.linalg.vector_norm(wrists[:, :, None] - targets[:, None], dim=-1)

    def local_wrists(self, person: int) -> torch.Tensor:
        """(T, 2, 3) wrists in the body's own frame (pelvis at the origin, x to the side, y up,
        z forward from the hips): what gestures change, and walking or turning do not."""
        joints = self.joints[:, person]
        across = _horizontal(joints[:, R_HIP] - joints[:, L_HIP])
        forward = torch.stack((across[:, 1], -across[:, 0]), -1)
        forward = forward / torch.linalg.vector_norm(forward, dim=-1, keepdim=True).clamp_min(1e-9)
        side = torch.stack((forward[:, 1], -forward[:, 0]), -1)
        relative = joints[:, list(WRISTS)] - joints[:, None, PELVIS]  # (T, 2, 3)
        flat = _horizontal(relative)
        return torch.stack(
            ((flat * side[:, None]).sum(-1), relative[..., 1], (flat * forward[:, None]).sum(-1)),
            -1,
        )

    def wrist_range(self, person: int) -> float:
        """Largest extent (bounding-box diagonal) of a wrist's path in the body frame."""
        local = self.local_wrists(person)
        extent = local.amax(0) - local.amin(0)  # (2, 3)
        return float(torch.linalg.vector_norm(extent, dim=-1).max())

    def wrist_speed(self, person: int) -> float:
        """Mean over frames of the faster wrist's speed in the body frame (m/s): steady arm
        motion. A mean, not an extent, so a window cut from the middle of a dance still has it."""
        steps = torch.linalg.vector_norm(self.local_wrists(person).diff(dim=0), dim=-1)
        return float(steps.amax(-1).mean()) * self.fps

    def bow(self, person: int) -> float:
        """Range in radians of the angle between pelvis -> head and the vertical. A range, not
        the largest angle: standing postures lean by up to 0.3 rad, a bow adds to that."""
        torso = self.joints[:, person, HEAD] - self.joints[:, person, PELVIS]
        up = torso[:, 1] / torch.linalg.vector_norm(torso, dim=-1).clamp_min(1e-9)
        angle = torch.arccos(up.clamp(-1.0, 1.0))
        return float(angle.max() - angle.min())

    def raised(self, person: int) -> torch.Tensor:
        """(T,) height of the higher wrist above the shoulders (their mean)."""
        joints = self.joints[:, person]
        return joints[:, list(WRISTS), 1].amax(-1) - joints[:, list(SHOULDERS), 1].mean(-1)


def _first(flags: torch.Tensor) -> int:
    """Index of the first True of ``flags (T,)``, T when there is none."""
    hits = torch.nonzero(flags)
    return int(hits[0, 0]) if len(hits) else len(flags)


def _hand_contact(pair: Pair, arrival: float) -> dict[str, float]:
    wrists = pair.joints[:, :, list(WRISTS)]  # (T, 2, 2, 3)
    gaps = torch.linalg.vector_norm(wrists[:, 0, :, None] - wrists[:, 1, None], dim=-1)  # (T, 2, 2)
    flat = int(gaps.flatten().argmin())
    frame, first, second = flat // 4, (flat % 4) // 2, flat % 2
    touching = torch.stack((wrists[:, 0, first], wrists[:, 1, second]), 1)  # (T, 2, 3)
    point = touching[frame].mean(0)
    shoulders = pair.joints[frame, :, list(SHOULDERS), 1].mean()
    # Who initiates: whose wrist gets near the meeting point first. Onsets of movement cannot
    # tell on a crop that starts while the actor holds the hand out and the reactor reaches.
    near = torch.linalg.vector_norm(touching - point, dim=-1) <= arrival  # (T, 2)
    arrive = [_first(near[:, p]) for p in (pair.a, pair.r)]
    return {
        "hand_gap": float(gaps.min()),
        "contact_height": float(point[1] - shoulders),
        "arrival_lead": (arrive[1] - arrive[0]) / pair.fps,
    }


def _hug(pair: Pair) -> dict[str, float]:
    reach = torch.cat([pair.wrist_gaps(p, (CHEST,)).flatten(1) for p in (0, 1)], 1).amax(1)
    frame = int(reach.argmin())
    return {"hug_reach": float(reach[frame]), "hug_distance": float(pair.distance()[frame])}


def _push(pair: Pair) -> dict[str, float]:
    reach = pair.wrist_gaps(pair.a, (CHEST,)).flatten(1).amax(1)
    frame = int(reach.argmin())
    moved = (pair.pelvis[frame:, pair.r] - pair.pelvis[frame, pair.r]) @ pair.away(frame)
    return {"push_reach": float(reach[frame]), "recoil": float(moved.max())}


def _retreat(pair: Pair) -> float:
    """Largest move of the reactor's pelvis away from where the actor first stood."""
    return float(((pair.pelvis[:, pair.r] - pair.pelvis[0, pair.r]) @ pair.away()).max())


def _signals(pair: Pair, action: str, thresholds: SuccessThresholds) -> dict[str, float]:
    a, r = pair.a, pair.r
    if action in ("handshake", "pass_object", "high_five"):
        return _hand_contact(pair, thresholds.arrival)
    if action == "hug":
        return _hug(pair)
    if action == "push":
        return _push(pair)
    if action == "punch_dodge":
        gap = pair.wrist_gaps(a, (HEAD,)).min()
        return {"punch_gap": float(gap), "retreat": _retreat(pair)}
    if action == "kick_block":
        ankles = pair.joints[:, a, [L_ANKLE, R_ANKLE], 1]
        return {"kick": float((ankles[:, 0] - ankles[:, 1]).abs().max()), "retreat": _retreat(pair)}
    if action in ("wave", "bow", "dance"):
        values = {"min_distance": float(pair.distance().min())}
        if action == "wave":
            values |= {"actor_raise": float(pair.raised(a).max())}
            values |= {"reactor_raise": float(pair.raised(r).max())}
        elif action == "bow":
            values |= {"actor_bow": pair.bow(a), "reactor_bow": pair.bow(r)}
        else:
            height = pair.joints[:, :, PELVIS, 1]  # (T, 2)
            values |= {
                "bounce": float((height.amax(0) - height.amin(0)).min()),
                "arm_speed": min(pair.wrist_speed(p) for p in (0, 1)),
                "travel": max(float(pair.travel(p).max()) for p in (0, 1)),
            }
        return values
    if action == "walk_meet":
        return {
            "actor_travel": float(pair.travel(a).max()),
            "reactor_travel": float(pair.travel(r).max()),
            "end_distance": float(pair.distance()[-1]),
        }
    if action == "chase":
        axis = pair.away()
        run = [float((pair.pelvis[-1, p] - pair.pelvis[0, p]) @ axis) for p in (a, r)]
        return {"chase_run": min(run), "min_distance": float(pair.distance().min())}
    if action == "pat_shoulder":
        return {
            "pat_gap": float(pair.wrist_gaps(a, SHOULDERS).min()),
            "pat_back_gap": float(pair.wrist_gaps(r, SHOULDERS).min()),
        }
    if action == "beckon":
        towards = (pair.pelvis[0, r] - pair.pelvis[:, r]) @ pair.away()
        return {
            "actor_gesture": pair.wrist_range(a),
            "actor_travel": float(pair.travel(a).max()),
            "approach": float(towards.max()),
        }
    raise ValueError(f"unknown action {action!r}; expected one of {', '.join(ACTIONS)}")


def measure(
    joints: torch.Tensor, *, action: str, actor: int, thresholds: SuccessThresholds
) -> dict[str, float]:
    """Signals of ``action``'s checks for ``joints (T, 2, 22, 3)`` with the actor at index
    ``actor`` (0 or 1); ``lead`` in seconds, the rest in metres or radians."""
    pair = Pair(joints, actor, fps=thresholds.fps, moving_speed=thresholds.moving_speed)
    signals = _signals(pair, action, thresholds)
    signals["lead"] = (pair.onset(pair.r) - pair.onset(pair.a)) / thresholds.fps
    signals["spacing"] = float(pair.distance().min())
    return signals


def failed_checks(
    joints: torch.Tensor, *, action: str, actor: int | None, thresholds: SuccessThresholds
) -> tuple[Check, ...]:
    """The checks of ``action`` that ``joints (T, 2, 22, 3)`` (the valid frames only) fails, in
    ``CHECKS`` order: empty when it shows the action.

    actor: 0 or 1 (an index), or None when unknown (generated motion): then either person may
    be the actor, and a motion that fails both ways reports the reading with fewer failures (the
    first person as the actor on a tie).
    """
    return judge(joints, action=action, actor=actor, thresholds=thresholds)[0]


def judge(
    joints: torch.Tensor, *, action: str, actor: int | None, thresholds: SuccessThresholds
) -> tuple[tuple[Check, ...], dict[str, float]]:
    """:func:`failed_checks` (same arguments) and the signals of the reading it reports (with
    the actor unknown, the person whose reading fails fewer checks acts)."""
    readings = []
    for index in (0, 1) if actor is None else (actor,):
        signals = measure(joints, action=action, actor=index, thresholds=thresholds)
        failed = tuple(check for check in CHECKS[action] if not check.passes(signals, thresholds))
        if not failed:
            return (), signals
        readings.append((failed, signals))
    return min(readings, key=lambda reading: len(reading[0]))  # the first of the fewest


def passes(
    joints: torch.Tensor, *, action: str, actor: int | None, thresholds: SuccessThresholds
) -> bool:
    """Whether ``joints (T, 2, 22, 3)`` (the valid frames only) shows ``action`` (see
    :func:`failed_checks`, whose ``actor`` this takes)."""
    return not failed_checks(joints, action=action, actor=actor, thresholds=thresholds)


def _check_batch(
    joints: torch.Tensor,
    lengths: torch.Tensor,
    action_ids: torch.Tensor,
    actors: torch.Tensor | None,
) -> None:
    if joints.ndim != 5 or tuple(joints.shape[2:]) != (2, NUM_JOINTS, 3):
        raise ValueError(
            f"interaction success needs joints of shape (B, T, 2, {NUM_JOINTS}, 3), got "
            f"{tuple(joints.shape)}"
        )
    batch, frames = joints.shape[:2]
    for name, values in (("lengths", lengths), ("action_ids", action_ids), ("actors", actors)):
        if values is not None and tuple(values.shape) != (batch,):
            raise ValueError(
                f"interaction success: {name} must have shape ({batch},) to match the joints, "
                f"got {tuple(values.shape)}"
            )
    if batch and (int(lengths.min()) < 2 or int(lengths.max()) > frames):
        raise ValueError(
            f"interaction success: lengths must lie in [2, {frames}] (the joints' frames), got "
            f"{int(lengths.min())}..{int(lengths.max())}"
        )
    if batch and (int(action_ids.min()) < 0 or int(action_ids.max()) >= len(ACTIONS)):
        raise ValueError(
            f"interaction success: action_ids must lie in [0, {len(ACTIONS) - 1}], got "
            f"{int(action_ids.min())}..{int(action_ids.max())}"
        )
    if actors is not None and batch and not bool(((actors >= 0) & (actors <= 2)).all()):
        raise ValueError(
            "interaction success: actors must be 1 or 2 (the acting person) or 0 (unknown), got "
            f"{sorted(set(actors.tolist()))}"
        )


def interaction_judgements(
    joints: torch.Tensor,
    lengths: torch.Tensor,
    action_ids: torch.Tensor,
    actors: torch.Tensor | None = None,
    *,
    thresholds: SuccessThresholds | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per sample, the failed checks of the action it should show and the signal each check
    reads (:func:`judge`): ``(failures (B,) int64, signals (B, MAX_CHECKS) float64)``. Bit ``i``
    of a failure word is set when the motion fails ``CHECKS[action][i]`` (0: it succeeds);
    ``signals[:, i]`` is the value ``CHECKS[action][i]`` compared with its threshold, NaN past
    the action's checks.

    joints: (B, T, 2, 22, 3) metres, Y up; lengths: (B,) valid frames; action_ids: (B,) indices
    into ``ACTIONS``; actors: (B,) 1 or 2 (the acting person, in the joints' person order) or 0,
    or None for all, when unknown (generated motion: either person may act).
    """
    _check_batch(joints, lengths, action_ids, actors)
    thresholds = thresholds or SuccessThresholds()
    masks, values = [], torch.full((joints.shape[0], MAX_CHECKS), torch.nan, dtype=torch.float64)
    for index in range(joints.shape[0]):
        actor = None if actors is None or int(actors[index]) == 0 else int(actors[index]) - 1
        valid = joints[index, : int(lengths[index])].detach().cpu()
        action = ACTIONS[int(action_ids[index])]
        failed, signals = judge(valid, action=action, actor=actor, thresholds=thresholds)
        masks.append(sum(1 << CHECKS[action].index(check) for check in failed))
        for slot, check in enumerate(CHECKS[action]):
            values[index, slot] = signals[check.signal]
    return (
        torch.tensor(masks, dtype=torch.int64, device=joints.device),
        values.to(joints.device),
    )


def interaction_success(
    joints: torch.Tensor,
    lengths: torch.Tensor,
    action_ids: torch.Tensor,
    actors: torch.Tensor | None = None,
    *,
    thresholds: SuccessThresholds | None = None,
) -> torch.Tensor:
    """Per-sample success of the action each motion should show: no failed check in
    :func:`interaction_judgements` (same arguments). -> (B,) bool."""
    failures, _ = interaction_judgements(joints, lengths, action_ids, actors, thresholds=thresholds)
    return failures == 0
