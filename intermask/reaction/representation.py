"""The space the flow runs in: one flat vector per person and frame, and its way back to joints.

InterHuman: the 262-d feature, z-scored with the dataset statistics (normalized space).
Inter-X: the (56, 6) representation flattened to 336 values (not normalized, as the reference
trains on it). Joints come from the de-normalized features: InterHuman's positions directly,
Inter-X's through forward kinematics of the 22 body rows on our template skeleton.
The statistics are buffers, so a checkpoint carries them.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from intermask.motion import interhuman as ih
from intermask.motion import interx as ix
from intermask.motion.kinds import DatasetKind, check_dataset_kind

FEATURE_SHAPES: dict[str, tuple[int, ...]] = {
    "interhuman": (ih.FEATURE_DIM,),
    "interx": (ix.NUM_ROWS, ix.RAW_CHANNELS),
}


class FeatureSpace(nn.Module):
    """Normalized flat vectors (..., T, D) <-> dataset features (..., T, *F) and joints.

    representation: "interhuman" (D = 262) or "interx" (D = 56 * 6 = 336).
    up_axis: the raw frame of Inter-X translations ("z" for the release); joints are Y-up.
    """

    def __init__(self, *, representation: DatasetKind, up_axis: str = "z") -> None:
        super().__init__()
        check_dataset_kind(representation, name="representation")
        self.representation, self.up_axis = representation, up_axis
        self.feature_shape = FEATURE_SHAPES[representation]
        self.register_buffer("mean", torch.zeros(self.feature_shape))
        self.register_buffer("std", torch.ones(self.feature_shape))

    @property
    def dim(self) -> int:
        return math.prod(self.feature_shape)

    def set_statistics(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Copy a dataset Normalizer's mean and std (shape ``feature_shape``)."""
        mean = torch.as_tensor(mean, dtype=torch.float32)
        std = torch.as_tensor(std, dtype=torch.float32)
        if mean.shape != self.feature_shape or std.shape != self.feature_shape:
            raise ValueError(
                f"{self.representation} statistics must have shape {self.feature_shape}, got "
                f"{tuple(mean.shape)} and {tuple(std.shape)}"
            )
        self.mean.copy_(mean)
        self.std.copy_(std)

    def flatten(self, features: torch.Tensor) -> torch.Tensor:
        """(..., T, *F) -> (..., T, D)."""
        n = len(self.feature_shape)
        if tuple(features.shape[features.ndim - n :]) != self.feature_shape:
            raise ValueError(
                f"expected {self.representation} features (..., T, "
                f"{', '.join(map(str, self.feature_shape))}), got {tuple(features.shape)}"
            )
        return features.reshape(*features.shape[: features.ndim - n], self.dim)

    def unflatten(self, x: torch.Tensor) -> torch.Tensor:
        """(..., T, D) -> (..., T, *F)."""
        if x.shape[-1] != self.dim:
            raise ValueError(f"expected (..., T, {self.dim}) vectors, got {tuple(x.shape)}")
        return x.reshape(*x.shape[:-1], *self.feature_shape)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        """(..., T, D) normalized vectors -> (..., T, *F) dataset features."""
        return self.unflatten(x) * self.std + self.mean

    def joints(self, x: torch.Tensor) -> torch.Tensor:
        """(..., T, D) normalized vectors -> (..., T, 22, 3) joint positions, metres, Y-up."""
        return self.feature_joints(self.denormalize(x))

    def feature_joints(self, features: torch.Tensor) -> torch.Tensor:
        """(..., T, *F) de-normalized features -> (..., T, 22, 3) joint positions."""
        return ix.person_joint_positions(features, self.representation, up_axis=self.up_axis)
