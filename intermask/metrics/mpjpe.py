"""Mean per-joint position error."""

from __future__ import annotations

import torch
from torchmetrics import Metric


def per_joint_errors(prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(..., J, 3) x2 -> (..., J) Euclidean distances."""
    if prediction.shape != target.shape or prediction.shape[-1] != 3:
        raise ValueError(
            f"MPJPE needs two (..., J, 3) tensors of one shape, got {tuple(prediction.shape)} "
            f"and {tuple(target.shape)}"
        )
    return torch.linalg.vector_norm(prediction - target, dim=-1)


class MPJPE(Metric):
    """Mean over valid frames and joints of the joint position error, in the input's unit x ``scale``.

    ``update(prediction (B, T, J, 3), target (B, T, J, 3), frame_mask (B, T) bool | None)``.
    Sums are float64 states reduced by summation, so DDP gathers them exactly.
    """

    full_state_update = False
    higher_is_better = False

    def __init__(self, *, scale: float = 1000.0) -> None:
        super().__init__()
        self.scale = scale
        self.add_state(
            "error_sum", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum"
        )
        self.add_state(
            "count", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum"
        )

    def update(
        self, prediction: torch.Tensor, target: torch.Tensor, frame_mask: torch.Tensor | None = None
    ) -> None:
        errors = per_joint_errors(prediction.double(), target.double())  # (B, T, J)
        if frame_mask is not None:
            errors = errors[frame_mask]
        self.error_sum += errors.sum()
        self.count += errors.numel()

    def compute(self) -> torch.Tensor:
        if self.count == 0:
            raise ValueError("MPJPE.compute() called before any update")
        return (self.error_sum / self.count * self.scale).float()
