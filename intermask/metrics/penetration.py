"""Intersection Volume (IV) and Intersection Frequency (IF) of two persons (ARFlow section 4.1).

IntersectionVolume and IntersectionFrequency measure the skeleton capsule proxy of
``intermask.physics``, so their numbers compare with each other, not with the ARFlow tables;
MeshIntersectionVolume and MeshIntersectionFrequency measure the two bodies' meshes (fitted
SMPL-H / SMPL-X bodies, ``intermask.body``), ARFlow's own definition. The math lives in
``intermask.physics.volume``; these classes only accumulate it. Sums are float64 states reduced by
summation, so DDP gathers them exactly.
"""

from __future__ import annotations

import torch
from torchmetrics import Metric

from intermask.physics.capsules import BodyProxy
from intermask.physics.mesh_volume import mesh_intersection_volume
from intermask.physics.volume import (
    DEFAULT_CHUNK_VOXELS,
    DEFAULT_PITCH,
    DEFAULT_TOLERANCE,
    intersection_volume,
    penetrating_frames,
)


class _PenetrationMetric(Metric):
    full_state_update = False
    higher_is_better = False

    def __init__(
        self,
        *,
        pitch: float = DEFAULT_PITCH,
        proxy: BodyProxy | None = None,
        chunk_voxels: int = DEFAULT_CHUNK_VOXELS,
    ) -> None:
        super().__init__()
        if not pitch > 0:
            raise ValueError(f"{type(self).__name__}: pitch must be > 0 metres, got {pitch}")
        self.pitch = pitch
        self.proxy = proxy
        self.chunk_voxels = chunk_voxels
        self.add_state(
            "total", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum"
        )
        self.add_state(
            "frames", default=torch.tensor(0.0, dtype=torch.float64), dist_reduce_fx="sum"
        )

    def _volumes(
        self, joints_a: torch.Tensor, joints_b: torch.Tensor, frame_mask: torch.Tensor | None
    ) -> torch.Tensor:
        """(B, T, 22, 3) x2, (B, T) | None -> IV (V,) in cm^3 of the valid frames."""
        if joints_a.ndim != 4:
            raise ValueError(
                f"{type(self).__name__}.update: joints must be (B, T, 22, 3), got "
                f"{tuple(joints_a.shape)}"
            )
        volume = intersection_volume(
            joints_a,
            joints_b,
            pitch=self.pitch,
            proxy=self.proxy,
            frame_mask=frame_mask,
            chunk_voxels=self.chunk_voxels,
        )
        return volume if frame_mask is None else volume[frame_mask]

    def _accumulate(self, volume: torch.Tensor) -> None:
        raise NotImplementedError

    def update(
        self,
        joints_a: torch.Tensor | None = None,
        joints_b: torch.Tensor | None = None,
        frame_mask: torch.Tensor | None = None,
        *,
        volumes: torch.Tensor | None = None,
    ) -> None:
        """The two persons' joints (and valid frames), or ``volumes``: the (V,) intersection
        volumes in cm^3 of V valid frames computed elsewhere (the evaluation rows compute them
        once for both metrics)."""
        if volumes is None:
            if joints_a is None or joints_b is None:
                raise ValueError(
                    f"{type(self).__name__}.update: give joints_a and joints_b, or volumes"
                )
            volumes = self._volumes(joints_a, joints_b, frame_mask)
        self._accumulate(volumes)

    def _mean(self) -> torch.Tensor:
        if self.frames == 0:
            raise ValueError(f"{type(self).__name__}.compute() called before any valid frame")
        return (self.total / self.frames).float()


class IntersectionVolume(_PenetrationMetric):
    """Mean per-frame intersection volume in cm^3 over valid frames (ARFlow eq. 18).

    ``update(joints_a (B, T, 22, 3), joints_b (B, T, 22, 3), frame_mask (B, T) bool | None)``,
    joints in metres.
    """

    def _accumulate(self, volume: torch.Tensor) -> None:
        self.total += volume.double().sum().to(self.total.device)
        self.frames += volume.numel()

    def compute(self) -> torch.Tensor:
        return self._mean()


class IntersectionFrequency(_PenetrationMetric):
    """Share in [0, 1] of valid frames whose intersection volume exceeds `tolerance` cm^3.

    ``update(joints_a (B, T, 22, 3), joints_b (B, T, 22, 3), frame_mask (B, T) bool | None)``.
    """

    def __init__(
        self,
        *,
        pitch: float = DEFAULT_PITCH,
        proxy: BodyProxy | None = None,
        tolerance: float = DEFAULT_TOLERANCE,
        chunk_voxels: int = DEFAULT_CHUNK_VOXELS,
    ) -> None:
        super().__init__(pitch=pitch, proxy=proxy, chunk_voxels=chunk_voxels)
        if tolerance < 0:
            raise ValueError(f"IntersectionFrequency: tolerance must be >= 0 cm^3, got {tolerance}")
        self.tolerance = tolerance

    def _accumulate(self, volume: torch.Tensor) -> None:
        hits = penetrating_frames(volume, tolerance=self.tolerance).double().sum()
        self.total += hits.to(self.total.device)
        self.frames += volume.numel()

    def compute(self) -> torch.Tensor:
        return self._mean()


class _MeshPenetration:
    """``update`` of the mesh measures: the two bodies' meshes instead of their joints."""

    pitch: float
    chunk_voxels: int

    def update(
        self,
        vertices_a: torch.Tensor | None = None,
        vertices_b: torch.Tensor | None = None,
        faces_a: torch.Tensor | None = None,
        faces_b: torch.Tensor | None = None,
        frame_mask: torch.Tensor | None = None,
        *,
        volumes: torch.Tensor | None = None,
    ) -> None:
        """vertices_* (B, T, V, 3) in metres, faces (F, 3) (faces_b: faces_a when None), frame_mask
        (B, T) bool | None; or ``volumes``: the (V,) mesh intersection volumes in cm^3 of the
        valid frames, computed elsewhere."""
        if volumes is None:
            if vertices_a is None or vertices_b is None or faces_a is None:
                raise ValueError(
                    f"{type(self).__name__}.update: give vertices_a, vertices_b and faces_a, or volumes"
                )
            volumes = mesh_intersection_volume(
                vertices_a, vertices_b, faces_a, faces_b, pitch=self.pitch, frame_mask=frame_mask
            )
            volumes = volumes if frame_mask is None else volumes[frame_mask]
        self._accumulate(volumes.reshape(-1))  # type: ignore[attr-defined]


class MeshIntersectionVolume(_MeshPenetration, IntersectionVolume):
    """Mean per-frame intersection volume in cm^3 of the two bodies' meshes (ARFlow's definition,
    intermask.physics.mesh_volume) over valid frames.

    ``update(vertices_a (B, T, V, 3), vertices_b (B, T, V', 3), faces_a (F, 3), faces_b, frame_mask)``.
    """


class MeshIntersectionFrequency(_MeshPenetration, IntersectionFrequency):
    """Share in [0, 1] of valid frames whose mesh intersection volume exceeds `tolerance` cm^3."""
