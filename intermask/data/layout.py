"""Recognise which official layout a dataset folder follows."""

from __future__ import annotations

from pathlib import Path
from typing import Literal, get_args

from intermask.motion.kinds import DatasetKind

# The two-person dataset kinds, and HumanML3D (one person, read by intermask.data.humanml3d).
LayoutKind = Literal["interhuman", "interx", "humanml3d"]
LAYOUT_KINDS: tuple[LayoutKind, ...] = get_args(LayoutKind)


def detect_layout(root: Path | str) -> LayoutKind:
    """``interhuman`` when ``motions_processed/`` exists, ``interx`` when ``motions/*.h5`` or
    ``texts_processed/`` exists, ``humanml3d`` when ``new_joint_vecs/`` exists; otherwise a
    ``FileNotFoundError`` naming what was looked for."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset root {root} does not exist or is not a folder")
    if (root / "motions_processed").is_dir():
        return "interhuman"
    if (root / "texts_processed").is_dir() or any((root / "motions").glob("*.h5")):
        return "interx"
    if (root / "new_joint_vecs").is_dir():
        return "humanml3d"
    raise FileNotFoundError(
        f"{root} follows no official layout: expected {root / 'motions_processed'} (InterHuman), "
        f"{root / 'motions'}/<split>.h5 with {root / 'texts_processed'} (Inter-X) "
        f"or {root / 'new_joint_vecs'} (HumanML3D)"
    )


def detect_format(root: Path | str) -> DatasetKind:
    """The two-person dataset kind of ``root`` (:func:`detect_layout`); a ValueError for a
    HumanML3D folder, which the two-person readers do not read."""
    layout = detect_layout(root)
    if layout == "humanml3d":
        raise ValueError(
            f"{root} is a HumanML3D folder (one person): this command reads InterHuman and "
            "Inter-X folders (`intermask data check` validates HumanML3D folders too)"
        )
    return layout
