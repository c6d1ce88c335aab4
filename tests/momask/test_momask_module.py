"""MoMask LightningModules: losses, frozen tokenizer and text, training, generation, errors."""

from __future__ import annotations

import time
from functools import partial

import pytest
import torch
import torch.nn.functional as F

from intermask.momask.masking import base_corruption, condition_drops, draw_layers
from intermask.momask.model import MaskedTransformer, ResidualTransformer, sentence_features
from intermask.momask.module import MaskTransformerModule, ResidualTransformerModule
from tests.momask.momask_tiny import TINY, make_batch, make_mask_net, make_residual_net, make_vq

pytestmark = pytest.mark.filterwarnings("ignore:You are trying to `self.log")


def _mask_module(text_cache, optimizer, **overrides) -> MaskTransformerModule:
    kwargs = {
        "net": partial(MaskedTransformer, **TINY),
        "text": text_cache,
        "optimizer": optimizer,
        "warmup_fraction": 0.0,
        "vq": make_vq(),
    }
    return MaskTransformerModule(**{**kwargs, **overrides})


def _residual_module(text_cache, optimizer, **overrides) -> ResidualTransformerModule:
    kwargs = {
        "net": partial(ResidualTransformer, **TINY),
        "text": text_cache,
        "optimizer": optimizer,
        "warmup_fraction": 0.0,
        "vq": make_vq(),
    }
    return ResidualTransformerModule(**{**kwargs, **overrides})


@pytest.mark.parametrize("build", [_mask_module, _residual_module])
def test_training_reduces_the_loss_on_a_fixed_batch(build, text_cache, optimizer):
    torch.manual_seed(0)
    module = build(text_cache, optimizer)
    batch = make_batch()
    step = torch.optim.AdamW(module.parameters(), lr=3e-3)
    # Process CPU time, not wall time: a loaded machine stretches the wall clock, not the work.
    # On one thread: OpenMP workers that wait for a busy core spin and bill CPU time (a 0.3 s loop
    # measured 14 s of it with `make overfit` beside `make test`).
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        start, losses = time.process_time(), []
        for _ in range(20):
            generator = torch.Generator().manual_seed(0)  # the same masks, layers, drops each step
            loss = module.compute_losses(batch, condition_drop=0.1, generator=generator).total
            step.zero_grad()
            loss.backward()
            step.step()
            losses.append(loss.item())
        seconds = time.process_time() - start
    finally:
        torch.set_num_threads(threads)
    assert losses[-1] < 0.7 * losses[0]
    assert seconds < 10.0  # a fast test, not `slow`


@pytest.mark.parametrize("build", [_mask_module, _residual_module])
def test_only_the_network_is_trained_and_checkpointed(build, text_cache, optimizer):
    module = build(text_cache, optimizer)
    loss = module.training_step(make_batch(), 0)
    assert loss.ndim == 0 and torch.isfinite(loss)
    loss.backward()
    assert {id(p) for p in module.parameters()} == {id(p) for p in module.net.parameters()}
    assert all(key.startswith("net.") for key in module.state_dict())
    assert all(p.grad is None and not p.requires_grad for p in module.vq.parameters())
    assert not module.vq.training and module.hparams.vq_digest is not None
    assert module.hparams.codebook_size == 16 and module.hparams.text_dim == 64


@pytest.mark.parametrize("build", [_mask_module, _residual_module])
def test_steps_log_loss_and_accuracy(build, text_cache, optimizer, monkeypatch):
    module = build(text_cache, optimizer)
    logged = {}
    monkeypatch.setattr(module, "log", lambda name, value, **kwargs: logged.update({name: value}))
    module.training_step(make_batch(), 0)
    module.validation_step(make_batch(), 0)
    assert sorted(logged) == ["train/accuracy", "train/loss", "val/accuracy", "val/loss"]
    assert 0.0 <= float(logged["val/accuracy"]) <= 1.0 and float(logged["val/loss"]) > 0


def test_mask_loss_is_the_cross_entropy_over_the_masked_steps(text_cache, optimizer):
    module = _mask_module(text_cache, optimizer)
    batch = make_batch()
    losses = module.compute_losses(
        batch, condition_drop=0.5, generator=torch.Generator().manual_seed(7)
    )

    lengths = torch.tensor([64, 40, 28, 16])  # 30 frames round down to 7 steps
    codes = module.vq.encode(batch["motion"], lengths)[:, 0, 0]  # (B, T') base layer
    assert (codes[2, 7:] == -1).all() and (codes[2, :7] >= 0).all()
    generator = torch.Generator().manual_seed(7)  # replay the draws in their order
    masking = base_corruption(codes, lengths // 4, 16, generator=generator)
    drop = condition_drops(4, 0.5, generator=generator)
    text = sentence_features(text_cache.get_or_encode(batch["caption"]))
    logits = module.net(masking.tokens, text, lengths // 4, drop)
    expected = F.cross_entropy(logits[masking.mask], codes[masking.mask])
    accuracy = (logits[masking.mask].argmax(-1) == codes[masking.mask]).float().mean()
    torch.testing.assert_close(losses.total, expected)
    torch.testing.assert_close(losses.accuracy, accuracy)
    assert not masking.mask[2, 7:].any()


def test_residual_loss_is_the_cross_entropy_of_each_drawn_layer(text_cache, optimizer):
    module = _residual_module(text_cache, optimizer)
    batch = make_batch()
    losses = module.compute_losses(
        batch, condition_drop=0.5, generator=torch.Generator().manual_seed(8)
    )

    lengths = torch.tensor([64, 40, 28, 16])
    codes = module.vq.encode(batch["motion"], lengths)[:, :, 0]  # (B, Q, T')
    generator = torch.Generator().manual_seed(8)
    layers = draw_layers(4, 3, generator=generator)
    drop = condition_drops(4, 0.5, generator=generator)
    text = sentence_features(text_cache.get_or_encode(batch["caption"]))
    logits = module.net(codes, text, lengths // 4, drop, layer=layers)
    targets = codes[torch.arange(4), layers]
    valid = targets >= 0
    torch.testing.assert_close(losses.total, F.cross_entropy(logits[valid], targets[valid]))
    assert int(valid.sum()) == 16 + 10 + 7 + 4


def test_cached_tokens_equal_fresh_ones(text_cache, optimizer):
    module = _mask_module(text_cache, optimizer)
    batch = {**make_batch(), "id": ["a", "b", "c", "d"], "start": [0, 3, 0, 5]}
    fresh, lengths = module.tokenize(make_batch())
    first, _ = module.tokenize(batch)
    second, again = module.tokenize(batch)
    assert fresh.shape == (4, 3, 16) and lengths.tolist() == [16, 10, 7, 4]
    assert torch.equal(first, fresh) and torch.equal(second, fresh) and torch.equal(again, lengths)
    assert module.token_cache.hits == 4 and len(module.token_cache) == 4


def test_generated_base_tokens_are_completed_and_decoded(text_cache, optimizer):
    mask, residual = _mask_module(text_cache, optimizer), _residual_module(text_cache, optimizer)
    captions, lengths = ["a person walks", "someone jumps"], [64, 30]
    base = mask.generate(captions, lengths, generator=torch.Generator().manual_seed(0))
    assert base.shape == (2, 1, 1, 16) and (base[1, ..., 7:] == -1).all()
    full = residual.generate(captions, base, lengths)
    assert full.shape == (2, 3, 1, 16) and torch.equal(full[:, :1], base)
    assert (full[1, ..., :7] >= 0).all() and (full[1, ..., 7:] == -1).all()
    assert mask.vq.decode(full).shape == (2, 64, 263)
    again = mask.sampler(residual.net)(
        captions, torch.tensor(lengths), generator=torch.Generator().manual_seed(0)
    )
    assert torch.equal(again.tokens, full)


def test_a_tokenizer_can_be_set_after_construction(text_cache, optimizer):
    module = _mask_module(text_cache, optimizer, net=make_mask_net(), vq=None)
    with pytest.raises(
        RuntimeError, match="no tokenizer: pass vq or vq_ckpt, or call set_tokenizer"
    ):
        module.tokenize(make_batch())
    module.set_tokenizer(make_vq())
    tokens, _ = module.tokenize(make_batch())
    assert tokens.shape == (4, 3, 16)


def test_resuming_with_another_tokenizer_is_refused(text_cache, optimizer):
    module = _mask_module(text_cache, optimizer)
    with pytest.raises(ValueError, match="trained on the VQ-VAE with weights digest 0123"):
        module.on_load_checkpoint({"hyper_parameters": {"vq_digest": "0123" * 16}})
    module.on_load_checkpoint({"hyper_parameters": {"vq_digest": module.hparams.vq_digest}})


def test_errors_name_the_problem(text_cache, optimizer):
    with pytest.raises(
        ValueError, match="net is a factory: it takes its codebook size from the tokenizer"
    ):
        _mask_module(text_cache, optimizer, vq=None)
    with pytest.raises(ValueError, match="give the tokenizer as vq or as vq_ckpt, not both"):
        _mask_module(text_cache, optimizer, vq_ckpt="run/checkpoints/last.ckpt")
    with pytest.raises(
        ValueError, match=r"net.text_dim \(32\) must equal the text encoder width \(64\)"
    ):
        _mask_module(text_cache, optimizer, net=make_mask_net(text_dim=32))
    with pytest.raises(ValueError, match="the VQ-VAE has 16 codes per layer, the network 8"):
        _mask_module(text_cache, optimizer, net=make_mask_net(codebook_size=8))
    with pytest.raises(
        ValueError, match="the VQ-VAE has 4 quantizer layers, the residual transformer 3"
    ):
        _residual_module(text_cache, optimizer, net=make_residual_net(), vq=make_vq(layers=4))
    with pytest.raises(ValueError, match=r"condition_drop must lie in \[0, 1\], got 1.5"):
        _mask_module(text_cache, optimizer, condition_drop=1.5)
    with pytest.raises(ValueError, match="layer_draw must be one of"):
        _residual_module(text_cache, optimizer, layer_draw="cosine")
    module = _mask_module(text_cache, optimizer)
    with pytest.raises(ValueError, match=r"motion must be \(B, T, \*F\), got \(64, 263\)"):
        module.tokenize({**make_batch(), "motion": torch.zeros(64, 263)})
    with pytest.raises(ValueError, match=r"lengths must be \(2,\) frames >= 4, got \[64\]"):
        module.generate(["a", "b"], [64])
    residual = _residual_module(text_cache, optimizer)
    with pytest.raises(ValueError, match=r"base_tokens must be \(B, T'\) or \(B, Q', 1, T'\)"):
        residual.generate(None, torch.zeros(2, 3, 4, dtype=torch.long), [16, 16])


def test_residual_training_learns_codes_only_the_layers_below_predict(
    text_cache, optimizer, monkeypatch
):
    """One caption for every sample, random base codes and layer j's codes a fixed permutation of
    layer j-1's: only the summed embeddings of the layers below can tell them (the caption and
    the position, which are enough to memorise clips, give the marginal rate 1/16), so the module
    trains on the history it is meant to read."""
    torch.manual_seed(0)
    module = _residual_module(text_cache, optimizer)
    permutations = [torch.randperm(16) for _ in range(3)]

    def tokens(batch):
        codes = torch.empty(32, 3, 8, dtype=torch.long)
        codes[:, 0] = torch.randint(0, 16, (32, 8))
        for layer in (1, 2):
            codes[:, layer] = permutations[layer][codes[:, layer - 1]]
        return codes, torch.full((32,), 8)

    monkeypatch.setattr(module, "tokenize", tokens)
    batch = {"caption": ["a person walks"] * 32}
    step = torch.optim.AdamW(module.parameters(), lr=3e-3)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # process time on a loaded machine (see the first test)
    try:
        start = time.process_time()
        for _ in range(300):
            loss = module.compute_losses(batch, condition_drop=0.1).total
            step.zero_grad()
            loss.backward()
            step.step()
        seconds = time.process_time() - start
        module.eval()
        with torch.no_grad():
            accuracy = module.compute_losses(batch, condition_drop=0.0).accuracy
    finally:
        torch.set_num_threads(threads)
    assert float(accuracy) > 0.9, float(accuracy)
    assert seconds < 10.0, seconds
