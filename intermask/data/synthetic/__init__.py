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

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import torch

from intermask.data.common import single_threaded
from intermask.data.synthetic.clips import SynthClip, generate_clip
from intermask.data.synthetic.humanml3d import HumanML3DSummary, generate_humanml3d
from intermask.data.synthetic.planning import assign_actions, assign_splits, prepare_folder
from intermask.data.synthetic.writers import (
    META_FORMAT,
    SPLITS,
    InterHumanWriter,
    InterXWriter,
)
from intermask.motion.actions import ACTIONS, CONTACT_ACTIONS
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
# A worker costs its start-up and the pickling of its clips back (one clip takes ~0.06 s on one
# core), so smaller datasets are generated in-process.
CLIPS_PER_WORKER = 200


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


def default_workers(clips: int) -> int:
    """Processes :func:`generate_dataset` uses by default: one per usable core where processes
    start by fork (Linux), none for fewer than ``CLIPS_PER_WORKER`` clips each. Elsewhere a
    spawned worker would import the caller's main module again, so the default stays in-process."""
    if not _forks():
        return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity call on this platform
        cores = os.cpu_count() or 1
    return max(1, min(cores, clips // CLIPS_PER_WORKER))


def generate_dataset(
    out: Path | str,
    format: DatasetKind,
    clips: int,
    seed: int,
    split_fractions: tuple[float, float, float] = (0.8, 0.1, 0.1),
    workers: int | None = None,
) -> SynthSummary:
    """Write `clips` synthetic clips under `out` in the official `format` layout.

    `out` must be empty, missing, or hold an earlier synthetic dataset (which is replaced).
    Inter-X clips use the template body for both people: that layout stores rotations and a root
    translation only, so readers rebuild joints with the template offsets. `workers` processes
    generate the clips (None: :func:`default_workers`; see :func:`_clips` for how they start);
    every clip depends on (seed, index) only, so the bytes written are the same for any number.
    """
    check_dataset_kind(format, name="format")
    if not 3 <= clips <= MAX_CLIPS:
        raise ValueError(f"clips must be between 3 and {MAX_CLIPS}, got {clips}")
    workers = default_workers(clips) if workers is None else workers
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    out = Path(out)
    splits = assign_splits(clips, seed, split_fractions)
    actions = assign_actions(clips, seed)
    prepare_folder(out)
    writer = InterHumanWriter(out) if format == "interhuman" else InterXWriter(out)
    jobs = [(seed, index, action, format == "interhuman") for index, action in enumerate(actions)]
    # Every tensor here is tiny ((T, 22, 3, 3) at most): intra-op threads only add overhead, up to
    # 10x on a busy 2-core machine. The caller's setting is restored afterwards.
    try:
        with single_threaded():
            for index, (clip, split) in enumerate(zip(_clips(jobs, workers), splits, strict=True)):
                writer.add(index=index, clip=clip, split=split)
    finally:
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


def _forks() -> bool:
    """Whether new processes start by fork on this platform by default (Linux)."""
    return multiprocessing.get_all_start_methods()[0] == "fork"


def _one_thread() -> None:
    torch.set_num_threads(1)


def _clip(job: tuple[int, int, str, bool]) -> SynthClip:
    seed, index, action, vary_bodies = job
    return generate_clip(seed=seed, index=index, action=action, vary_bodies=vary_bodies)


def _clips(jobs: list[tuple[int, int, str, bool]], workers: int) -> Iterator[SynthClip]:
    """The clips of ``jobs`` in order, from ``workers`` processes (1: this one). Workers are forked
    where that is the platform's default (Linux), as PyTorch's data loader workers are; elsewhere
    (macOS, Windows) they are spawned and import the caller's main module, which then needs an
    ``if __name__ == "__main__"`` guard."""
    if workers == 1:
        yield from map(_clip, jobs)
        return
    context = multiprocessing.get_context("fork" if _forks() else "spawn")
    chunk = max(1, len(jobs) // (4 * workers))
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_one_thread) as pool:
        yield from pool.map(_clip, jobs, chunksize=chunk)
