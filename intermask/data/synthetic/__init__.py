"""The embedded procedural two-person interaction dataset.

``generate_dataset(out, format="interhuman" | "interx", clips=N, seed=S)`` writes a complete
dataset in one of the official layouts, so the real readers are what every test and demo uses.
Each clip is one of 14 interactions (``ACTIONS``) between an actor and a reactor who answers after
a short delay, posed by forward kinematics of the SMPL 22-joint skeleton with per-person
proportions, feet on the ground, per-person posture and secondary motion (:mod:`.secondary`) in
every joint, three paraphrased captions, and an action / actor annotation in
``interaction_meta.json``. The same seed gives the same bytes. ``generate_humanml3d(out, clips=N,
seed=S)`` writes the actor of each clip as a single-person dataset in the HumanML3D layout.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from intermask.data.synthetic.clips import ACTIONS, CONTACT_ACTIONS, SynthClip, generate_clip
from intermask.data.synthetic.humanml3d import HumanML3DSummary, generate_humanml3d
from intermask.data.synthetic.planning import assign_actions, assign_splits, prepare_folder
from intermask.data.synthetic.writers import (
    META_FORMAT,
    SPLITS,
    InterHumanWriter,
    InterXWriter,
)
from intermask.motion.kinds import DatasetKind, check_dataset_kind

__all__ = [
    "ACTIONS",
    "CONTACT_ACTIONS",
    "GENERATOR_VERSION",
    "HumanML3DSummary",
    "SynthClip",
    "SynthSummary",
    "assign_actions",
    "assign_splits",
    "generate_clip",
    "generate_dataset",
    "generate_humanml3d",
]

GENERATOR_VERSION = META_FORMAT
MAX_CLIPS = 999_000  # Inter-X names hold the clip index in three 3-digit fields


@dataclass(frozen=True)
class SynthSummary:
    """What generate_dataset wrote."""

    root: Path
    format: str
    clips: int
    seed: int
    split_sizes: dict[str, int]
    action_counts: dict[str, int]

    def __str__(self) -> str:
        sizes = "/".join(str(self.split_sizes[s]) for s in SPLITS)
        return (
            f"{self.clips} synthetic {self.format} clips ({len(self.action_counts)} interaction types, "
            f"train/val/test {sizes}, seed {self.seed})"
        )


def _readme(*, format: str, clips: int, seed: int, split_sizes: dict[str, int]) -> str:
    return (
        f"Synthetic two-person interaction dataset ({GENERATOR_VERSION})\n\n"
        "NOT motion capture. Every clip was generated procedurally by intermask.data.synthetic:\n"
        f"{len(ACTIONS)} scripted interactions ({', '.join(ACTIONS)}) between an actor and a reactor who\n"
        "responds after a short delay, posed by forward kinematics of the SMPL 22-joint skeleton\n"
        "(per-person proportions, closed-form leg and arm IK, planted feet, random posture and\n"
        "secondary sway, gaze towards the partner), 30 fps, 2-10 s,\n"
        "three template captions per clip. interaction_meta.json names the action and the actor.\n\n"
        f"layout: {format}\nclips: {clips} (train {split_sizes['train']}, val {split_sizes['val']}, "
        f"test {split_sizes['test']})\nseed: {seed}\n"
        f"regenerate: intermask data synth --out DIR --format {format} --clips {clips} --seed {seed}\n"
    )


def generate_dataset(
    out: Path | str,
    format: DatasetKind,
    clips: int,
    seed: int,
    split_fractions: tuple[float, float, float] = (0.8, 0.1, 0.1),
) -> SynthSummary:
    """Write `clips` synthetic clips under `out` in the official `format` layout.

    `out` must be empty, missing, or hold an earlier synthetic dataset (which is replaced).
    Inter-X clips use the template body for both people: that layout stores rotations and a root
    translation only, so readers rebuild joints with the template offsets.
    """
    check_dataset_kind(format, name="format")
    if not 3 <= clips <= MAX_CLIPS:
        raise ValueError(f"clips must be between 3 and {MAX_CLIPS}, got {clips}")
    out = Path(out)
    splits = assign_splits(clips, seed, split_fractions)
    actions = assign_actions(clips, seed)
    prepare_folder(out)
    writer = InterHumanWriter(out) if format == "interhuman" else InterXWriter(out)
    threads = torch.get_num_threads()
    # Every tensor here is tiny ((T, 22, 3, 3) at most): intra-op threads only add overhead, up to
    # 10x on a busy 2-core machine. The caller's setting is restored afterwards.
    torch.set_num_threads(1)
    try:
        for index, (action, split) in enumerate(zip(actions, splits, strict=True)):
            clip = generate_clip(
                seed=seed, index=index, action=action, vary_bodies=format == "interhuman"
            )
            writer.add(index=index, clip=clip, split=split)
    finally:
        torch.set_num_threads(threads)
        writer.close(ACTIONS)
    split_sizes = {split: splits.count(split) for split in SPLITS}
    (out / "README.txt").write_text(
        _readme(format=format, clips=clips, seed=seed, split_sizes=split_sizes), encoding="utf-8"
    )
    counts = {action: actions.count(action) for action in ACTIONS}
    return SynthSummary(
        root=out,
        format=format,
        clips=clips,
        seed=seed,
        split_sizes=split_sizes,
        action_counts=counts,
    )
