"""Export one processed clip to .npz (``intermask data item``): what the readers feed the models.

Augmentation is off: the whole clip (or its first ``max_length`` frames), persons in file order,
person 1 as the canonical reference, no mirroring. The features are de-normalized (feature
units), so ``features`` equals ``denormalize(normalize(features))`` of a dataset item.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from intermask.data import interhuman as ih
from intermask.data import interx as ix
from intermask.data.common import read_id_list
from intermask.data.errors import DataError
from intermask.motion.interx import to_joint_positions
from intermask.motion.kinds import DatasetKind, check_dataset_kind
from intermask.utils.staging import write_atomically


class ExportedItem(NamedTuple):
    path: Path
    features: np.ndarray  # (2, T, 262) or (2, T, 56, 6)
    joints: np.ndarray  # (T, 2, 22, 3) Y-up metres
    length: int
    captions: list[str]

    def __str__(self) -> str:
        return str(self.path)


def load_item(
    root: str | Path,
    format: DatasetKind,
    split: str,
    clip_id: str,
    *,
    max_length: int | None = None,
) -> tuple[torch.Tensor, list[str]]:
    """(features (2, T, C...), captions) of one clip, augmentation off."""
    root = Path(root)
    if check_dataset_kind(format, name="format") == "interhuman":
        layout = ih.InterHumanLayout(root)
        ih.check_root(root)
        _check_listed(layout.split_file(split), split, clip_id)
        body, captions = ih.load_clip(layout, clip_id)
        body = torch.from_numpy(body[:max_length])
        if len(body) < 2:
            raise DataError(
                f"{layout.motion_file(1, clip_id)}: need at least 2 frames, got {len(body)}"
            )
        raw = ih.body_to_raw(body)
        features = ih.interaction_features(raw[:, 0], raw[:, 1]).transpose(0, 1)  # (2, T-1, 262)
        return features, captions
    layout = ix.InterXLayout(root)
    if not root.is_dir():
        raise DataError(f"{root}: dataset root not found (expected the Inter-X folder)")
    _check_listed(layout.split_file(split), split, clip_id)
    h5_path = layout.motion_file(split)
    with ix.open_h5(h5_path) as file:
        raw = ix.read_h5_clip(file, h5_path, clip_id)
    captions = [c.text for c in ix.read_captions(layout.caption_file(clip_id))]
    return ix.person_features(torch.from_numpy(raw[:max_length])), captions


def export_item(
    root: str | Path,
    format: DatasetKind,
    split: str,
    clip_id: str,
    out_path: str | Path,
    *,
    max_length: int | None = None,
) -> ExportedItem:
    """Write ``out_path`` (.npz) with features, joints (T, 2, 22, 3), length, captions, id, format."""
    features, captions = load_item(root, format, split, clip_id, max_length=max_length)
    joints = to_joint_positions(features, format)  # (T, 2, 22, 3)
    out_path = Path(out_path)
    if out_path.suffix != ".npz":  # np.savez would append it anyway
        out_path = out_path.with_name(out_path.name + ".npz")
    arrays = {
        "features": features.numpy(),
        "joints": joints.numpy(),
        "length": np.int64(features.shape[1]),
        "captions": np.array(captions),
        "id": np.array(clip_id),
        "format": np.array(format),
    }

    def write(temporary: Path) -> None:
        with temporary.open("wb") as handle:  # a handle: np.savez adds no suffix
            np.savez(handle, **arrays)

    write_atomically(out_path, write)  # the old file or the new one, never half of it
    return ExportedItem(
        out_path, features.numpy(), joints.numpy(), int(features.shape[1]), captions
    )


def _check_listed(split_path: Path, split: str, clip_id: str) -> None:
    if clip_id not in read_id_list(split_path, what=f"{split} split"):
        raise DataError(f"{split_path}: clip {clip_id!r} is not in the {split} split")
