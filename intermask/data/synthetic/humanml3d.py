"""The embedded synthetic dataset in the official HumanML3D layout (single person, 20 fps).

``generate_humanml3d(out, clips=N, seed=S)`` writes the actor of N generator clips, read unchanged
by :class:`intermask.data.humanml3d.HumanML3DDataset`:

    new_joint_vecs/<id>.npy float32 (T, 263); new_joints/<id>.npy float32 (T, 22, 3), Y up
    texts/<id>.txt          caption#word/POS ...#start#end
    Mean.npy, Std.npy       (263,) over the training split
    train.txt val.txt test.txt train_val.txt all.txt

The generator runs at 30 fps only (``scene.FPS`` is fixed in every choreography), so each clip is
resampled: the actor's local rotations (quaternion nlerp, exact slerp at the 0 and 1/2 frame
fractions that 30 -> 20 fps needs) and root position (linear) at t = k / 20 s, then posed by
forward kinematics, so bone lengths stay exact; everything else is computed from those positions
(:func:`intermask.motion.humanml3d.features_from_positions`). Every clip uses the template body,
as the reference processing retargets every motion to one skeleton. Captions are the
single-person templates; a clip in which the actor moves across the floor for at least 2 s gets
an extra time-tagged line for that span. ``interaction_meta.json`` names each clip's action.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from intermask.data.humanml3d import HumanML3DLayout
from intermask.data.normalization import StatsAccumulator
from intermask.data.synthetic.captions import make_solo_captions, moving_caption, processed_line
from intermask.data.synthetic.clips import SynthClip, generate_clip
from intermask.data.synthetic.planning import assign_actions, assign_splits, prepare_folder
from intermask.data.synthetic.scene import FPS as SOURCE_FPS
from intermask.data.synthetic.writers import META_FILE, META_FORMAT, SPLITS
from intermask.motion import humanml3d as hml
from intermask.motion.actions import ACTIONS
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import matrix_to_quaternion, quaternion_to_matrix

LAYOUT_ENTRIES = (
    "new_joint_vecs",
    "new_joints",
    "texts",
    "Mean.npy",
    "Std.npy",
    *(f"{name}.txt" for name in (*SPLITS, "train_val", "all")),
)
MIN_STD = 1e-3  # the floor of the other writers' statistics (StatsAccumulator)
MOVING_SPEED = 0.5  # m/s of the root on the floor above which a frame counts as moving
MIN_PHASE_FRAMES = 40  # a sub-clip must pass the reader's 40-frame rule
_CAPTION_TAG = 0xCA7  # third seed word: caption streams apart from the clip streams
# The parts whose std the reference replaces by the part's mean std (cal_mean_variance.ipynb).
STD_GROUPS = hml.PARTS


@dataclass(frozen=True)
class HumanML3DSummary:
    """What generate_humanml3d wrote."""

    root: Path
    clips: int
    seed: int
    split_sizes: dict[str, int]
    action_counts: dict[str, int]
    subclips: int  # time-tagged caption lines written
    outside_length_rule: int  # clips the reader skips (T outside [40, 200))

    def __str__(self) -> str:
        sizes = "/".join(str(self.split_sizes[s]) for s in SPLITS)
        return (
            f"{self.clips} synthetic HumanML3D clips (train/val/test {sizes}, "
            f"{self.subclips} sub-clips, {self.outside_length_rule} outside [40, 200) frames, "
            f"seed {self.seed})"
        )


class Resampled(NamedTuple):
    positions: torch.Tensor  # (K, 22, 3) Y-up world joints
    local_rotations: torch.Tensor  # (K, 22, 3, 3); row 0 the root's world orientation


def resample(clip: SynthClip, person: int, fps: int = hml.FPS) -> Resampled:
    """`person` (0 or 1) at `fps`: K = floor((T - 1) fps / 30) + 1 frames at t = k / fps, from
    interpolated local rotations and root position posed by forward kinematics."""
    frames = clip.frames
    count = (frames - 1) * fps // SOURCE_FPS + 1
    where = torch.arange(count, dtype=torch.float64) * SOURCE_FPS / fps
    low = where.floor().long().clamp(max=frames - 1)
    high = (low + 1).clamp(max=frames - 1)
    frac = (where - low)[:, None]
    quat = matrix_to_quaternion(clip.local_rotations[person])  # (T, 22, 4)
    q0, q1 = quat[low], quat[high]
    q1 = torch.where(((q0 * q1).sum(-1, keepdim=True) < 0), -q1, q1)  # the shorter arc
    blend = torch.nn.functional.normalize((1 - frac[..., None]) * q0 + frac[..., None] * q1, dim=-1)
    root = clip.positions[person, :, 0]
    root = (1 - frac) * root[low] + frac * root[high]
    local = quaternion_to_matrix(blend)
    return Resampled(forward_kinematics(local, root, clip.offsets[person]).positions, local)


def _seconds(frame: int) -> str:
    """A time tag the reader turns back into `frame` (int(seconds * 20) == frame)."""
    text = f"{frame / hml.FPS:g}"
    if int(float(text) * hml.FPS) != frame:
        text = f"{(frame + 0.01) / hml.FPS:.4f}"
    return text


def moving_span(joints: torch.Tensor) -> tuple[int, int] | None:
    """Longest run [start, stop) of frames whose root moves faster than MOVING_SPEED on the floor,
    when it lasts at least MIN_PHASE_FRAMES and leaves at least as many other frames."""
    step = joints[1:, 0, [0, 2]] - joints[:-1, 0, [0, 2]]
    moving = (torch.linalg.vector_norm(step, dim=-1) * hml.FPS > MOVING_SPEED).tolist()
    best, start = (0, 0), None
    for frame, flag in enumerate([*moving, False]):
        if flag and start is None:
            start = frame
        elif not flag and start is not None:
            best = max(best, (start, frame), key=lambda span: span[1] - span[0])
            start = None
    length = best[1] - best[0]
    if length < MIN_PHASE_FRAMES or len(joints) - length < MIN_PHASE_FRAMES:
        return None
    return best


def group_std(std: np.ndarray) -> np.ndarray:
    """The reference's Std.npy: each part's std replaced by its mean over the part, then floored."""
    std = std.copy()
    for part in STD_GROUPS:
        std[part] = std[part].mean()
    return np.maximum(std, MIN_STD)


def _write_lines(path: Path, lines: list[str]) -> None:
    path.write_text("".join(f"{line}\n" for line in lines), encoding="utf-8")


def _readme(clips: int, seed: int, split_sizes: dict[str, int]) -> str:
    return (
        f"Synthetic single-person motion dataset, HumanML3D layout ({META_FORMAT})\n\n"
        "NOT motion capture. Every clip is the actor of a procedurally generated two-person\n"
        f"interaction (intermask.data.synthetic; {len(ACTIONS)} interactions), resampled from 30 to\n"
        "20 fps, template skeleton, single-person template captions with POS tags.\n"
        "interaction_meta.json names each clip's interaction.\n\n"
        f"clips: {clips} (train {split_sizes['train']}, val {split_sizes['val']}, "
        f"test {split_sizes['test']})\nseed: {seed}\n"
        "regenerate: intermask.data.synthetic.generate_humanml3d(DIR, "
        f"clips={clips}, seed={seed})\n"
    )


def generate_humanml3d(
    out: Path | str,
    clips: int,
    seed: int,
    split_fractions: tuple[float, float, float] = (0.8, 0.1, 0.1),
) -> HumanML3DSummary:
    """Write `clips` single-person clips under `out` in the official HumanML3D layout.

    `out` must be empty, missing, or hold an earlier synthetic dataset (which is replaced). The
    same seed gives the same bytes. Ids are six digits, "000000" upwards.
    """
    if not 3 <= clips <= 999_999:
        raise ValueError(f"clips must be between 3 and 999999, got {clips}")
    out = Path(out)
    splits = assign_splits(clips, seed, split_fractions)
    actions = assign_actions(clips, seed)
    prepare_folder(out)  # refuses a folder that holds anything but a synthetic dataset
    layout = HumanML3DLayout(out)
    _clear_layout(out)
    ids: dict[str, list[str]] = {split: [] for split in SPLITS}
    meta: dict[str, dict[str, object]] = {}
    stats = StatsAccumulator((hml.FEATURE_DIM,))
    subclips = outside = 0
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny tensors: threads only add overhead (see generate_dataset)
    try:
        for index, (action, split) in enumerate(zip(actions, splits, strict=True)):
            clip_id = f"{index:06d}"
            clip, features, tagged = _write_clip(layout, clip_id, seed, index, action)
            subclips += tagged
            outside += not 40 <= len(features) < 200
            if split == "train":
                stats.update(features)
            ids[split].append(clip_id)
            meta[clip_id] = {
                "action": action,
                "action_id": clip.action_id,
                "source_person": clip.actor,
            }
    finally:
        torch.set_num_threads(threads)
    _write_statistics(layout, stats)
    _write_splits(layout, ids, clips)
    (out / META_FILE).write_text(
        json.dumps(
            {"format": META_FORMAT, "actions": list(ACTIONS), "clips": meta},
            sort_keys=True,
            indent=1,
        ),
        encoding="utf-8",
    )
    split_sizes = {split: len(names) for split, names in ids.items()}
    (out / "README.txt").write_text(_readme(clips, seed, split_sizes), encoding="utf-8")
    return HumanML3DSummary(
        root=out,
        clips=clips,
        seed=seed,
        split_sizes=split_sizes,
        action_counts={action: actions.count(action) for action in ACTIONS},
        subclips=subclips,
        outside_length_rule=outside,
    )


def _clear_layout(out: Path) -> None:
    """Remove an earlier dataset's layout entries (the folders' files, the top-level files) and
    make the three per-clip folders."""
    for name in LAYOUT_ENTRIES:
        path = out / name
        if path.is_dir():
            for child in sorted(path.iterdir()):
                child.unlink()
        elif path.exists():
            path.unlink()
    for folder in ("new_joint_vecs", "new_joints", "texts"):
        (out / folder).mkdir(exist_ok=True)


def _write_clip(
    layout: HumanML3DLayout, clip_id: str, seed: int, index: int, action: str
) -> tuple[SynthClip, np.ndarray, bool]:
    """Generate clip `index` and write its actor's features, joints and captions as `clip_id`.

    Returns the generator clip, the (T, 263) float32 features and whether a time-tagged
    moving line was captioned.
    """
    clip = generate_clip(seed=seed, index=index, action=action, vary_bodies=False)
    motion = hml.features_from_positions(*resample(clip, clip.actor - 1))
    features = motion.features.numpy().astype(np.float32)
    np.save(layout.motion_file(clip_id), features)
    np.save(layout.joints_file(clip_id), motion.joints.numpy().astype(np.float32))
    rng = np.random.default_rng(np.random.SeedSequence([seed, index, _CAPTION_TAG]))
    captions = make_solo_captions(rng, action=action, side=clip.side, speed=clip.speed)
    lines = [processed_line(caption) for caption in captions]
    moving = _moving_line(rng, motion.joints)  # after the templates: the same caption stream
    if moving is not None:
        lines.append(moving)
    _write_lines(layout.caption_file(clip_id), lines)
    return clip, features, moving is not None


def _moving_line(rng: np.random.Generator, joints: torch.Tensor) -> str | None:
    """The time-tagged caption line of the (T, 22, 3) joints' :func:`moving_span`, at the
    span's mean floor speed; None when the clip has no such span."""
    span = moving_span(joints)
    if span is None:
        return None
    step = joints[span[0] + 1 : span[1], 0] - joints[span[0] : span[1] - 1, 0]
    speed = float(torch.linalg.vector_norm(step[:, [0, 2]], dim=-1).mean()) * hml.FPS
    return processed_line(moving_caption(rng, speed), _seconds(span[0]), _seconds(span[1]))


def _write_statistics(layout: HumanML3DLayout, stats: StatsAccumulator) -> None:
    """Mean.npy and the reference's grouped Std.npy of the training split."""
    mean, std, _ = stats.compute(min_std=0.0)
    np.save(layout.mean_file, mean.astype(np.float32))
    np.save(layout.std_file, group_std(std).astype(np.float32))


def _write_splits(layout: HumanML3DLayout, ids: dict[str, list[str]], clips: int) -> None:
    """The split files: train, val and test, train_val, and all ids."""
    for split, names in ids.items():
        _write_lines(layout.split_file(split), names)
    _write_lines(layout.split_file("train_val"), ids["train"] + ids["val"])
    _write_lines(layout.split_file("all"), [f"{index:06d}" for index in range(clips)])
