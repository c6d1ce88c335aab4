"""Fixtures for the render tests: one synthetic two-person clip, shared by the whole session."""

from __future__ import annotations

import numpy as np
import pytest

from intermask.data.synthetic import SynthClip, generate_clip


@pytest.fixture(scope="session")
def synth_clip() -> SynthClip:
    """A handshake, 132 frames at 30 fps (4.4 s), both bodies with their own proportions."""
    return generate_clip(seed=0, index=0, action="handshake")


@pytest.fixture(scope="session")
def clip_joints(synth_clip: SynthClip) -> np.ndarray:
    """(T, 2, 22, 3) Y-up world joints of synth_clip."""
    return synth_clip.positions.permute(1, 0, 2, 3).numpy()
