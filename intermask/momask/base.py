"""The LightningModule base of MoMask's two transformers: frozen tokenizer and text encoder.

As :class:`~intermask.interm.module.InterMModule` does, the frozen residual VQ-VAE and the frozen
text encoder are kept in a plain attribute, not as submodules: ``state_dict``, checkpoints,
``parameters()`` (hence the optimizer), ``.train()`` and Lightning's device moves never see
them. Checkpoints hold the transformer; the tokenizer comes from its own ``train_vq`` run
(``vq_ckpt``), from a built ``vq``, or later from :meth:`MoMaskModuleBase.set_tokenizer`, and the
checkpoint records its weights digest so that a resumed run cannot switch tokenizers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import torch
from torch import nn
from torch.optim import Optimizer

from intermask.interm.token_cache import FrozenTokenizerHooks, TokenCache
from intermask.momask.model import sentence_features
from intermask.text.cache import TextFeatureCache
from intermask.utils.fingerprint import weights_digest
from intermask.utils.lightning import LossStepsModule
from intermask.vq.load import load_vq
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE
from intermask.vq.views import TwoPersonView

LR_MILESTONES = (0.27,)  # reference: x0.1 at iteration 50,000 of ~180k (see the configs)
LR_GAMMA = 0.1  # reference


class MoMaskLosses(NamedTuple):
    total: torch.Tensor  # () mean CE over the loss positions of the global batch
    accuracy: torch.Tensor  # () argmax accuracy over the loss positions


@dataclass
class _Frozen:
    """Holder that hides the frozen networks from ``nn.Module`` registration."""

    vq: MotionVQVAE | None
    text: TextFeatureCache


def check_probability(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1], got {value}")


class MoMaskModuleBase(FrozenTokenizerHooks, LossStepsModule):
    """The part both transformers share: frozen tokenizer and text, tokens, text features.

    Subclasses build their network from a factory (:meth:`_build_net`), check a tokenizer
    against it (:meth:`_check_tokenizer`) and define the losses.
    """

    def __init__(
        self,
        *,
        net: nn.Module | Callable[..., nn.Module],
        text: TextFeatureCache,
        optimizer: Callable[..., Optimizer],
        warmup_fraction: float,
        vq: MotionVQVAE | None,
        vq_ckpt: str | Path | None,
        condition_drop: float,
        lr_milestones: Sequence[float],
        lr_gamma: float,
        token_cache: bool,
        hyper_parameters: dict[str, Any],
    ) -> None:
        super().__init__()
        check_probability("condition_drop", condition_drop)
        if not 0.0 <= warmup_fraction < 1.0:
            raise ValueError(f"warmup_fraction must lie in [0, 1), got {warmup_fraction}")
        if vq is not None and vq_ckpt is not None:
            raise ValueError("give the tokenizer as vq or as vq_ckpt, not both")
        if vq_ckpt is not None:
            vq = load_vq(vq_ckpt)
        if not isinstance(net, nn.Module):
            if vq is None:
                raise ValueError(
                    "net is a factory: it takes its codebook size from the tokenizer, so vq or "
                    "vq_ckpt must be given (or pass a built network and call set_tokenizer)"
                )
            net = self._build_net(net, vq, text.encoder.width)
        if net.text_dim != text.encoder.width:
            raise ValueError(
                f"net.text_dim ({net.text_dim}) must equal the text encoder width "
                f"({text.encoder.width})"
            )
        self.net = net
        self._frozen = _Frozen(vq=None, text=text)
        self.token_cache = TokenCache(codebook_size=net.codebook_size) if token_cache else None
        self.optimizer_factory = optimizer
        # plain Python values only, so checkpoints load with torch.load(weights_only=True)
        self.save_hyperparameters(
            {
                "condition_drop": float(condition_drop),
                "warmup_fraction": float(warmup_fraction),
                "lr_milestones": [float(m) for m in lr_milestones],
                "lr_gamma": float(lr_gamma),
                "token_cache": bool(token_cache),
                "validation_samples": 0,  # LossStepsModule: no sample generation in validation
                "vq_digest": None,  # set by set_tokenizer
                # what a loader rebuilds the network with (the tokenizer and text own them)
                "codebook_size": int(net.codebook_size),
                "text_dim": int(net.text_dim),
                "num_quantizers": int(getattr(net, "num_quantizers", 0)) or None,
                **hyper_parameters,
            },
            logger=False,
        )
        if vq is not None:
            self.set_tokenizer(vq)

    def _build_net(
        self, factory: Callable[..., nn.Module], vq: MotionVQVAE, text_dim: int
    ) -> nn.Module:
        """The network of ``factory`` for ``vq``'s codes and ``text_dim``-wide text."""
        raise NotImplementedError

    def _check_tokenizer(self, vq: MotionVQVAE) -> None:
        """Raise when ``vq``'s tokens do not fit the network (beyond the codebook size)."""
        raise NotImplementedError

    def set_tokenizer(self, vq: MotionVQVAE) -> None:
        """Use ``vq`` (frozen, eval mode, not checkpointed) to tokenize the batches."""
        if isinstance(vq.view, TwoPersonView):
            raise ValueError("MoMask needs a single-person VQ-VAE, got persons=2")
        if vq.token_rows != 1:
            raise ValueError(
                f"MoMask needs 1D tokens (one token row), the VQ-VAE has {vq.token_rows} rows"
            )
        if vq.quantizer.codebook_size != self.net.codebook_size:
            raise ValueError(
                f"the VQ-VAE has {vq.quantizer.codebook_size} codes per layer, the network "
                f"{self.net.codebook_size}"
            )
        self._check_tokenizer(vq)
        vq.eval().requires_grad_(False)
        self._frozen.vq = vq
        self.hparams["vq_digest"] = weights_digest(vq)

    @property
    def vq(self) -> MotionVQVAE:
        if self._frozen.vq is None:
            raise RuntimeError("no tokenizer: pass vq or vq_ckpt, or call set_tokenizer(vq) first")
        return self._frozen.vq

    @property
    def text(self) -> TextFeatureCache:
        return self._frozen.text

    def tokenize(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        """Batch -> (B, Q, T') codes of every layer (-1 beyond each length) and (B,) lengths in
        token steps."""
        motion, lengths = batch["motion"], batch["length"]
        if motion.ndim < 3:
            raise ValueError(f"motion must be (B, T, *F), got {tuple(motion.shape)}")
        frames = motion.shape[1] - motion.shape[1] % FRAMES_PER_STEP
        lengths = torch.as_tensor(lengths, device=motion.device).long().clamp(max=frames)
        lengths = lengths - lengths % FRAMES_PER_STEP
        self._move_frozen(motion.device)
        motion = motion[:, :frames]
        keys = self._crop_keys(batch, lengths.tolist(), frames)
        if keys is None:
            tokens = self._encode(motion, lengths)
        else:
            tokens = self._cached_tokens(motion, lengths, keys)
        return tokens[:, :, 0], lengths // FRAMES_PER_STEP

    def _encode(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """(B, T, *F), (B,) frames -> (B, Q, 1, T') codes."""
        # nearest-code search in float32 even under bf16 autocast: rounding could change codes
        with torch.autocast(device_type=motion.device.type, enabled=False):
            return self.vq.encode(motion.float(), lengths)

    def _crop_keys(self, batch: dict[str, Any], lengths: list[int], frames: int) -> list | None:
        """Per-sample cache keys (id, start frame, length, padded frames), or None when the cache
        is off or the batch does not identify its crops."""
        if self.token_cache is None or "id" not in batch or "start" not in batch:
            return None
        return [
            (str(batch["id"][b]), int(batch["start"][b]), lengths[b], frames)
            for b in range(len(lengths))
        ]

    def _cached_tokens(
        self, motion: torch.Tensor, lengths: torch.Tensor, keys: list
    ) -> torch.Tensor:
        """:meth:`_encode` through the token cache: only missing crops are encoded, then kept."""
        cache = self.token_cache
        cache.bind(self.vq)
        codes = [cache.get(key) for key in keys]  # (Q, 1, T') or None
        missing = [b for b, found in enumerate(codes) if found is None]
        if missing:
            index = torch.tensor(missing, device=motion.device)
            fresh = self._encode(motion[index], lengths[index]).cpu()
            for row, sample in enumerate(missing):
                codes[sample] = fresh[row]
                cache.put(keys[sample], fresh[row])
        return torch.stack(codes).to(motion.device)

    def sentence(self, captions: Sequence[str]) -> torch.Tensor:
        """B captions -> (B, D_text) sentence features on the module's device."""
        if isinstance(captions, str):
            raise TypeError("captions must be a sequence of strings, got a single string")
        if self.text.encoder.device != self.device:
            self.text.encoder.to(self.device)
        return sentence_features(self.text.get_or_encode(list(captions))).to(self.device)

    def _lengths_in_steps(self, lengths: torch.Tensor | Sequence[int], batch: int) -> torch.Tensor:
        lengths = torch.as_tensor(lengths, device=self.device).long()
        if lengths.shape != (batch,) or bool((lengths < FRAMES_PER_STEP).any()):
            raise ValueError(
                f"lengths must be ({batch},) frames >= {FRAMES_PER_STEP}, got {lengths.tolist()}"
            )
        return lengths // FRAMES_PER_STEP

    def loss_values(self, losses: MoMaskLosses) -> dict[str, torch.Tensor]:
        return {"loss": losses.total, "accuracy": losses.accuracy}
