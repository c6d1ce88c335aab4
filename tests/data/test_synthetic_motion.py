"""Physical properties of the synthetic motion, measured on the written InterHuman files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from intermask.data.synthetic import ACTIONS, CONTACT_ACTIONS, generate_clip, generate_dataset
from intermask.motion.rotations import matrix_to_axis_angle
from intermask.motion.skeleton import PARENTS

CLIPS = 42  # three of each of the 14 interactions
SEED = 11
FPS = 30
MOVING = 0.1  # m/s: a joint faster than this is moving (the idle sway stays below 0.06)
ROTATION_SPREAD = 0.02  # rad: std of a joint's rotation about one axis that counts as turning


class Clip:
    """One written clip: joints (2, T, 62, 3) Y-up, labels from interaction_meta.json."""

    def __init__(self, root: Path, clip_id: str, entry: dict) -> None:
        raws = [
            np.load(root / "motions_processed" / f"person{p}" / f"{clip_id}.npy") for p in (1, 2)
        ]
        zup = np.stack([raw[:, :186].reshape(len(raw), 62, 3) for raw in raws]).astype(np.float64)
        self.joints = np.stack((zup[..., 0], zup[..., 2], -zup[..., 1]), -1)  # Z-up -> Y-up
        self.action, self.actor = entry["action"], entry["actor"] - 1
        self.reactor = 1 - self.actor

    @property
    def body(self) -> np.ndarray:
        return self.joints[:, :, :22]

    def palms(self, person: int) -> np.ndarray:
        """(T, 2, 3) left/right palm centres: mean of each hand's 15 finger joints."""
        hands = self.joints[person]
        return np.stack((hands[:, 22:37].mean(1), hands[:, 37:52].mean(1)), 1)

    def onset(self, person: int) -> int:
        """First frame at which some body joint moves faster than MOVING."""
        speed = np.linalg.norm(np.diff(self.body[person], axis=0), axis=-1).max(-1) * FPS
        return int(np.argmax(speed > MOVING)) if (speed > MOVING).any() else len(speed)


@pytest.fixture(scope="module")
def clips(tmp_path_factory: pytest.TempPathFactory) -> list[Clip]:
    root = tmp_path_factory.mktemp("synth_motion")
    generate_dataset(root, format="interhuman", clips=CLIPS, seed=SEED)
    meta = json.loads((root / "interaction_meta.json").read_text())["clips"]
    return [
        Clip(root, clip_id, entry)
        for clip_id, entry in sorted(meta.items(), key=lambda kv: int(kv[0]))
    ]


def _of(clips: list[Clip], *actions: str) -> list[Clip]:
    chosen = [c for c in clips if c.action in actions]
    assert chosen, actions
    return chosen


def test_bone_lengths_constant_and_bodies_varied(clips: list[Clip]) -> None:
    children = np.arange(1, 22)
    statures = []
    for clip in clips:
        bones = np.linalg.norm(
            clip.body[:, :, children] - clip.body[:, :, list(PARENTS[1:])], axis=-1
        )  # (2, T, 21)
        assert np.abs(bones - bones[:, :1]).max() < 1e-5  # float32 files, exact FK
        statures += [clip.body[p, 0, 15, 1] + 0.12 * bones[p, 0].sum() / 4.7 for p in (0, 1)]
    lengths = np.array([np.linalg.norm(c.body[0, 0, 18] - c.body[0, 0, 16]) for c in clips])
    assert lengths.std() > 0.005  # proportions differ from person to person
    assert 1.45 < min(statures) and max(statures) < 2.0


def test_feet_on_the_ground_every_frame(clips: list[Clip]) -> None:
    for clip in clips:
        lowest = clip.body[..., 1].min(-1)  # (2, T): nobody jumps, one foot is always down
        assert np.abs(lowest).max() < 1e-4, clip.action


def test_planted_feet_are_stationary_and_detected(clips: list[Clip]) -> None:
    for clip in _of(clips, "walk_meet", "chase", "push"):
        feet = clip.body[:, :, [10, 11]]  # toes
        down = feet[..., 1] < 1e-4
        planted = down[:, :-1] & down[:, 1:]  # on the ground in two consecutive frames
        step = np.linalg.norm(np.diff(feet, axis=1), axis=-1)
        assert step[planted].max() < 1e-3, (
            clip.action
        )  # a foot on the ground does not slide (< 1 mm)
        assert (~down).any() and planted.mean() > 0.5  # the feet step, and mostly stand
    for clip in _of(clips, "handshake", "bow", "wave"):
        feet = clip.body[:, :, [7, 10, 8, 11]]
        squared = np.square(np.diff(feet, axis=1)).sum(-1)
        low = feet[:, :-1, :, 1] < np.array([0.12, 0.05, 0.12, 0.05])
        assert ((squared < 0.001) & low).all(), (
            clip.action
        )  # InterGen's contact rule fires throughout


def test_reactor_moves_after_the_actor(clips: list[Clip]) -> None:
    for clip in clips:
        actor, reactor = clip.onset(clip.actor), clip.onset(clip.reactor)
        assert actor >= 3, clip.action  # a still moment before the action starts
        assert reactor - actor >= 3, (clip.action, actor, reactor)  # at least 0.1 s later
        assert reactor < clip.body.shape[1] - 1


def test_contact_interactions_touch(clips: list[Clip]) -> None:
    for clip in _of(clips, "handshake", "high_five", "pass_object"):
        gaps = np.linalg.norm(
            clip.palms(clip.actor)[:, :, None] - clip.palms(clip.reactor)[:, None], axis=-1
        )
        assert gaps.min() < 0.04, clip.action  # palm to palm
    for clip in _of(clips, "hug", "push"):
        chest = clip.body[clip.reactor, :, 9]
        to_chest = np.linalg.norm(clip.palms(clip.actor) - chest[:, None], axis=-1)  # (T, 2)
        assert to_chest.max(-1).min() < 0.2, clip.action  # both palms on the partner's torso
    for clip in _of(clips, "pat_shoulder"):
        shoulders = clip.body[clip.reactor, :, [16, 17]].transpose(1, 0, 2)
        gaps = np.linalg.norm(clip.palms(clip.actor)[:, :, None] - shoulders[:, None], axis=-1)
        assert gaps.min() < 0.1
    assert set(CONTACT_ACTIONS) == {
        "handshake",
        "hug",
        "push",
        "pass_object",
        "high_five",
        "pat_shoulder",
    }


def test_distant_interactions_stay_apart(clips: list[Clip]) -> None:
    for clip in _of(clips, "wave", "bow", "walk_meet", "beckon", "dance"):
        a, b = clip.joints[0], clip.joints[1]
        closest = np.linalg.norm(a[:, :, None] - b[:, None], axis=-1).min()
        assert closest > 0.5, clip.action
    for clip in _of(clips, "chase"):
        gap = np.linalg.norm(clip.body[0, :, 0, [0, 2]] - clip.body[1, :, 0, [0, 2]], axis=0)
        assert gap.min() > 1.0  # the chaser never catches up


def test_people_face_each_other_at_the_start(clips: list[Clip]) -> None:
    for clip in clips:
        pelvis = clip.body[:, 0, 0]
        for person in (0, 1):
            across = clip.body[person, 0, 2] - clip.body[person, 0, 1]  # r_hip - l_hip
            forward = np.cross([0.0, 1.0, 0.0], across)
            to_other = pelvis[1 - person] - pelvis[person]
            cos = (
                forward[[0, 2]]
                @ to_other[[0, 2]]
                / np.linalg.norm(forward[[0, 2]])
                / np.linalg.norm(to_other[[0, 2]])
            )
            assert cos > 0.95, clip.action


def _relative_axis_angles(rotations: torch.Tensor) -> torch.Tensor:
    """(N, 3, 3) rotations -> (N, 3) axis-angles relative to their chordal mean rotation."""
    u, _, vh = torch.linalg.svd(rotations.mean(0))
    mean = u @ torch.diag(torch.tensor([1.0, 1.0, float(torch.det(u @ vh))], dtype=u.dtype)) @ vh
    return matrix_to_axis_angle(mean.T @ rotations)


def test_every_joint_turns_about_at_least_two_axes() -> None:
    """Planar motion (hips and knees only bending forward, wrists, feet and collars never turning)
    leaves whole rotation channels constant, which normalization then has to floor."""
    clips = [generate_clip(seed=SEED, index=i, action=action) for i, action in enumerate(ACTIONS)]
    local = torch.cat([c.local_rotations.flatten(0, 1) for c in clips])  # (N, 22, 3, 3)
    for joint in range(1, 22):
        spread = _relative_axis_angles(local[:, joint]).std(0)  # (3,) radians
        assert (spread > ROTATION_SPREAD).sum() >= 2, (joint, spread.tolist())
