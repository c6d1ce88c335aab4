"""LightningModules training MoMask's masked transformer and residual transformer.

Batches: ``motion`` (B, T, *F) z-scored features, ``length`` (B,) frames, ``caption`` B
strings; with ``id`` and ``start`` (the HumanML3D items') the codes of each crop are cached.
Lengths are rounded down and time cropped to a multiple of 4 frames. Logged: ``train/loss``,
``train/accuracy``, ``val/loss``, ``val/accuracy`` (cross-entropy and argmax accuracy over the
loss positions). The frozen tokenizer and text encoder: :mod:`intermask.momask.base`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from torch.optim import Optimizer

from intermask.interm.module import global_masked_cross_entropy, masked_accuracy
from intermask.momask.base import (
    LR_GAMMA,
    LR_MILESTONES,
    MoMaskLosses,
    MoMaskModuleBase,
    check_probability,
)
from intermask.momask.masking import (
    BERT_MASK_PROB,
    BERT_RANDOM_PROB,
    LAYER_DRAWS,
    base_corruption,
    condition_drops,
    draw_layers,
    valid_steps,
)
from intermask.momask.model import MaskedTransformer, ResidualTransformer
from intermask.momask.sampler import (
    ITERATIONS,
    MASK_CFG_SCALE,
    RESIDUAL_CFG_SCALE,
    RESIDUAL_TEMPERATURE,
    TEMPERATURE,
    TOP_K_RATIO,
    MoMaskSampler,
    decode_base,
    decode_residual,
)
from intermask.motion.masks import length_mask
from intermask.text.cache import TextFeatureCache
from intermask.utils.distributed import gather_rows, local_rows
from intermask.vq.model import MotionVQVAE


def _layout(lengths_in_steps: torch.Tensor, steps: int) -> torch.Tensor:
    """(B,) lengths -> (B, T') int64: 0 inside each length, -1 after: what the draws of a sample
    depend on, for the rows of the global batch this rank does not hold."""
    return torch.where(length_mask(lengths_in_steps, steps), 0, -1)


class MaskTransformerModule(MoMaskModuleBase):
    """Trains :class:`MaskedTransformer` on the base layer (section 3.2).

    Args:
        net: the masked transformer, or a factory taking ``codebook_size`` and ``text_dim``
            (what the configs give: the tokenizer and the text encoder own them).
        text: feature cache in front of the frozen text encoder; not checkpointed.
        optimizer: partial optimizer taking the parameters (AdamW lr 2e-4).
        warmup_fraction: linear warm-up as a fraction of all optimizer steps.
        vq, vq_ckpt: the frozen residual VQ-VAE, built or as a ``train_vq`` checkpoint (or run
            folder); or neither, and :meth:`set_tokenizer` before training.
        condition_drop: per-sample probability of the null condition (0.1, section 3.4).
        lr_milestones, lr_gamma: the learning rate is multiplied by ``lr_gamma`` at these
            fractions of training.
        bert_random_prob, bert_mask_prob: the corruption of the masked steps (80/10/10:
            0.1 and 8/9; the reference code's 0.1 and 0.88).
        token_cache: keep the codes of each crop the batches identify (``id``, ``start``).
    """

    def __init__(
        self,
        *,
        net: MaskedTransformer | Callable[..., MaskedTransformer],
        text: TextFeatureCache,
        optimizer: Callable[..., Optimizer],
        warmup_fraction: float,
        vq: MotionVQVAE | None = None,
        vq_ckpt: str | Path | None = None,
        condition_drop: float = 0.1,
        lr_milestones: Sequence[float] = LR_MILESTONES,
        lr_gamma: float = LR_GAMMA,
        bert_random_prob: float = BERT_RANDOM_PROB,
        bert_mask_prob: float = BERT_MASK_PROB,
        token_cache: bool = True,
    ) -> None:
        check_probability("bert_random_prob", bert_random_prob)
        check_probability("bert_mask_prob", bert_mask_prob)
        super().__init__(
            net=net,
            text=text,
            optimizer=optimizer,
            warmup_fraction=warmup_fraction,
            vq=vq,
            vq_ckpt=vq_ckpt,
            condition_drop=condition_drop,
            lr_milestones=lr_milestones,
            lr_gamma=lr_gamma,
            token_cache=token_cache,
            hyper_parameters={
                "bert_random_prob": float(bert_random_prob),
                "bert_mask_prob": float(bert_mask_prob),
            },
        )

    def _build_net(
        self, factory: Callable[..., MaskedTransformer], vq: MotionVQVAE, text_dim: int
    ) -> MaskedTransformer:
        return factory(codebook_size=vq.quantizer.codebook_size, text_dim=text_dim)

    def _check_tokenizer(self, vq: MotionVQVAE) -> None:
        """Any number of layers: the base layer is layer 0."""

    def compute_losses(
        self,
        batch: dict[str, Any],
        *,
        condition_drop: float,
        generator: torch.Generator | None = None,
    ) -> MoMaskLosses:
        """CE over the masked base-layer steps (:func:`base_corruption`).

        Data parallel: masks, corruption and condition drops are drawn for the whole global
        batch on every rank and the CE is a mean over its masked steps
        (:mod:`intermask.utils.distributed`), so N processes take the step of one.
        """
        tokens, lengths_in_steps = self.tokenize(batch)
        targets = tokens[:, 0]  # (B, T')
        text = self.sentence(batch["caption"])
        mine = local_rows(targets.shape[0])
        every_length = gather_rows(lengths_in_steps)
        layout = _layout(every_length, targets.shape[1])
        layout[mine] = targets
        masking = base_corruption(
            layout,
            every_length,
            self.net.codebook_size,
            random_prob=self.hparams.bert_random_prob,
            mask_prob=self.hparams.bert_mask_prob,
            generator=generator,
        )
        drop = condition_drops(
            layout.shape[0], condition_drop, generator=generator, device=targets.device
        )[mine]
        mask = masking.mask[mine]
        logits = self.net(masking.tokens[mine], text, lengths_in_steps, drop)
        return MoMaskLosses(
            global_masked_cross_entropy(logits, targets, mask),
            masked_accuracy(logits.detach(), targets, mask),
        )

    @torch.no_grad()
    def generate(
        self,
        captions: Sequence[str] | None,
        lengths: torch.Tensor | Sequence[int],
        *,
        generator: torch.Generator | None = None,
        iterations: int = ITERATIONS,
        cfg_scale: float = MASK_CFG_SCALE,
        top_k_ratio: float = TOP_K_RATIO,
        temperature: float = TEMPERATURE,
    ) -> torch.Tensor:
        """B captions (None: unconditional) and (B,) frames -> (B, 1, 1, T') base-layer codes,
        -1 beyond each length // 4: the first layer of :meth:`MotionVQVAE.decode`'s input."""
        batch = len(lengths) if captions is None else len(captions)
        steps = self._lengths_in_steps(lengths, batch)
        text = None if captions is None else self.sentence(captions)
        base = decode_base(
            self.net,
            text,
            steps,
            iterations=iterations,
            cfg_scale=cfg_scale,
            top_k_ratio=top_k_ratio,
            temperature=temperature,
            generator=generator,
        )
        return base[:, None, None, :]

    def sampler(
        self, residual_net: ResidualTransformer | None = None, **settings: Any
    ) -> MoMaskSampler:
        """A :class:`MoMaskSampler` over this network, ``residual_net`` (None: base layer only),
        the tokenizer and the text cache; ``settings`` are its decoding keyword arguments."""
        self._move_frozen(self.device)
        return MoMaskSampler(
            mask_net=self.net, residual_net=residual_net, vq=self.vq, text=self.text, **settings
        )


class ResidualTransformerModule(MoMaskModuleBase):
    """Trains :class:`ResidualTransformer` on layers 1..Q-1 (section 3.3).

    Each sample learns one layer j (:func:`draw_layers`) at every valid step, from the codes of
    layers 0..j-1; no masking.

    Args:
        net: the residual transformer, or a factory taking ``codebook_size``,
            ``num_quantizers`` and ``text_dim``.
        layer_draw: "uniform" (the paper) or "reference" (the reference code's skew to low
            layers).
        text, optimizer, warmup_fraction, vq, vq_ckpt, condition_drop, lr_milestones,
            lr_gamma, token_cache: as :class:`MaskTransformerModule`.
    """

    def __init__(
        self,
        *,
        net: ResidualTransformer | Callable[..., ResidualTransformer],
        text: TextFeatureCache,
        optimizer: Callable[..., Optimizer],
        warmup_fraction: float,
        vq: MotionVQVAE | None = None,
        vq_ckpt: str | Path | None = None,
        condition_drop: float = 0.1,
        lr_milestones: Sequence[float] = LR_MILESTONES,
        lr_gamma: float = LR_GAMMA,
        layer_draw: str = "uniform",
        token_cache: bool = True,
    ) -> None:
        if layer_draw not in LAYER_DRAWS:
            raise ValueError(f"layer_draw must be one of {LAYER_DRAWS}, got {layer_draw!r}")
        super().__init__(
            net=net,
            text=text,
            optimizer=optimizer,
            warmup_fraction=warmup_fraction,
            vq=vq,
            vq_ckpt=vq_ckpt,
            condition_drop=condition_drop,
            lr_milestones=lr_milestones,
            lr_gamma=lr_gamma,
            token_cache=token_cache,
            hyper_parameters={"layer_draw": layer_draw},
        )

    def _build_net(
        self, factory: Callable[..., ResidualTransformer], vq: MotionVQVAE, text_dim: int
    ) -> ResidualTransformer:
        return factory(
            codebook_size=vq.quantizer.codebook_size,
            num_quantizers=vq.quantizer.num_quantizers,
            text_dim=text_dim,
        )

    def _check_tokenizer(self, vq: MotionVQVAE) -> None:
        if vq.quantizer.num_quantizers != self.net.num_quantizers:
            raise ValueError(
                f"the VQ-VAE has {vq.quantizer.num_quantizers} quantizer layers, the residual "
                f"transformer {self.net.num_quantizers}"
            )

    def compute_losses(
        self,
        batch: dict[str, Any],
        *,
        condition_drop: float,
        generator: torch.Generator | None = None,
    ) -> MoMaskLosses:
        """CE of each sample's drawn layer over its valid steps (global-batch draws and mean, as
        :meth:`MaskTransformerModule.compute_losses`)."""
        tokens, lengths_in_steps = self.tokenize(batch)  # (B, Q, T')
        text = self.sentence(batch["caption"])
        batch_size, device = tokens.shape[0], tokens.device
        mine = local_rows(batch_size)
        total = gather_rows(lengths_in_steps).shape[0]
        layers = draw_layers(
            total,
            self.net.num_quantizers,
            draw=self.hparams.layer_draw,
            generator=generator,
            device=device,
        )[mine]
        drop = condition_drops(total, condition_drop, generator=generator, device=device)[mine]
        logits = self.net(tokens, text, lengths_in_steps, drop, layer=layers)  # (B, T', K)
        targets = tokens[torch.arange(batch_size, device=device), layers]  # (B, T')
        mask = valid_steps(targets, lengths_in_steps)
        return MoMaskLosses(
            global_masked_cross_entropy(logits, targets, mask),
            masked_accuracy(logits.detach(), targets, mask),
        )

    @torch.no_grad()
    def generate(
        self,
        captions: Sequence[str] | None,
        base_tokens: torch.Tensor,
        lengths: torch.Tensor | Sequence[int],
        *,
        generator: torch.Generator | None = None,
        cfg_scale: float = RESIDUAL_CFG_SCALE,
        temperature: float = RESIDUAL_TEMPERATURE,
        top_k_ratio: float = TOP_K_RATIO,
    ) -> torch.Tensor:
        """Complete base-layer codes -> (B, Q, 1, T') codes of every layer, -1 beyond each
        length // 4, ready for :meth:`MotionVQVAE.decode`.

        base_tokens: (B, T') or (B, Q', 1, T') (its layer 0 is used, e.g.
        :meth:`MaskTransformerModule.generate`'s result); lengths: (B,) frames.
        """
        if base_tokens.ndim == 4 and base_tokens.shape[2] == 1:
            base_tokens = base_tokens[:, 0, 0]
        if base_tokens.ndim != 2:
            raise ValueError(
                f"base_tokens must be (B, T') or (B, Q', 1, T'), got {tuple(base_tokens.shape)}"
            )
        steps = self._lengths_in_steps(lengths, base_tokens.shape[0])
        if captions is not None and len(captions) != base_tokens.shape[0]:
            raise ValueError(f"got {len(captions)} captions for {base_tokens.shape[0]} samples")
        text = None if captions is None else self.sentence(captions)
        tokens = decode_residual(
            self.net,
            base_tokens,
            text,
            steps,
            cfg_scale=cfg_scale,
            temperature=temperature,
            top_k_ratio=top_k_ratio,
            generator=generator,
        )
        return tokens[:, :, None, :]
