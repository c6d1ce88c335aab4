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

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from intermask.data.synthetic.clips import ACTIONS, CONTACT_ACTIONS, SynthClip, generate_clip
from intermask.data.synthetic.writers import (
    META_FILE,
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
_SPLIT_STREAM = 1  # random streams of the dataset-level draws, apart from the per-clip ones
_ACTION_STREAM = 2
# What a previous synthetic dataset (and statistics computed from it) may have left in `out`.
_OWN_ENTRIES = (
    "annots",
    "motions",
    "motions_processed",
    "split",
    "splits",
    "texts_processed",
    "stats",
    "ignore_list.txt",
    META_FILE,
    "README.txt",
)


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


_DATASET_STREAM_TAG = 0x5EED  # any non-zero word


def _dataset_rng(seed: int, stream: int) -> np.random.Generator:
    # Clip streams are SeedSequence([seed, index]). SeedSequence drops trailing zero words, so a
    # third word must be non-zero to keep dataset-level streams apart from the clip streams.
    return np.random.default_rng(np.random.SeedSequence([seed, stream, _DATASET_STREAM_TAG]))


def assign_actions(clips: int, seed: int) -> list[str]:
    """Round-robin over a seed-shuffled order of ACTIONS: every type gets clips // 14 or one more."""
    order = _dataset_rng(seed, _ACTION_STREAM).permutation(len(ACTIONS))
    return [ACTIONS[int(order[i % len(ACTIONS)])] for i in range(clips)]


def assign_splits(clips: int, seed: int, fractions: tuple[float, float, float]) -> list[str]:
    """Split name of every clip: a seeded permutation cut into train/val/test blocks; every split
    with a positive fraction gets at least one clip."""
    if (
        len(fractions) != 3
        or min(fractions) < 0
        or abs(sum(fractions) - 1.0) > 1e-6
        or fractions[0] <= 0
    ):
        raise ValueError(
            f"split_fractions must be 3 non-negative numbers summing to 1 with train > 0, got {fractions}"
        )
    sizes = [max(1, round(f * clips)) if f > 0 else 0 for f in fractions[1:]]
    train = clips - sum(sizes)
    if train < 1:
        raise ValueError(
            f"{clips} clips cannot fill the splits {fractions}; generate at least 3 clips"
        )
    labels = np.array(["train"] * train + ["val"] * sizes[0] + ["test"] * sizes[1])
    return labels[_dataset_rng(seed, _SPLIT_STREAM).permutation(clips)].tolist()


def _is_synthetic(meta: Path) -> bool:
    try:
        return json.loads(meta.read_text(encoding="utf-8")).get("format") == META_FORMAT
    except (OSError, ValueError, AttributeError):
        return False


def _prepare(out: Path) -> None:
    """Create `out`; clear it if it holds an earlier synthetic dataset; refuse anything else."""
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        if not _is_synthetic(out / META_FILE):
            raise FileExistsError(
                f"{out} is not empty and holds no synthetic dataset (no {META_FILE} with format "
                f"{META_FORMAT!r}); choose an empty folder"
            )
        for name in _OWN_ENTRIES:
            path = out / name
            if path.is_dir():
                shutil.rmtree(path)
            elif path.exists():
                path.unlink()
    out.mkdir(parents=True, exist_ok=True)


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
    _prepare(out)
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


# Imported last: the HumanML3D writer reuses the split, action and folder helpers above.
from intermask.data.synthetic.humanml3d import (  # noqa: E402
    HumanML3DSummary,
    generate_humanml3d,
)
