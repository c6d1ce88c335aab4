"""Check a dataset folder and report every problem at once (``intermask data check DATA_ROOT``).

The dataset constructors stop at the first problem; ``check_dataset`` keeps going and lists all of
them, each naming the file and what is wrong. Clips that the readers skip on purpose (too short,
ignore list) are not problems; ``check_dataset_report`` lists them separately.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from intermask.data import interhuman as ih
from intermask.data import interx as ix
from intermask.data.common import read_id_list, read_interaction_meta
from intermask.data.errors import DataError, DataProblem, SkippedClip
from intermask.data.layout import detect_format
from intermask.motion.kinds import DatasetKind, check_dataset_kind

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


def check_dataset(root: str | Path, format: DatasetKind | None = None) -> list[DataProblem]:
    """Every problem found under ``root`` (empty list: the readers will load all splits)."""
    return check_dataset_report(root, format).problems


def check_dataset_report(root: str | Path, format: DatasetKind | None = None) -> CheckReport:
    root = Path(root)
    report = CheckReport()
    if not root.is_dir():
        report.problems.append(DataProblem(root, "dataset root not found"))
        return report
    if format is None:
        try:
            format = detect_format(root)
        except FileNotFoundError as err:
            report.problems.append(DataProblem(root, str(err)))
            return report
    if check_dataset_kind(format, name="format") == "interhuman":
        _check_interhuman(root, report)
    else:
        _check_interx(root, report)
    return report


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
