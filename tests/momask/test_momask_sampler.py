"""MoMask decoding: guidance, mask-predict, residual layers, the sampler over a tiny VQ-VAE."""

from __future__ import annotations

import pytest
import torch

from intermask.momask.sampler import (
    MoMaskSampler,
    classifier_free_guidance,
    decode_base,
    decode_residual,
    guided_logits,
)
from tests.momask.momask_tiny import CODES, make_mask_net, make_residual_net, make_vq


def _text(batch: int, seed: int = 1) -> torch.Tensor:
    return torch.randn(batch, 64, generator=torch.Generator().manual_seed(seed))


def test_guidance_moves_the_conditional_logits_away_from_the_unconditional():
    cond, uncond = torch.tensor([2.0, 0.0, -1.0]), torch.tensor([1.0, 1.0, -1.0])
    assert torch.equal(classifier_free_guidance(cond, uncond, 4.0), torch.tensor([5.0, -3.0, -1.0]))
    assert torch.equal(classifier_free_guidance(cond, uncond, 1.0), cond)
    assert torch.equal(classifier_free_guidance(cond, uncond, 0.0), uncond)


def test_guided_logits_run_conditional_and_null_rows_in_one_doubled_batch():
    calls = []

    def run(copies: int, drop: torch.Tensor) -> torch.Tensor:
        calls.append((copies, drop.tolist()))
        # a toy network: conditional rows give 3, null rows give 1
        return torch.where(drop, 1.0, 3.0)[:, None].expand(-1, 2)

    guided = guided_logits(run, 2, True, 4.0, torch.device("cpu"))
    assert calls == [(2, [False, False, True, True])]
    assert torch.equal(guided, torch.full((2, 2), 1.0 + 4.0 * (3.0 - 1.0)))
    calls.clear()
    assert torch.equal(
        guided_logits(run, 2, True, 1.0, torch.device("cpu")), torch.full((2, 2), 3.0)
    )
    assert torch.equal(guided_logits(run, 2, False, 4.0, torch.device("cpu")), torch.ones(2, 2))
    assert calls == [(1, [False, False]), (1, [True, True])]


def test_base_decoding_fills_every_valid_step_and_pads_the_rest():
    net = make_mask_net()
    lengths = torch.tensor([9, 4, 1])
    tokens = decode_base(
        net, _text(3), lengths, steps=10, generator=torch.Generator().manual_seed(0)
    )
    assert tokens.shape == (3, 10) and tokens.dtype == torch.long
    for row, length in enumerate(lengths.tolist()):
        assert ((tokens[row, :length] >= 0) & (tokens[row, :length] < CODES)).all()
        assert (tokens[row, length:] == -1).all()
    assert not (tokens == net.vocabulary.mask_id).any() and net.training  # mode restored


def test_seeded_base_decoding_is_reproducible():
    net = make_mask_net()
    lengths = torch.tensor([12, 7])

    def draw(seed: int) -> torch.Tensor:
        return decode_base(net, _text(2), lengths, generator=torch.Generator().manual_seed(seed))

    assert torch.equal(draw(3), draw(3))
    assert not torch.equal(draw(3), draw(4))


def test_each_iteration_keeps_what_it_decided():
    net = make_mask_net()
    seen = []
    # the tokens of each pass (the first copy of the doubled guidance batch)
    net.register_forward_pre_hook(lambda module, args: seen.append(args[0][:1].clone()))
    final = decode_base(net, _text(1), torch.tensor([10]), iterations=4)
    masked = [int((t == net.vocabulary.mask_id).sum()) for t in seen]
    # ceil(gamma(i / 4) * 10) masked before iteration i: 10, 10, 8, 4 (gamma(0) = 1)
    assert masked == [10, 10, 8, 4]
    for before, after in zip(seen, [*seen[1:], final], strict=True):
        decided = before != net.vocabulary.mask_id
        assert torch.equal(after[decided], before[decided])


def test_greedy_residual_layers_are_the_argmax_of_the_guided_logits():
    net = make_residual_net().eval()
    base = torch.tensor([[1, 2, 3, 4, 5], [6, 7, 8, -1, -1]])
    lengths, text = torch.tensor([5, 3]), _text(2)
    tokens = decode_residual(net, base, text, lengths, cfg_scale=5.0)
    assert tokens.shape == (2, 3, 5)
    assert torch.equal(tokens[:, 0], base)
    with torch.no_grad():
        cond = net(tokens[:, :1], text, lengths, layer=1)
        uncond = net(tokens[:, :1], text, lengths, torch.ones(2, dtype=torch.bool), layer=1)
    expected = (uncond + 5.0 * (cond - uncond)).argmax(-1)
    assert torch.equal(tokens[0, 1], expected[0]) and torch.equal(tokens[1, 1, :3], expected[1, :3])
    assert (tokens[1, :, 3:] == -1).all() and (tokens[:, 1:][tokens[:, 1:] >= 0] < CODES).all()


def test_sampled_residual_layers_are_reproducible_and_can_stop_early():
    net = make_residual_net()
    base, lengths = torch.tensor([[1, 2, 3, 4]]), torch.tensor([4])

    def draw(seed: int, layers: int | None = None) -> torch.Tensor:
        generator = torch.Generator().manual_seed(seed)
        return decode_residual(
            net, base, _text(1), lengths, temperature=1.0, generator=generator, layers=layers
        )

    assert torch.equal(draw(0), draw(0))
    partial = draw(0, layers=1)
    assert (partial[:, 2] == -1).all() and (partial[:, 1] >= 0).all()


def test_the_sampler_generates_decodable_tokens(text_cache):
    vq = make_vq()
    sampler = MoMaskSampler(
        mask_net=make_mask_net(), residual_net=make_residual_net(), vq=vq, text=text_cache
    )
    sample = sampler(
        ["a person walks", "someone jumps"],
        torch.tensor([64, 30]),
        generator=torch.Generator().manual_seed(0),
    )
    assert sample.tokens.shape == (2, 3, 1, 16) and sample.features.shape == (2, 64, 263)
    assert sample.lengths.tolist() == [64, 28]
    assert (sample.tokens[1, ..., 7:] == -1).all() and (sample.tokens[1, ..., :7] >= 0).all()
    torch.testing.assert_close(sample.features, vq.decode_valid(sample.tokens))
    base_only = MoMaskSampler(mask_net=make_mask_net(), residual_net=None, vq=vq, text=text_cache)
    tokens = base_only.tokens(None, torch.tensor([16]))
    assert (
        tokens.shape == (1, 3, 1, 4) and (tokens[:, 1:] == -1).all() and (tokens[:, 0] >= 0).all()
    )


def test_errors_name_the_problem(text_cache):
    net, lengths = make_mask_net(), torch.tensor([4])
    with pytest.raises(ValueError, match="iterations must be at least 1, got 0"):
        decode_base(net, None, lengths, iterations=0)
    with pytest.raises(ValueError, match="temperature must be >= 0, got -1"):
        decode_base(net, None, lengths, temperature=-1)
    with pytest.raises(ValueError, match=r"top_k_ratio must lie in \(0, 1\], got 0"):
        decode_base(net, None, lengths, top_k_ratio=0)
    with pytest.raises(ValueError, match=r"text must be \(B, D_text\) = \(1, 64\)"):
        decode_base(net, torch.zeros(2, 64), lengths)
    residual = make_residual_net()
    with pytest.raises(ValueError, match=r"base codes inside each length must lie in \[0, 16\)"):
        decode_residual(residual, torch.tensor([[1, -1, 2, 3]]), None, lengths)
    with pytest.raises(ValueError, match=r"layers must lie in \[0, 2\], got 3"):
        decode_residual(residual, torch.tensor([[1, 1, 2, 3]]), None, lengths, layers=3)
    vq = make_vq(layers=4)
    with pytest.raises(ValueError, match="residual_net predicts 3 layers, the VQ-VAE has 4"):
        MoMaskSampler(mask_net=net, residual_net=residual, vq=vq, text=text_cache)
    with pytest.raises(ValueError, match="mask_net has 8 codes per layer, the VQ-VAE 16"):
        MoMaskSampler(
            mask_net=make_mask_net(codebook_size=8), residual_net=None, vq=vq, text=text_cache
        )
    sampler = MoMaskSampler(mask_net=net, residual_net=None, vq=vq, text=text_cache)
    with pytest.raises(ValueError, match=r"lengths must be \(B,\) frames >= 4, got \[2\]"):
        sampler(None, torch.tensor([2]))
    with pytest.raises(ValueError, match="got 2 captions for 1 lengths"):
        sampler(["a", "b"], torch.tensor([8]))
