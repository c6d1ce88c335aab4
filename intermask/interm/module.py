"""InterMModule: trains the Inter-M Transformer (masking, two-stage loss, optimizer, logging).

The frozen motion tokenizer and the frozen text encoder are *not* submodules: they are kept in
a plain attribute (:class:`_Frozen`), so ``state_dict``, checkpoints, ``parameters()`` (hence
the optimizer), ``.train()`` and Lightning's device moves never see them. Checkpoints hold the
transformer only; the VQ-VAE and text encoder are rebuilt from their own checkpoint / config.
Before every step they are moved to the module's device (a no-op once they are there).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
import torch.nn.functional as F
from einops import rearrange
from torch.optim import Optimizer

from intermask.interm.masking import (
    P_RANDOM,
    bert_corruption,
    stack_persons,
    step_unroll_mask,
    training_mask,
)
from intermask.interm.model import InterMTransformer, TextFeatures
from intermask.interm.sampler import (
    GeneratedMotion,
    InteractionSampler,
    joints_from_features,
)
from intermask.interm.token_cache import FrozenTokenizerHooks, TokenCache, crop_keys
from intermask.motion import interhuman
from intermask.motion.masks import length_mask
from intermask.motion.statistics import interaction_statistics
from intermask.text.cache import TextFeatureCache
from intermask.utils.distributed import gather_rows, global_mean_scale, local_rows
from intermask.utils.fingerprint import weights_digest
from intermask.utils.lightning import LossStepsModule
from intermask.utils.schedules import check_lr_decay
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE
from intermask.vq.views import TwoPersonView


class InterMLosses(NamedTuple):
    total: torch.Tensor  # () stage 1 + stage 2
    stage1: torch.Tensor  # () CE over the stage-1 masked tokens
    stage2: torch.Tensor  # () CE over the step-unroll tokens (0 when step_unroll is off)
    masked_accuracy: torch.Tensor  # () stage-1 argmax accuracy over the masked tokens


@dataclass
class _Frozen:
    """Holder that hides the frozen networks from ``nn.Module`` registration."""

    vq: MotionVQVAE
    text: TextFeatureCache


def masked_cross_entropy(
    logits: torch.Tensor, targets: torch.Tensor, mask: torch.Tensor
) -> torch.Tensor:
    """(B, 2, rows, T', K) logits, (B, 2, rows, T') codes and bool mask -> () mean CE over the
    masked tokens of the whole batch (the reference's ``ignore_index`` mean). An empty mask
    gives a zero that still carries the graph."""
    if not bool(mask.any()):
        return logits.sum() * 0.0
    return F.cross_entropy(logits[mask].float(), targets[mask])


def global_masked_cross_entropy(
    logits: torch.Tensor, targets: torch.Tensor, mask: torch.Tensor
) -> torch.Tensor:
    """:func:`masked_cross_entropy` over the masked tokens of the global batch: this rank's sum
    times world / (masked tokens of all ranks), which data-parallel gradient averaging turns into
    the one-process mean. Equal to :func:`masked_cross_entropy` in one process."""
    scale = global_mean_scale(mask.sum())
    if not bool(mask.any()):
        return logits.sum() * 0.0
    total = F.cross_entropy(logits[mask].float(), targets[mask], reduction="sum")
    return total * scale.to(total.dtype)


def _layout_of(lengths_in_steps: torch.Tensor, grid: torch.Size) -> torch.Tensor:
    """(B,) lengths and (rows, T') -> (B, 2, rows, T') int64: 0 inside each length, -1 after (the
    padding of :meth:`InterMModule.tokenize`), what the masks depend on."""
    inside = length_mask(lengths_in_steps, grid[-1])  # (B, T')
    codes = torch.where(inside, 0, -1)
    return codes[:, None, None, :].expand(-1, 2, *grid[:-1], -1).clone()


def masked_accuracy(
    logits: torch.Tensor, targets: torch.Tensor, mask: torch.Tensor
) -> torch.Tensor:
    """Share of masked tokens whose argmax is the true code (0 for an empty mask)."""
    if not bool(mask.any()):
        return logits.new_zeros(())
    return (logits[mask].argmax(dim=-1) == targets[mask]).float().mean()


def _base_codebook(vq: MotionVQVAE) -> torch.Tensor:
    """The (K, code_dim) codebook of the VQ-VAE's base layer, whose codes Inter-M generates."""
    return vq.quantizer.layers[0].codebook


def _network_for(
    net: InterMTransformer | Callable[..., InterMTransformer],
    *,
    vq: MotionVQVAE,
    text: TextFeatureCache,
    code_vectors: bool,
) -> tuple[InterMTransformer, int | None]:
    """The Inter-M network that fits the frozen tokenizer and text encoder, and its code-vector
    width (None without code vectors).

    A factory ``net`` is built with the VQ's codebook size (and code width when
    ``code_vectors``); a built one must already match them. With code vectors the network gets
    the VQ's base codebook. Raises ValueError on a two-person VQ-VAE or any mismatch.
    """
    if isinstance(vq.view, TwoPersonView):
        raise ValueError("the Inter-M Transformer needs a single-person VQ-VAE, got persons=2")
    vq_codes = vq.quantizer.codebook_size
    code_dim = int(_base_codebook(vq).shape[1]) if code_vectors else None
    if not isinstance(net, InterMTransformer):  # a factory: the VQ owns the codebook size
        net = net(codebook_size=vq_codes, code_dim=code_dim)
    if vq_codes != net.codebook_size:
        raise ValueError(
            f"net.codebook_size ({net.codebook_size}) must equal the VQ codebook size ({vq_codes})"
        )
    if net.code_dim != code_dim:
        raise ValueError(
            f"code_vectors={code_vectors} needs net.code_dim {code_dim} (the VQ's code width "
            f"when on, None when off), got {net.code_dim}"
        )
    if code_dim is not None:
        net.set_code_vectors(_base_codebook(vq))
    if text.encoder.width != net.text_dim:
        raise ValueError(
            f"net.text_dim ({net.text_dim}) must equal the text encoder width ({text.encoder.width})"
        )
    return net, code_dim


def _check_training_settings(
    *,
    probabilities: dict[str, float],
    warmup_fraction: float,
    lr_decay: str,
    lr_milestones: Sequence[float],
    lr_final: float,
    validation_samples: int,
    sample_iterations: int,
) -> None:
    """Raise ValueError on an :class:`InterMModule` setting out of range: a masking or
    condition-drop probability outside [0, 1] (``probabilities``: name -> value), a warm-up
    fraction outside [0, 1), a learning-rate decay its milestones do not fit, a negative sample
    count or no decoding iteration."""
    for name, prob in probabilities.items():
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"{name} must lie in [0, 1], got {prob}")
    if not 0.0 <= warmup_fraction < 1.0:
        raise ValueError(f"warmup_fraction must lie in [0, 1), got {warmup_fraction}")
    check_lr_decay(lr_decay, lr_milestones, lr_final)
    if validation_samples < 0 or sample_iterations < 1:
        raise ValueError(
            f"validation_samples must be >= 0 and sample_iterations >= 1, got "
            f"{validation_samples} and {sample_iterations}"
        )


class InterMModule(FrozenTokenizerHooks, LossStepsModule):
    """Trains :class:`InterMTransformer` on interaction batches of the DataModule.

    Batch: ``motion`` (B, 2, T, *F) normalized features, ``length`` (B,) frames, ``caption``
    list of B strings.

    Args:
        net: the Inter-M Transformer (its ``codebook_size`` and ``rows`` must match ``vq``), or
            a factory taking ``codebook_size``, called with the VQ's (what the configs give:
            the codebook size has one owner, the tokenizer's checkpoint).
        vq: the trained single-person VQ-VAE; frozen, eval mode, not checkpointed. Tokens are
            its first quantizer layer (the base codes, section 3.2).
        text: feature cache in front of the frozen CLIP text encoder; not checkpointed.
        optimizer: partial optimizer taking the parameters (paper: AdamW lr 2e-4).
        p_random: p_r, random- vs interaction-masking probability (section 3.2.1, 0.8).
        p_solo: share of the samples not randomly masked that get solo masking instead of
            interaction masking (:mod:`intermask.interm.masking`; 0, the paper).
        p_partner: share of the samples left to interaction masking that get partner masking
            instead: the hidden person masked on the schedule, not wholly (0, the paper).
        condition_drop: per-sample probability of the null condition (classifier-free
            guidance, 0.1).
        step_unroll: add the second, step-unroll pass (section 3.2.1 stage 2).
        warmup_fraction: linear warm-up length as a fraction of all optimizer steps. The paper
            warms up for a quarter epoch, i.e. ``0.25 / max_epochs``; the config computes it.
        lr_milestones, lr_gamma: the learning rate is multiplied by ``lr_gamma`` (1/3) at these
            fractions of training (0.5, 0.7, 0.85).
        lr_decay, lr_final: ``"multistep"`` (the paper) uses the milestones; ``"cosine"`` or
            ``"linear"`` instead decay the rate smoothly from the end of the warm-up to
            ``lr_final`` times the base rate at the last step (no milestones then).
        validation_samples: every validation generates this many interactions from the first
            captions of the first batch (fixed seeds) and logs their joint statistics next to
            the ground truth's (``val_samples/{generated,real}_*``); 0 switches it off.
        sample_iterations: decoding iterations for those samples (fewer than the paper's 20
            keeps validation cheap).
        fps: frame rate of the dataset, for speeds in m/s.
        token_cache: keep the VQ codes of every crop the batches identify (``id``, ``start``,
            ``persons``, ``mirrored``, ``reference``) and reuse them instead of re-encoding; exact
            (:mod:`intermask.interm.token_cache`), emptied when the VQ changes.
        code_vectors: each motion code's input also carries the VQ's codebook vector for it,
            through a learned projection (``InterMTransformer(code_dim=...)``, built here with
            the VQ's code width); off in the paper (docs/decisions.md: model.code_vectors).
    """

    def __init__(
        self,
        *,
        net: InterMTransformer | Callable[..., InterMTransformer],
        vq: MotionVQVAE,
        text: TextFeatureCache,
        optimizer: Callable[..., Optimizer],
        warmup_fraction: float,
        p_random: float = P_RANDOM,
        p_solo: float = 0.0,
        p_partner: float = 0.0,
        condition_drop: float = 0.1,
        step_unroll: bool = True,
        lr_milestones: Sequence[float] = (0.5, 0.7, 0.85),
        lr_gamma: float = 1 / 3,
        lr_decay: str = "multistep",
        lr_final: float = 0.0,
        validation_samples: int = 4,
        sample_iterations: int = 10,
        fps: float = float(interhuman.FPS),
        token_cache: bool = True,
        code_vectors: bool = False,
    ) -> None:
        super().__init__()
        net, code_dim = _network_for(net, vq=vq, text=text, code_vectors=code_vectors)
        vq_codes = vq.quantizer.codebook_size
        _check_training_settings(
            probabilities={
                "p_random": p_random,
                "p_solo": p_solo,
                "p_partner": p_partner,
                "condition_drop": condition_drop,
            },
            warmup_fraction=warmup_fraction,
            lr_decay=lr_decay,
            lr_milestones=lr_milestones,
            lr_final=lr_final,
            validation_samples=validation_samples,
            sample_iterations=sample_iterations,
        )
        self.net = net
        self.last_samples: tuple[list[str], GeneratedMotion] | None = None
        vq.eval().requires_grad_(False)
        self._frozen = _Frozen(vq=vq, text=text)
        self.token_cache = TokenCache(codebook_size=vq_codes) if token_cache else None
        self.optimizer_factory = optimizer
        # plain Python values only, so checkpoints load with torch.load(weights_only=True)
        self.save_hyperparameters(
            {
                "p_random": float(p_random),
                "p_solo": float(p_solo),
                "p_partner": float(p_partner),
                "condition_drop": float(condition_drop),
                "step_unroll": bool(step_unroll),
                "warmup_fraction": float(warmup_fraction),
                "lr_milestones": [float(m) for m in lr_milestones],
                "lr_gamma": float(lr_gamma),
                "lr_decay": str(lr_decay),
                "lr_final": float(lr_final),
                "validation_samples": int(validation_samples),
                "sample_iterations": int(sample_iterations),
                "fps": float(fps),
                "token_cache": bool(token_cache),
                # the tokens mean something only to this VQ: loaders check it (load_generator)
                "vq_digest": weights_digest(vq),
                "codebook_size": int(vq_codes),  # what load_generator builds the network with
                "code_dim": code_dim,  # the same, None without code vectors
            },
            logger=False,
        )

    def muon_excluded(self) -> list[torch.nn.Parameter]:
        # beside the code embedding, the logits layer: it scores each code by its own row
        return [*super().muon_excluded(), *self.net.head.logits.parameters()]

    @property
    def vq(self) -> MotionVQVAE:
        return self._frozen.vq

    @property
    def text(self) -> TextFeatureCache:
        return self._frozen.text

    def tokenize(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        """Batch -> (B, 2, rows, T') base-layer tokens (-1 on padding) and (B,) lengths in steps.

        Lengths are rounded down and time cropped to a multiple of 4 frames.
        """
        motion, lengths = batch["motion"], batch["length"]
        if motion.ndim < 4 or motion.shape[1] != 2:
            raise ValueError(f"motion must be (B, 2, T, *F), got {tuple(motion.shape)}")
        frames = motion.shape[2] - motion.shape[2] % FRAMES_PER_STEP
        lengths = lengths.to(motion.device).long().clamp(max=frames)
        lengths = lengths - lengths % FRAMES_PER_STEP
        self._move_frozen(motion.device)
        keys = None
        if self.token_cache is not None:
            keys = crop_keys(batch, lengths.tolist(), frames)
        if keys is None:
            tokens = self._encode(motion[:, :, :frames], lengths)
        else:
            tokens = self._cached_tokens(motion[:, :, :frames], lengths, keys)
        return tokens, lengths // FRAMES_PER_STEP

    def _encode(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """(B, 2, T, *F) and (B,) frames -> (B, 2, rows, T') base-layer codes."""
        # nearest-code search in float32 even under bf16 autocast: rounding could change codes
        with torch.autocast(device_type=motion.device.type, enabled=False):
            tokens = [
                self.vq.encode(motion[:, person].float(), lengths)[:, 0]  # (B, rows, T')
                for person in range(2)
            ]
        return stack_persons(*tokens)

    def _cached_tokens(self, motion, lengths, keys) -> torch.Tensor:
        """:meth:`_encode` through the token cache: only samples with a missing person are
        encoded (both persons, one batch), then stored."""
        cache = self.token_cache
        cache.bind(self.vq)
        codes = [cache.get(key) for key in keys]  # B * 2 entries, (rows, T') or None
        missing = sorted({i // 2 for i, found in enumerate(codes) if found is None})
        if missing:
            index = torch.tensor(missing, device=motion.device)
            fresh = self._encode(motion[index], lengths[index]).cpu()  # (M, 2, rows, T')
            for row, sample in enumerate(missing):
                for person in range(2):
                    codes[2 * sample + person] = fresh[row, person]
                    cache.put(keys[2 * sample + person], fresh[row, person])
        tokens = rearrange(torch.stack(codes), "(b p) r t -> b p r t", p=2)
        return tokens.to(motion.device)

    def sampler(self, **settings: Any) -> InteractionSampler:
        """An :class:`InteractionSampler` over this module's network, VQ-VAE and text cache;
        ``settings`` are its decoding keyword arguments (iterations, cfg_scale, ...)."""
        self._move_frozen(self.device)
        return InteractionSampler(net=self.net, vq=self.vq, text=self.text, **settings)

    def encode_text(self, captions: Sequence[str]) -> TextFeatures:
        features = self.text.get_or_encode(list(captions))
        return TextFeatures(*(t.to(self.device) for t in features))

    def _forward(self, tokens, text, lengths_in_steps, drop) -> torch.Tensor:
        out = self.net(tokens[:, 0], tokens[:, 1], text, lengths_in_steps, drop)
        return torch.stack([out.logits_a, out.logits_b], dim=1)  # (B, 2, rows, T', K)

    def compute_losses(
        self,
        batch: dict[str, Any],
        *,
        condition_drop: float,
        generator: torch.Generator | None = None,
    ) -> InterMLosses:
        """Stage-1 masked CE (random / interaction masking + BERT corruption) and, with
        ``step_unroll``, the stage-2 CE on the re-masked least confident predictions.

        ``generator`` draws the masks, corruption and condition drops (the trainer's
        :meth:`batch_generator`). Data parallel: they are drawn for the whole global batch on
        every rank (:mod:`intermask.utils.distributed`) and the CE is a mean over the
        global batch's masked tokens, so N processes take the step of one process.
        """
        targets, lengths_in_steps = self.tokenize(batch)
        text = self.encode_text(batch["caption"])
        vocabulary = self.net.vocabulary
        mine = local_rows(targets.shape[0])
        every_length = gather_rows(lengths_in_steps)
        layout = _layout_of(every_length, targets.shape[2:])  # the global batch, codes unknown
        layout[mine] = targets
        masking = training_mask(
            layout[:, 0],
            layout[:, 1],
            every_length,
            p_random=self.hparams.p_random,
            p_solo=self.hparams.get("p_solo", 0.0),  # checkpoints from before the switch: 0
            p_partner=self.hparams.get("p_partner", 0.0),
            generator=generator,
        )
        corrupted = bert_corruption(layout, masking.mask, vocabulary, generator=generator).tokens
        corrupted = corrupted[mine]
        drawn = torch.rand(layout.shape[0], generator=generator, device=targets.device)
        drop = drawn[mine] < condition_drop  # (B,)
        mask, tau = masking.mask[mine], masking.tau[mine]
        logits = self._forward(corrupted, text, lengths_in_steps, drop)
        stage1 = global_masked_cross_entropy(logits, targets, mask)
        accuracy = masked_accuracy(logits.detach(), targets, mask)
        stage2 = stage1.new_zeros(())
        if self.hparams.step_unroll:
            unroll = step_unroll_mask(
                logits.detach(), corrupted, mask, tau, lengths_in_steps, vocabulary
            )
            logits2 = self._forward(unroll.tokens, text, lengths_in_steps, drop)
            stage2 = global_masked_cross_entropy(logits2, targets, unroll.mask)
        return InterMLosses(stage1 + stage2, stage1, stage2, accuracy)

    def loss_values(self, losses: InterMLosses) -> dict[str, torch.Tensor]:
        return {
            "loss": losses.total,
            "loss_stage1": losses.stage1,
            "loss_stage2": losses.stage2,
            "masked_accuracy": losses.masked_accuracy,
        }

    def condition_gain(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        """Masked CE of the batch with every token masked, with its captions and with the null
        condition -> (ce_text, ce_null). Their difference (nats per token) is how much the
        caption tells the network at the first decoding iteration, where the sampler has
        nothing else to go on; near 0 means samples will not follow their captions."""
        targets, lengths_in_steps = self.tokenize(batch)
        mask = targets >= 0
        masked = targets.masked_fill(mask, self.net.vocabulary.mask_id)
        text = self.encode_text(batch["caption"])
        ce = []
        for drop in (False, True):
            flags = torch.full((targets.shape[0],), drop, device=targets.device)
            logits = self._forward(masked, text, lengths_in_steps, flags)
            ce.append(masked_cross_entropy(logits, targets, mask))
        return ce[0], ce[1]

    def _log_validation_samples(self, batch: dict[str, Any]) -> None:
        """Log the condition gain of the batch (:meth:`condition_gain`), then generate from the
        first captions of the batch and log decoded joint statistics of the samples and of
        their ground truth (same lengths)."""
        ce_text, ce_null = self.condition_gain(batch)
        size = batch["motion"].shape[0]
        self.log("val/fully_masked_ce", ce_text, batch_size=size)
        self.log("val/condition_gain", ce_null - ce_text, batch_size=size)
        count = min(self.hparams.validation_samples, batch["motion"].shape[0])
        captions = list(batch["caption"][:count])
        motion = batch["motion"][:count]
        frames = motion.shape[2] - motion.shape[2] % FRAMES_PER_STEP
        lengths = batch["length"][:count].to(self.device).long().clamp(max=frames)
        lengths = (lengths - lengths % FRAMES_PER_STEP).clamp_min(2 * FRAMES_PER_STEP)
        generated = self.sampler(iterations=self.hparams.sample_iterations)(
            captions, lengths, seeds=list(range(count))
        )
        self.last_samples = (captions, generated)
        real = joints_from_features(self.vq, motion[:, :, :frames].float())
        if generated.joints is None or real is None:
            return  # a representation without positions (Inter-X without a body model)
        fps = self.hparams.fps
        for source, joints in (("generated", generated.joints), ("real", real)):
            for name, value in interaction_statistics(joints, lengths, fps=fps).items():
                self.log(f"val_samples/{source}_{name}", value, batch_size=count)
