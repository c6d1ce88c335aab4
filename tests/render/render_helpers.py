"""Helpers shared by the render tests."""

from __future__ import annotations

import numpy as np


def color_pixels(image: object, color: tuple[int, int, int], tolerance: int = 12) -> int:
    """Number of pixels of an RGB image within tolerance (per channel) of color."""
    array = np.asarray(image, dtype=np.int64)[..., :3]
    return int((np.abs(array - np.array(color)).max(-1) <= tolerance).sum())
