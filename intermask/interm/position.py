"""2D sinusoidal positional encoding of a person's (rows, T') token grid (Wang & Liu 2021).

InterMask section 3.2.2 adds the same encoding to both persons' grids: channels ``0..D/2-1``
encode the body-part row, ``D/2..D-1`` the time step, each half as interleaved sin/cos pairs with
frequencies ``10000^(-2i / (D/2))`` (the ``PositionalEncoding2D`` the reference uses). [SEP] gets
none, and there is no person embedding, so the model is invariant to swapping persons.
"""

from __future__ import annotations

from functools import lru_cache

import torch


def axis_frequencies(channels: int) -> torch.Tensor:
    """(channels / 2,) float64 frequencies ``w_i = 10000^(-2i / channels)`` of one axis."""
    return 10000.0 ** (-torch.arange(0, channels, 2, dtype=torch.float64) / channels)


def _axis_encoding(positions: torch.Tensor, channels: int) -> torch.Tensor:
    """(P,) positions -> (P, channels): [sin(p w_0), cos(p w_0), sin(p w_1), cos(p w_1), ...]."""
    angles = positions.double()[:, None] * axis_frequencies(channels)[None, :]
    return torch.stack([angles.sin(), angles.cos()], dim=-1).flatten(-2)


def grid_encoding(
    rows: int, steps: int, dim: int, *, device: torch.device | None = None
) -> torch.Tensor:
    """(rows * T', D) float32 encoding, flattened joint-major (index ``row * T' + t``)."""
    if dim % 4:
        raise ValueError(f"the 2D sinusoidal encoding needs a width divisible by 4, got {dim}")
    half = dim // 2
    row_part = _axis_encoding(torch.arange(rows), half)  # (rows, D/2)
    time_part = _axis_encoding(torch.arange(steps), half)  # (T', D/2)
    grid = torch.cat(
        [
            row_part[:, None, :].expand(rows, steps, half),
            time_part[None, :, :].expand(rows, steps, half),
        ],
        dim=-1,
    )
    return grid.reshape(rows * steps, dim).to(device=device, dtype=torch.float32)


def add_grid_encoding(x: torch.Tensor, *, rows: int, steps: int) -> torch.Tensor:
    """(B, 2N + 1, D) embeddings of ``[A, SEP, B]`` -> the same with the encoding on A and B."""
    n = rows * steps
    if x.shape[1] != 2 * n + 1:
        raise ValueError(
            f"expected (B, {2 * n + 1}, D) for rows={rows}, steps={steps}, got {tuple(x.shape)}"
        )
    return x + _pair_encoding(rows, steps, x.shape[-1], x.device, x.dtype)


@lru_cache(maxsize=64)
def _pair_encoding(
    rows: int, steps: int, dim: int, device: torch.device, dtype: torch.dtype
) -> torch.Tensor:
    """(2N + 1, D) ``[grid, 0, grid]``, built once per shape, device and dtype: rebuilt every
    forward it cost 10-20% of a GPU decoding pass (float64 sin/cos on the host, then a copy).

    Made outside inference mode, so a tensor first built under ``torch.inference_mode`` can
    still be used by a training forward afterwards.
    """
    with torch.inference_mode(False), torch.no_grad():
        grid = grid_encoding(rows, steps, dim, device=device).to(dtype)
        return torch.cat([grid, grid.new_zeros(1, dim), grid], dim=0)
