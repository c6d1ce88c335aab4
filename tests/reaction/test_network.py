"""The decoder: online causality, offline full attention, padding and the dropped condition."""

from __future__ import annotations

import pytest
import torch
from reaction_builders import make_net

from intermask.reaction.network import attention_masks

B, T, D = 2, 9, 262


def _inputs(seed: int = 0):
    generator = torch.Generator().manual_seed(seed)
    x_t = torch.randn(B, T, D, generator=generator)
    actor = torch.randn(B, T, D, generator=generator)
    t = torch.tensor([0.2, 0.8])
    return x_t, t, actor, torch.ones(B, T, dtype=torch.bool)


def _change_future(x: torch.Tensor, frame: int) -> torch.Tensor:
    changed = x.clone()
    changed[:, frame + 1 :] = torch.randn_like(changed[:, frame + 1 :]) * 3
    return changed


@pytest.mark.parametrize("which", ["actor", "x_t"])
def test_online_output_ignores_the_future(which):
    net = make_net(causal=True)
    x_t, t, actor, mask = _inputs()
    frame = 4
    if which == "actor":
        out, changed = net(x_t, t, actor, mask), net(x_t, t, _change_future(actor, frame), mask)
    else:
        out, changed = net(x_t, t, actor, mask), net(_change_future(x_t, frame), t, actor, mask)
    torch.testing.assert_close(changed[:, : frame + 1], out[:, : frame + 1])
    assert not torch.allclose(changed[:, frame + 1 :], out[:, frame + 1 :])


def test_offline_output_sees_the_future():
    net = make_net(causal=False)
    x_t, t, actor, mask = _inputs()
    out = net(x_t, t, actor, mask)
    for changed in (
        net(x_t, t, _change_future(actor, 4), mask),
        net(_change_future(x_t, 4), t, actor, mask),
    ):
        assert (changed[:, :5] - out[:, :5]).abs().max() > 1e-4


@pytest.mark.parametrize("causal", [True, False])
def test_padding_is_never_attended(causal):
    net = make_net(causal=causal)
    x_t, t, actor, mask = _inputs(1)
    mask[0, 6:] = False
    out = net(x_t, t, actor, mask)
    x_t2, actor2 = x_t.clone(), actor.clone()
    x_t2[0, 6:] = 100.0
    actor2[0, 6:] = -100.0
    torch.testing.assert_close(net(x_t2, t, actor2, mask)[0, :6], out[0, :6])
    torch.testing.assert_close(net(x_t2, t, actor2, mask)[1], out[1])  # the other sample too


def test_attention_masks_layout():
    mask = torch.tensor([[True, True, False]])
    self_mask, cross_mask = attention_masks(mask, causal=True)
    assert self_mask[0, 0].tolist() == [
        [True, False, False],
        [True, True, False],
        [True, True, False],
    ]
    assert cross_mask.shape == (1, 1, 3, 4) and bool(cross_mask[..., 0].all())  # z always seen
    self_full, _ = attention_masks(mask, causal=False)
    assert self_full[0, 0].tolist() == [[True, True, False]] * 3


def test_dropped_condition_is_the_null_condition():
    net = make_net(causal=True, text_dim=16)
    with torch.no_grad():
        net.null_text.normal_()
    x_t, t, actor, mask = _inputs(2)
    text = torch.randn(B, 16)
    conditioned = net(x_t, t, actor, mask, text)
    null = net(x_t, t, actor, mask, None)
    dropped = net(x_t, t, actor, mask, text, torch.tensor([True, False]))
    torch.testing.assert_close(dropped[0], null[0])
    torch.testing.assert_close(dropped[1], conditioned[1])
    assert not torch.allclose(conditioned[0], null[0])


def test_time_changes_the_prediction():
    net = make_net(causal=True)
    x_t, _, actor, mask = _inputs(3)
    early = net(x_t, torch.zeros(B), actor, mask)
    late = net(x_t, torch.ones(B), actor, mask)
    assert (early - late).abs().max() > 1e-4


def test_input_errors_name_the_problem():
    net = make_net(causal=True)
    x_t, t, actor, mask = _inputs()
    with pytest.raises(
        ValueError, match=r"x_t and actor must both be \(B, T, 262\), got \(2, 9, 10\)"
    ):
        net(x_t[..., :10], t, actor, mask)
    with pytest.raises(ValueError, match=r"frame_mask must be bool \(2, 9\)"):
        net(x_t, t, actor, mask.float())
    mask[1] = False
    with pytest.raises(ValueError, match="at least one valid frame"):
        net(x_t, t, actor, mask)
    with pytest.raises(ValueError, match=r"no text condition \(text_dim=None\)"):
        net(x_t, t, actor, torch.ones(B, T, dtype=torch.bool), torch.zeros(B, 4))
    with pytest.raises(ValueError, match="width 30 is not divisible by 4 heads"):
        make_net(causal=True).__class__(feature_dim=8, width=30, heads=4)
