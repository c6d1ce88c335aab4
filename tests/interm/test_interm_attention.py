import torch
from torch import nn

from intermask.interm.attention import MultiHeadAttention, SpatioTemporalAttention


def test_attention_matches_torch_multihead_attention_with_key_padding():
    torch.manual_seed(0)
    ours = MultiHeadAttention(width=16, heads=4, dropout=0.0)
    reference = nn.MultiheadAttention(16, 4, batch_first=True)
    with torch.no_grad():
        reference.in_proj_weight.copy_(torch.cat([ours.query.weight, ours.key_value.weight]))
        reference.in_proj_bias.copy_(torch.cat([ours.query.bias, ours.key_value.bias]))
        reference.out_proj.weight.copy_(ours.out.weight)
        reference.out_proj.bias.copy_(ours.out.bias)
    x, context = torch.randn(3, 5, 16), torch.randn(3, 6, 16)
    padding = torch.zeros(3, 6, dtype=torch.bool)
    padding[1, 4:] = True
    expected = reference(x, context, context, key_padding_mask=padding, need_weights=False)[0]
    torch.testing.assert_close(ours(x, context, padding), expected, atol=1e-5, rtol=1e-5)


def test_fully_padded_groups_give_zeros_and_finite_gradients():
    torch.manual_seed(0)
    attention = MultiHeadAttention(width=8, heads=2, dropout=0.0)
    x = torch.randn(2, 4, 8, requires_grad=True)
    padding = torch.tensor([[True] * 4, [False, False, True, True]])
    out = attention(x, key_padding_mask=padding)
    assert torch.isfinite(out).all()
    torch.testing.assert_close(out[0], attention.out.bias.expand(4, 8))  # zero before out-proj
    out.sum().backward()
    assert torch.isfinite(x.grad).all()


def test_spatial_mixes_only_within_a_step_and_temporal_only_within_a_row():
    torch.manual_seed(0)
    rows, steps = 5, 4
    module = SpatioTemporalAttention(width=8, heads=2, dropout=0.0)
    x = torch.randn(2, rows * steps, 8)
    padding = torch.zeros(2, rows * steps, dtype=torch.bool)
    before = module(x, x, padding, rows=rows)
    changed = x.clone()
    changed[:, 2 * steps + 1] += 1.0  # row 2, step 1
    after = module(changed, changed, padding, rows=rows)
    row, step = torch.arange(rows * steps) // steps, torch.arange(rows * steps) % steps
    spatial_same = (after.spatial - before.spatial).abs().amax(dim=(0, 2)) == 0
    temporal_same = (after.temporal - before.temporal).abs().amax(dim=(0, 2)) == 0
    assert torch.equal(spatial_same, step != 1)
    assert torch.equal(temporal_same, row != 2)


def test_temporal_attention_ignores_padded_steps():
    torch.manual_seed(0)
    module = SpatioTemporalAttention(width=8, heads=2, dropout=0.0)
    x = torch.randn(1, 5 * 4, 8)
    padding = (torch.arange(5 * 4) % 4 >= 3)[None]  # last step padded in every row
    before = module(x, x, padding, rows=5)
    changed = x.clone()
    changed[:, padding[0]] = torch.randn(1, 5, 8)
    after = module(changed, changed, padding, rows=5)
    keep = ~padding[0]
    torch.testing.assert_close(after.spatial[:, keep], before.spatial[:, keep])
    torch.testing.assert_close(after.temporal[:, keep], before.temporal[:, keep])
