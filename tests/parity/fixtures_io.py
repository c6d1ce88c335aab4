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


def weight_recipe(
    state: Mapping[str, torch.Tensor], *, keep: tuple[str, ...] = ()
) -> dict[str, Any]:
    """How to rebuild ``state`` with random values of sensible magnitudes: per key either the
    tensor itself (keys starting with one of ``keep``, e.g. a position encoding's buffer, and
    integer or boolean tensors) or ``(shape, mean, std)``: matrices and kernels ``N(0, 1/fan_in)``
    (as a default init: activations keep their size, so a tolerance means something), vectors
    named ``weight`` (norm scales) ``N(1, 0.1^2)``, other vectors ``N(0, 0.1^2)``, scalars 1."""
    recipe: dict[str, Any] = {}
    for key, value in state.items():
        if key.startswith(keep) or not value.is_floating_point():
            recipe[key] = value.detach().clone()
        elif value.ndim >= 2:
            recipe[key] = (tuple(value.shape), 0.0, float(value[0].numel()) ** -0.5)
        elif value.ndim == 1:
            norm = key.endswith("weight")
            recipe[key] = (tuple(value.shape), 1.0 if norm else 0.0, 0.1)
        else:
            recipe[key] = ((), 1.0, 0.0)
    return recipe


def build_state(recipe: Mapping[str, Any], *, seed: int) -> dict[str, torch.Tensor]:
    """The tensors of a :func:`weight_recipe`, drawn as :func:`seeded_state` draws them."""
    state = {}
    for key, entry in recipe.items():
        if isinstance(entry, torch.Tensor):
            state[key] = entry.clone()
            continue
        shape, mean, std = entry
        values = np.random.RandomState(key_seed(seed, key)).standard_normal(shape) * std + mean
        state[key] = torch.from_numpy(np.asarray(values, dtype=np.float32))
    return state
