"""Fixtures for the motion tests (builders in motion_builders.py)."""

from __future__ import annotations

from collections.abc import Callable

import pytest
import torch
from motion_builders import SkeletonMotion, build_motion, random_motion


@pytest.fixture
def generator() -> torch.Generator:
    return torch.Generator().manual_seed(1234)


@pytest.fixture
def make_motion(generator: torch.Generator) -> Callable[..., SkeletonMotion]:
    """make_motion(frames=24, yaw=None, root_xz=None) -> SkeletonMotion (fresh random draw per call)."""

    def make(**kwargs) -> SkeletonMotion:
        return random_motion(generator, **kwargs)

    return make


@pytest.fixture
def make_built_motion(
    generator: torch.Generator,
) -> Callable[[torch.Tensor, torch.Tensor], SkeletonMotion]:
    """make_built_motion(local_rotations (T, 22, 3, 3), root_position (T, 3)) -> SkeletonMotion."""

    def make(local_rotations: torch.Tensor, root_position: torch.Tensor) -> SkeletonMotion:
        return build_motion(local_rotations, root_position, generator)

    return make
