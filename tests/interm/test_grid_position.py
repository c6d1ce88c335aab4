import math

import pytest
import torch

from intermask.interm import position
from intermask.interm.position import add_grid_encoding, grid_encoding


def _direct(row: int, t: int, channel: int, dim: int) -> float:
    half = dim // 2
    position, c = (row, channel) if channel < half else (t, channel - half)
    angle = position / 10000 ** ((c - c % 2) / half)
    return math.sin(angle) if c % 2 == 0 else math.cos(angle)


@pytest.mark.parametrize(("row", "t"), [(0, 0), (3, 7), (4, 11)])
def test_encoding_matches_the_direct_formula(row: int, t: int):
    dim, rows, steps = 384, 5, 12
    grid = grid_encoding(rows, steps, dim)
    assert grid.shape == (rows * steps, dim)
    expected = torch.tensor([_direct(row, t, c, dim) for c in range(dim)])
    torch.testing.assert_close(grid[row * steps + t], expected, atol=1e-6, rtol=0)


def test_both_persons_get_the_same_encoding_and_sep_none():
    x = torch.zeros(2, 2 * 5 * 3 + 1, 8)
    y = add_grid_encoding(x, rows=5, steps=3)
    torch.testing.assert_close(y[:, :15], y[:, 16:])
    assert torch.equal(y[:, 15], x[:, 15])
    assert torch.equal(y[0, :15], grid_encoding(5, 3, 8))


def test_width_must_split_into_sin_cos_pairs_per_axis():
    with pytest.raises(ValueError, match="divisible by 4, got 6"):
        grid_encoding(5, 3, 6)


def test_the_cached_encoding_first_built_in_inference_mode_serves_training():
    """The encoding is built once per shape; one first built under inference mode must still
    let a later training forward backpropagate (inference tensors cannot be saved for it)."""
    with torch.inference_mode():
        first = add_grid_encoding(torch.zeros(1, 2 * 4 * 7 + 1, 12), rows=4, steps=7)
    x = torch.randn(2, 2 * 4 * 7 + 1, 12, requires_grad=True)
    y = add_grid_encoding(x, rows=4, steps=7)
    (y * y).sum().backward()
    torch.testing.assert_close(x.grad, 2 * y.detach())
    assert not position._pair_encoding(4, 7, 12, x.device, x.dtype).is_inference()
    grid = grid_encoding(4, 7, 12)
    assert torch.equal(first[0], torch.cat([grid, torch.zeros(1, 12), grid]))
    # a second dtype gets its own entry, not a cast of the first
    half = add_grid_encoding(torch.zeros(1, 57, 12, dtype=torch.bfloat16), rows=4, steps=7)
    assert half.dtype == torch.bfloat16
    torch.testing.assert_close(half[0].float(), first[0], atol=1e-2, rtol=1e-2)
