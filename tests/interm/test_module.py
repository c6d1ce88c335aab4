"""InterMModule: two-stage masked loss, frozen tokenizer and text encoder, checkpoints, fit."""

from __future__ import annotations

import math
from functools import partial
from types import SimpleNamespace

import lightning as L
import pytest
import torch
import torch.nn.functional as F
from torch.utils.data import DataLoader

from intermask.interm.masking import bert_corruption, training_mask
from intermask.interm.model import InterMTransformer
from intermask.interm.module import InterMModule, masked_cross_entropy
from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder
from intermask.text.cache import TextFeatureCache
from intermask.utils.optim import Muon
from intermask.vq.convolutions import MotionDecoder, MotionEncoder
from intermask.vq.model import MotionVQVAE
from intermask.vq.quantizers import ResidualQuantizer
from intermask.vq.views import InterHumanView

CODEBOOK = 32
CAPTIONS = ["two people shake hands", "one person pushes the other", "they dance together"]


@pytest.fixture(scope="module")
def encoder() -> FrozenCLIPTextEncoder:
    return FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=None, seed=0)


def _vq() -> MotionVQVAE:
    torch.manual_seed(0)
    vq = MotionVQVAE(
        view=InterHumanView(mean=torch.zeros(262), std=torch.ones(262)),
        encoder=MotionEncoder(num_joints=22, in_channels=12, width=16),
        quantizer=ResidualQuantizer(num_quantizers=2, codebook_size=CODEBOOK, dim=16),
        decoder=MotionDecoder(num_joints=22, out_channels=12, width=16),
    )
    vq.train()(torch.randn(4, 64, 262))  # initialise the codebooks from data
    return vq


def _net(**overrides: object) -> InterMTransformer:
    torch.manual_seed(1)
    config = {
        "codebook_size": CODEBOOK,
        "width": 32,
        "depth": 1,
        "heads": 2,
        "ff": 64,
        "dropout": 0.0,
        "token_embed_dim": 32,
        "text_dim": 64,
        "text_layers": 1,
        "text_heads": 2,
        "text_ff": 64,
        "text_dropout": 0.0,
    }
    return InterMTransformer(**{**config, **overrides})


def _module(encoder, tmp_path, **overrides: object) -> InterMModule:
    kwargs = {
        "net": _net(),
        "vq": _vq(),
        "text": TextFeatureCache(encoder=encoder, cache_dir=tmp_path / "text"),
        "optimizer": partial(torch.optim.AdamW, lr=2e-4, betas=(0.9, 0.99)),
        "warmup_fraction": 0.25,
    }
    return InterMModule(**{**kwargs, **overrides})


def _item(index: int, length: int) -> dict:
    generator = torch.Generator().manual_seed(index)
    return {
        "motion": torch.randn(2, 64, 262, generator=generator),
        "length": torch.tensor(length),
        "caption": CAPTIONS[index % len(CAPTIONS)],
    }


def _batch() -> dict:
    return next(iter(DataLoader([_item(i, n) for i, n in enumerate([64, 40, 30])], batch_size=3)))


@pytest.mark.filterwarnings("ignore:You are trying to `self.log")
def test_training_step_gives_a_finite_loss_whose_gradient_reaches_the_net_only(encoder, tmp_path):
    module = _module(encoder, tmp_path)
    torch.manual_seed(2)
    loss = module.training_step(_batch(), 0)
    assert loss.ndim == 0 and torch.isfinite(loss)
    loss.backward()
    assert module.net.head.logits.weight.grad is not None
    assert module.net.token_embedding.weight.grad.abs().sum() > 0
    assert all(p.grad is None and not p.requires_grad for p in module.vq.parameters())
    assert all(p.grad is None for p in module.text.encoder.parameters())
    trainable = {id(p) for p in module.parameters()}
    assert trainable == {id(p) for p in module.net.parameters()}


def test_stage1_loss_is_the_cross_entropy_over_the_masked_tokens(encoder, tmp_path):
    module = _module(encoder, tmp_path, step_unroll=False, condition_drop=0.0)
    batch = _batch()
    torch.manual_seed(3)
    losses = module.compute_losses(batch, condition_drop=0.0)

    torch.manual_seed(3)  # replay the same random draws by hand
    lengths = torch.tensor([64, 40, 28])  # 30 frames round down to 7 token steps
    codes = [module.vq.encode(batch["motion"][:, p], lengths)[:, 0] for p in range(2)]
    steps = lengths // 4
    masking = training_mask(codes[0], codes[1], steps, p_random=0.8)
    targets = torch.stack(codes, dim=1)
    corrupted = bert_corruption(targets, masking.mask, module.net.vocabulary).tokens
    torch.rand(3)  # the condition-drop draw
    text = encoder.encode(batch["caption"])
    out = module.net(corrupted[:, 0], corrupted[:, 1], text, steps)
    logits = torch.stack([out.logits_a, out.logits_b], dim=1)
    expected = F.cross_entropy(logits[masking.mask], targets[masking.mask])

    assert masking.mask.any()
    assert (targets[2, ..., 7:] == -1).all() and not masking.mask[2, ..., 7:].any()
    torch.testing.assert_close(losses.stage1, expected)
    torch.testing.assert_close(losses.total, expected)
    assert losses.stage2 == 0


def test_p_solo_and_p_partner_reach_the_training_masks(encoder, tmp_path, monkeypatch):
    from intermask.interm import module as module_file

    seen = []
    original = module_file.training_mask

    def recording(*args, **kwargs):
        seen.append((kwargs["p_solo"], kwargs["p_partner"]))
        return original(*args, **kwargs)

    monkeypatch.setattr(module_file, "training_mask", recording)
    module = _module(
        encoder, tmp_path, step_unroll=False, p_random=0.5, p_solo=0.25, p_partner=0.75
    )
    module.compute_losses(_batch(), condition_drop=0.0)
    assert seen == [(0.25, 0.75)]
    assert (module.hparams.p_solo, module.hparams.p_partner) == (0.25, 0.75)
    with pytest.raises(ValueError, match=r"p_solo must lie in \[0, 1\], got 2.0"):
        _module(encoder, tmp_path, p_solo=2.0)
    with pytest.raises(ValueError, match=r"p_partner must lie in \[0, 1\], got -1.0"):
        _module(encoder, tmp_path, p_partner=-1.0)


def test_masked_cross_entropy_ignores_unmasked_positions():
    generator = torch.Generator().manual_seed(0)
    logits = torch.randn(2, 2, 5, 4, CODEBOOK, generator=generator)
    targets = torch.randint(0, CODEBOOK, (2, 2, 5, 4), generator=generator)
    mask = torch.rand(2, 2, 5, 4, generator=generator) < 0.3
    changed = logits.clone()
    changed[~mask] = torch.randn_like(changed[~mask]) * 10
    loss = masked_cross_entropy(logits, targets, mask)
    torch.testing.assert_close(loss, masked_cross_entropy(changed, targets, mask))
    manual = -logits.log_softmax(-1).gather(-1, targets[..., None])[..., 0][mask].mean()
    torch.testing.assert_close(loss, manual)
    empty = masked_cross_entropy(logits.requires_grad_(), targets, torch.zeros_like(mask))
    assert empty == 0 and empty.requires_grad


def test_step_unroll_adds_a_second_pass_loss(encoder, tmp_path):
    module = _module(encoder, tmp_path)
    torch.manual_seed(4)
    losses = module.compute_losses(_batch(), condition_drop=0.1)
    assert losses.stage2 > 0 and torch.isfinite(losses.stage2)
    torch.testing.assert_close(losses.total, losses.stage1 + losses.stage2)
    assert 0 <= losses.masked_accuracy <= 1


def test_checkpoint_state_holds_the_transformer_only_and_vq_stays_in_eval(encoder, tmp_path):
    module = _module(encoder, tmp_path)
    module.train()
    assert not module.vq.training and not module.text.encoder.training
    keys = list(module.state_dict())
    assert keys and all(key.startswith("net.") for key in keys)
    assert not any(key.startswith(("vq.", "text.", "_frozen.")) for key in keys)
    assert set(module.net.state_dict()) == {key.removeprefix("net.") for key in keys}


def test_mismatched_codebook_and_text_width_are_rejected(encoder, tmp_path):
    with pytest.raises(
        ValueError, match=r"codebook_size \(16\) must equal the VQ codebook size \(32\)"
    ):
        _module(encoder, tmp_path, net=_net(codebook_size=16))
    with pytest.raises(
        ValueError, match=r"text_dim \(40\) must equal the text encoder width \(64\)"
    ):
        _module(encoder, tmp_path, net=_net(text_dim=40, text_heads=2))
    with pytest.raises(ValueError, match="condition_drop must lie in"):
        _module(encoder, tmp_path, condition_drop=1.5)


def test_a_smooth_learning_rate_decay_is_recorded_and_drives_the_optimizer(encoder, tmp_path):
    module = _module(
        encoder, tmp_path, warmup_fraction=0.0, lr_milestones=[], lr_decay="cosine", lr_final=0.1
    )
    assert (module.hparams.lr_decay, module.hparams.lr_final) == ("cosine", 0.1)
    module._trainer = SimpleNamespace(estimated_stepping_batches=4)
    config = module.configure_optimizers()
    optimizer, scheduler = config["optimizer"], config["lr_scheduler"]["scheduler"]
    rates = []
    for _ in range(5):
        rates.append(optimizer.param_groups[0]["lr"] / 2e-4)
        optimizer.step()
        scheduler.step()
    half = 0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi / 4))
    assert rates == pytest.approx([1.0, half, 0.55, 1.1 - half, 0.1])
    with pytest.raises(ValueError, match=r"lr_decay='linear' .* set lr_milestones to \[\]"):
        _module(encoder, tmp_path, lr_decay="linear")  # the paper's milestones left in place
    with pytest.raises(
        ValueError, match="lr_decay must be one of multistep, cosine, linear, got 'exp'"
    ):
        _module(encoder, tmp_path, lr_decay="exp", lr_milestones=[])


def test_muon_steps_the_hidden_matrices_and_adamw_the_embedding_logits_and_vectors(
    encoder, tmp_path
):
    module = _module(encoder, tmp_path, optimizer=partial(Muon, lr=2e-3, betas=(0.9, 0.99)))
    module._trainer = SimpleNamespace(estimated_stepping_batches=8)
    config = module.configure_optimizers()
    optimizer, scheduler = config["optimizer"], config["lr_scheduler"]["scheduler"]
    matrices, others = optimizer.param_groups
    net = module.net
    assert matrices["muon"] and not others["muon"]
    on_muon = {id(p) for p in matrices["params"]}
    assert id(net.token_projection.weight) in on_muon
    assert id(net.blocks[0].self_attention.attention.query.weight) in on_muon
    assert id(net.blocks[0].joint_ffn.modulation.linear.weight) in on_muon
    on_adamw = {id(p) for p in others["params"]}
    assert {id(net.token_embedding.weight), id(net.head.logits.weight)} <= on_adamw
    assert id(net.head.logits.bias) in on_adamw and id(net.text_norm.weight) in on_adamw
    assert on_muon | on_adamw == {id(p) for p in net.parameters()}
    assert all(p.ndim == 2 for p in matrices["params"])
    # the warm-up (a quarter of 8 steps) drives both groups alike
    assert matrices["lr"] == others["lr"] == pytest.approx(1e-3)
    optimizer.step()  # no gradients yet: nothing moves
    scheduler.step()
    assert matrices["lr"] == others["lr"] == pytest.approx(2e-3)


def test_code_vectors_come_from_the_vqs_base_codebook(encoder, tmp_path):
    factory = _net  # a factory, as Hydra's ``_partial_`` network: InterMModule completes it
    module = _module(encoder, tmp_path, net=factory, code_vectors=True)
    base = module.vq.quantizer.layers[0].codebook  # Inter-M generates base-layer codes
    assert module.net.code_dim == 16 == base.shape[1]
    torch.testing.assert_close(module.net.code_vectors[:CODEBOOK], base / base.pow(2).mean().sqrt())
    assert module.hparams.code_dim == 16
    assert _module(encoder, tmp_path, net=factory).net.code_dim is None  # off: the paper
    assert _module(encoder, tmp_path, net=factory).hparams.code_dim is None
    with pytest.raises(
        ValueError,
        match=r"code_vectors=True needs net.code_dim 16 \(the VQ's code width when on, None "
        r"when off\), got None",
    ):
        _module(encoder, tmp_path, net=_net(), code_vectors=True)
    with pytest.raises(ValueError, match=r"code_vectors=False needs net.code_dim None .* got 16"):
        _module(encoder, tmp_path, net=_net(code_dim=16))


def test_two_step_fit_trains_the_net_and_saves_a_weights_only_checkpoint(encoder, tmp_path):
    module = _module(encoder, tmp_path)
    vq_before = {k: v.clone() for k, v in module.vq.state_dict().items()}
    net_before = module.net.head.logits.bias.clone()
    items = [_item(i, n) for i, n in enumerate([64, 40, 30, 52])]
    trainer = L.Trainer(
        max_steps=2,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=1,
    )
    trainer.fit(
        module,
        train_dataloaders=DataLoader(items, batch_size=2),
        val_dataloaders=DataLoader(items[:2], batch_size=2),
    )
    assert trainer.global_step == 2
    assert not torch.equal(module.net.head.logits.bias, net_before)
    assert all(torch.equal(v, vq_before[k]) for k, v in module.vq.state_dict().items())
    for name in ("train/loss", "train/loss_stage1", "train/loss_stage2", "val/loss"):
        assert torch.isfinite(trainer.callback_metrics[name])
    path = tmp_path / "last.ckpt"
    trainer.save_checkpoint(path)
    checkpoint = torch.load(path, weights_only=True)
    assert all(key.startswith("net.") for key in checkpoint["state_dict"])
    assert checkpoint["hyper_parameters"]["lr_milestones"] == [0.5, 0.7, 0.85]


def test_alternative_modeling_trains_each_person_from_its_own_stream(encoder, tmp_path):
    module = _module(encoder, tmp_path, net=_net(modeling="alternative"))
    batch = _batch()
    torch.manual_seed(5)
    losses = module.compute_losses(batch, condition_drop=0.0)

    torch.manual_seed(5)  # replay: the loss is each direction's CE on its own masked tokens
    targets, steps = module.tokenize(batch)
    masking = training_mask(targets[:, 0], targets[:, 1], steps, p_random=0.8)
    corrupted = bert_corruption(targets, masking.mask, module.net.vocabulary).tokens
    torch.rand(3)  # the condition-drop draw
    condition = module.net.encode_condition(encoder.encode(batch["caption"]))
    a_given_b = module.net.forward_person(corrupted[:, 0], corrupted[:, 1], condition, steps)
    b_given_a = module.net.forward_person(corrupted[:, 1], corrupted[:, 0], condition, steps)
    logits = torch.stack([a_given_b, b_given_a], dim=1)
    expected = F.cross_entropy(logits[masking.mask], targets[masking.mask])
    torch.testing.assert_close(losses.stage1, expected, atol=1e-5, rtol=1e-5)
    assert losses.stage2 > 0 and torch.isfinite(losses.stage2)  # step unroll (deterministic)

    losses.total.backward()
    # AdaLN-Zero: at initialisation the gradient reaches cross attention through its gate
    assert module.net.blocks[0].cross_attention.modulation.linear.weight.grad.abs().sum() > 0
    generated = module.sampler(iterations=2)(CAPTIONS[:2], torch.tensor([64, 40]), seeds=[0, 1])
    assert generated.tokens.shape == (2, 2, 5, 16)
    assert ((generated.tokens[1, ..., :10] >= 0) & (generated.tokens[1, ..., :10] < CODEBOOK)).all()
    assert (generated.tokens[1, ..., 10:] == -1).all()
