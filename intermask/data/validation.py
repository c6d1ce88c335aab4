"""Check a dataset folder and report every problem at once (``intermask data check DATA_ROOT``).

The dataset constructors stop at the first problem; ``check_dataset`` keeps going and lists all of
them, each naming the file and what is wrong. Clips that the readers skip on purpose (too short,
ignore list) are not problems; ``check_dataset_report`` lists them separately. The same checks
cover the two-person layouts (InterHuman, Inter-X) and HumanML3D; when a HumanML3D dataset fails
to load, its DataModule reports every problem the checker finds (:func:`all_problems_error`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from intermask.data import humanml3d as hml
from intermask.data import interhuman as ih
from intermask.data import interx as ix
from intermask.data.common import (
    read_caption_lines,
    read_id_list,
    read_interaction_meta,
    read_npy,
)
from intermask.data.errors import DataError, DataProblem, SkippedClip
from intermask.data.layout import LAYOUT_KINDS, LayoutKind, detect_layout
from intermask.data.normalization import Normalizer
from intermask.motion.humanml3d import FEATURE_DIM as HML_FEATURE_DIM

SPLITS = ("train", "val", "test")


@dataclass
class CheckReport:
    """Problems (errors the readers would raise), skipped clips and usable clips per split."""

    problems: list[DataProblem] = field(default_factory=list)
    skipped: list[SkippedClip] = field(default_factory=list)
    clips: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.problems


def check_dataset(root: str | Path, format: LayoutKind | None = None) -> list[DataProblem]:
    """Every problem found under ``root`` (empty list: the readers will load all splits)."""
    return check_dataset_report(root, format).problems


def check_dataset_report(root: str | Path, format: LayoutKind | None = None) -> CheckReport:
    """``format``: "interhuman", "interx" or "humanml3d"; None = detected from the folder."""
    if format is not None and format not in LAYOUT_KINDS:
        raise ValueError(f"format must be one of {LAYOUT_KINDS}, got {format!r}")
    root = Path(root)
    report = CheckReport()
    if not root.is_dir():
        report.problems.append(DataProblem(root, "dataset root not found"))
        return report
    if format is None:
        try:
            format = detect_layout(root)
        except FileNotFoundError as err:
            report.problems.append(DataProblem(root, str(err)))
            return report
    checks = {"interhuman": _check_interhuman, "interx": _check_interx}
    checks.get(format, _check_humanml3d)(root, report)
    return report


def all_problems_error(root: str | Path, format: LayoutKind, first: DataError) -> DataError:
    """The error a dataset that failed to load with ``first`` raises: ``first`` itself when it is
    the only problem the checker finds, else one DataError listing ``first`` and every other
    problem, one per line (what ``intermask data check`` prints)."""
    try:
        problems = [str(p) for p in check_dataset(root, format)]
    except Exception:  # noqa: BLE001 - the checker must never hide the error being reported
        return first
    others = [p for p in problems if p != str(first)]
    if not others:
        return first
    lines = "\n".join(f"  {p}" for p in [str(first), *others])
    return DataError(
        f"{root}: {len(others) + 1} problems in the dataset "
        f"(`intermask data check {root}` lists them again):\n{lines}"
    )


def _problem(err: DataError) -> DataProblem:
    # Our messages are "<path>: <problem>" by construction.
    path, _, problem = str(err).partition(": ")
    return DataProblem(Path(path), problem or str(err))


def _collect(report: CheckReport, fn: Callable[..., object], *args: object) -> object | None:
    """fn(*args), or None after recording the DataError it raised."""
    try:
        return fn(*args)
    except DataError as err:
        report.problems.append(_problem(err))
        return None


def _read_splits(report: CheckReport, split_file: Callable[[str], Path]) -> dict[str, list[str]]:
    splits: dict[str, list[str]] = {}
    for split in SPLITS:
        ids = _collect(report, partial(read_id_list, what=f"{split} split"), split_file(split))
        if ids is not None:
            splits[split] = ids
    seen: dict[str, str] = {}
    for split, ids in splits.items():
        for clip_id in ids:
            if clip_id in seen:
                report.problems.append(
                    DataProblem(
                        split_file(split), f"clip {clip_id!r} is also in the {seen[clip_id]} split"
                    )
                )
            seen.setdefault(clip_id, split)
    return splits


def _check_meta(report: CheckReport, root: Path, ids: list[str]) -> None:
    meta = _collect(report, read_interaction_meta, root)
    if isinstance(meta, dict):
        missing = [i for i in ids if i not in meta]
        if missing:
            report.problems.append(
                DataProblem(
                    root / "interaction_meta.json",
                    f"no entry for {len(missing)} clips, e.g. {missing[:5]}",
                )
            )


def _finish_split(
    report: CheckReport, split_path: Path, split: str, listed: int, usable: int
) -> None:
    report.clips[split] = usable
    if usable == 0:
        report.problems.append(
            DataProblem(split_path, f"split resolves to zero clips ({listed} listed)")
        )


def _check_interhuman(root: Path, report: CheckReport, min_length: int = 15) -> None:
    layout = ih.InterHumanLayout(root)
    ignored = _collect(report, ih.read_ignore_list, layout) or set()
    splits = _read_splits(report, layout.split_file)
    for split, ids in splits.items():
        usable = 0
        for clip_id in ids:
            if clip_id in ignored:
                report.skipped.append(SkippedClip(clip_id, "on ignore_list.txt"))
                continue
            # Each file separately, so that one clip can contribute several problems.
            bodies = [
                _collect(report, ih.load_person, layout.motion_file(p, clip_id)) for p in (1, 2)
            ]
            captions = _collect(report, ih.read_caption_lines, layout.caption_file(clip_id))
            if any(b is None for b in bodies) or captions is None:
                continue
            if bodies[0].shape[0] != bodies[1].shape[0]:
                report.problems.append(
                    DataProblem(
                        layout.motion_file(2, clip_id),
                        f"expected {bodies[0].shape[0]} frames like person1, got {bodies[1].shape[0]}",
                    )
                )
            elif bodies[0].shape[0] < min_length:
                report.skipped.append(SkippedClip(clip_id, f"shorter than {min_length} frames"))
            else:
                usable += 1
        _finish_split(report, layout.split_file(split), split, len(ids), usable)
    _check_meta(report, root, [i for ids in splits.values() for i in ids if i not in ignored])


def _check_interx(
    root: Path, report: CheckReport, min_length: int = 24, max_frames: int = 1000
) -> None:
    layout = ix.InterXLayout(root)
    splits = _read_splits(report, layout.split_file)
    _collect(report, ix.read_order, layout.order_file)
    for split, ids in splits.items():
        usable = 0
        h5_path = layout.motion_file(split)
        file = _collect(report, ix.open_h5, h5_path)
        if file is None:
            continue
        with file:
            for name in ids:
                motion = _collect(report, ix.read_h5_clip, file, h5_path, name)
                captions = _collect(report, ix.read_captions, layout.caption_file(name))
                if motion is None or captions is None:
                    continue
                if min_length <= len(motion) < max_frames:
                    usable += 1
                else:
                    report.skipped.append(
                        SkippedClip(
                            name, f"{len(motion)} frames, outside [{min_length}, {max_frames})"
                        )
                    )
        _finish_split(report, layout.split_file(split), split, len(ids), usable)
    _check_meta(report, root, [i for ids in splits.values() for i in ids])


def _statistics_file(path: Path) -> np.ndarray:
    """A (263,) finite statistics array (Mean.npy or Std.npy); DataError naming the file."""
    array = read_npy(path, what="statistics")
    if tuple(array.shape) != (HML_FEATURE_DIM,):
        raise DataError(f"{path}: expected shape ({HML_FEATURE_DIM},), got {tuple(array.shape)}")
    if not np.issubdtype(array.dtype, np.floating) or not np.isfinite(array).all():
        raise DataError(f"{path}: expected finite float values, got dtype {array.dtype} or NaN/Inf")
    return array


def _check_humanml3d_statistics(report: CheckReport, layout: hml.HumanML3DLayout) -> None:
    mean, std = (_collect(report, _statistics_file, p) for p in (layout.mean_file, layout.std_file))
    if mean is not None and std is not None:
        _collect(report, partial(Normalizer, source=str(layout.std_file)), mean, std)  # std > 0


def _check_tagged_captions(report: CheckReport, path: Path) -> bool:
    """Every line of a HumanML3D caption file, each bad line a problem; True when all are good."""
    lines = _collect(report, read_caption_lines, path)
    if lines is None:
        return False
    parsed = [
        _collect(report, hml.parse_tagged_caption, line, path, number)
        for number, line in enumerate(lines, start=1)
    ]
    return all(caption is not None for caption in parsed)


def _humanml3d_clip_frames(
    report: CheckReport, layout: hml.HumanML3DLayout, split_file: Path, clip_id: str
) -> int | None:
    """Frames of a listed clip whose motion and caption files are good, else None (problems
    recorded: an id without either file is one problem of its split file)."""
    motion_file, caption_file = layout.motion_file(clip_id), layout.caption_file(clip_id)
    if not motion_file.exists() and not caption_file.exists():
        report.problems.append(
            DataProblem(
                split_file,
                f"clip {clip_id!r} has no files (expected {motion_file} and {caption_file})",
            )
        )
        return None
    what = f"motion (listed in {split_file.name})"
    load = partial(hml.load_npy, trailing=(HML_FEATURE_DIM,), what=what)
    motion = _collect(report, load, motion_file)
    captions_good = _check_tagged_captions(report, caption_file)
    return len(motion) if motion is not None and captions_good else None


def _check_humanml3d(
    root: Path, report: CheckReport, min_length: int = 40, max_frames: int = 200
) -> None:
    """HumanML3D's release: Mean/Std, the split files, every listed clip's vectors and captions
    (the reader's [min_length, max_frames) rule decides which clips are skipped)."""
    layout = hml.HumanML3DLayout(root)
    _check_humanml3d_statistics(report, layout)
    splits = _read_splits(report, layout.split_file)
    for split, ids in splits.items():
        usable = 0
        for clip_id in ids:
            frames = _humanml3d_clip_frames(report, layout, layout.split_file(split), clip_id)
            if frames is None:
                continue
            if min_length <= frames < max_frames:
                usable += 1
            else:
                reason = f"{frames} frames, outside [{min_length}, {max_frames})"
                report.skipped.append(SkippedClip(clip_id, reason))
        _finish_split(report, layout.split_file(split), split, len(ids), usable)
