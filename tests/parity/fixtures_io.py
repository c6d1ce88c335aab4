"""Parity fixtures: what the authors' code gave on fixed inputs, with the weights it was given.

A fixture stores no weights, only their recipe: every tensor of a state dict is drawn from
numpy's legacy ``RandomState`` (its stream is frozen across numpy versions) with a seed per key,
so a fixture of a 100M-parameter layout is a few kilobytes and the tests rebuild exactly the
weights the authors' model ran with. Written by ``tools/parity/*.py --write-fixture``; read by
``tests/parity/test_*.py`` with ``weights_only=True``.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

FIXTURES = Path(__file__).resolve().parent / "fixtures"
MAX_FIXTURE_BYTES = 1 << 20  # keep test data well under 1 MB each


def key_seed(seed: int, key: str) -> int:
    """The seed of one tensor: the fixture's seed and the key's CRC32 (stable everywhere)."""
    return (seed * 1_000_003 + zlib.crc32(key.encode())) % (2**32)


def seeded_state(
    shapes: Mapping[str, tuple[int, ...]],
    *,
    seed: int,
    scale: float = 0.02,
    overrides: Mapping[str, float] | None = None,
) -> dict[str, torch.Tensor]:
    """float32 tensors ``N(0, scale^2)`` per key (``overrides``: another scale for keys that
    end with a given suffix, e.g. ``{"weight": 1.0}`` for norms; first match wins)."""
    state = {}
    for key, shape in shapes.items():
        std = scale
        for suffix, value in (overrides or {}).items():
            if key.endswith(suffix):
                std = value
                break
        values = np.random.RandomState(key_seed(seed, key)).standard_normal(shape) * std
        state[key] = torch.from_numpy(values.astype(np.float32))
    return state


def save_fixture(name: str, payload: dict[str, Any]) -> Path:
    """``tests/parity/fixtures/<name>.pt``; refuses one over :data:`MAX_FIXTURE_BYTES`."""
    path = FIXTURES / f"{name}.pt"
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(payload, path)
    size = path.stat().st_size
    if size > MAX_FIXTURE_BYTES:
        path.unlink()
        raise ValueError(f"{path}: {size} bytes, over {MAX_FIXTURE_BYTES}: shrink the inputs")
    return path


def load_fixture(name: str) -> dict[str, Any]:
    return torch.load(FIXTURES / f"{name}.pt", weights_only=True)
