"""Recognise which official layout a dataset folder follows."""

from __future__ import annotations

from pathlib import Path

from intermask.motion.kinds import DatasetKind


def detect_format(root: Path | str) -> DatasetKind:
    """``interhuman`` when ``motions_processed/`` exists, ``interx`` when ``motions/*.h5`` or
    ``texts_processed/`` exists; otherwise a ``FileNotFoundError`` naming what was looked for."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset root {root} does not exist or is not a folder")
    if (root / "motions_processed").is_dir():
        return "interhuman"
    if (root / "texts_processed").is_dir() or any((root / "motions").glob("*.h5")):
        return "interx"
    raise FileNotFoundError(
        f"{root} follows neither official layout: expected {root / 'motions_processed'} (InterHuman) "
        f"or {root / 'motions'}/<split>.h5 with {root / 'texts_processed'} (Inter-X)"
    )
