"""The two dataset kinds the framework reads: each is an official release layout and the motion
representation that comes with it (InterHuman's 262-d joint features, Inter-X's SMPL-X rotations).
"""

from __future__ import annotations

from typing import Literal, get_args

DatasetKind = Literal["interhuman", "interx"]
DATASET_KINDS: tuple[DatasetKind, ...] = get_args(DatasetKind)


def check_dataset_kind(value: str, *, name: str = "dataset") -> DatasetKind:
    """``value`` as a :data:`DatasetKind`, or a ValueError naming ``name`` and the choices."""
    if value not in DATASET_KINDS:
        raise ValueError(f"{name} must be one of {DATASET_KINDS}, got {value!r}")
    return value  # type: ignore[return-value]
