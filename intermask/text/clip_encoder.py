"""Frozen CLIP text tower (open_clip): per-token features for the trainable text layers.

InterMask conditions on CLIP ViT-L/14@336px per-token features (77 x 768) taken after CLIP's
final LayerNorm, not on CLIP's pooled and projected sentence embedding: the trainable text
layers downstream pick the end-of-text token themselves. Only the text tower is kept; the
visual tower is deleted right after creation.

Weights come from an open_clip tag (``"openai"``, downloaded once by open_clip), from a local
checkpoint file, or nowhere (``pretrained=None``): a seeded random tower for tests and the demo,
announced loudly in the log. The bundled ``intermask-tiny-text`` architecture (width 64, 2
layers) is registered with open_clip on import of this module.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import torch
from lightning.pytorch.utilities.rank_zero import rank_zero_only
from torch import nn

from intermask.utils.fingerprint import weights_digest

log = logging.getLogger(__name__)

TINY_MODEL_NAME = "intermask-tiny-text"
_MODEL_CONFIG_DIR = Path(__file__).parent / "model_configs"


class TextFeatures(NamedTuple):
    """What a text tower gives every text-conditioned network (Inter-M, MoMask, ARFlow)."""

    features: torch.Tensor  # (B, L, D) per-token features after CLIP's ln_final
    eot_index: torch.Tensor  # (B,) int64 position of the end-of-text token
    padding_mask: torch.Tensor | None = None  # (B, L) bool, True after the end-of-text token;
    # None: attend to all L


@rank_zero_only
def _announce(message: str) -> None:
    log.warning(message)


def register_model_configs() -> None:
    """Add the bundled architectures (``intermask-tiny-text``) to open_clip's registry."""
    import open_clip

    if TINY_MODEL_NAME not in open_clip.list_models():
        open_clip.add_model_config(_MODEL_CONFIG_DIR)


def padding_mask_from_eot(eot_index: torch.Tensor, length: int) -> torch.Tensor:
    """(B,) end-of-text positions -> (B, L) bool mask, True strictly after the end-of-text token."""
    positions = torch.arange(length, device=eot_index.device)
    return positions[None, :] > eot_index[:, None]


class FrozenCLIPTextEncoder(nn.Module):
    """CLIP text transformer, frozen and always in eval mode.

    Args:
        model_name: open_clip architecture (paper: ``ViT-L-14-336``; tests: ``intermask-tiny-text``).
        pretrained: an open_clip tag (``"openai"``), a local checkpoint file, or None for a
            seeded random tower (never real CLIP features).
        context_length: L, tokens per caption (CLIP: 77).
        quick_gelu: activation of the tower; None follows the pretrained tag (OpenAI CLIP uses
            QuickGELU) or else the architecture config. Set True for a local OpenAI checkpoint.
        seed: initialisation seed of a random tower, so every DDP rank and every process builds
            the same weights (and the feature cache stays valid).
    """

    def __init__(
        self,
        *,
        model_name: str = "ViT-L-14-336",
        pretrained: str | None = None,
        context_length: int = 77,
        quick_gelu: bool | None = None,
        seed: int = 0,
    ) -> None:
        super().__init__()
        import open_clip

        register_model_configs()
        if model_name not in open_clip.list_models():
            raise ValueError(
                f"unknown open_clip model_name {model_name!r}; available: {open_clip.list_models()}"
            )
        if context_length < 2:
            raise ValueError(
                f"context_length must be >= 2 (start + end token), got {context_length}"
            )
        self.model_name, self.context_length = model_name, context_length
        self.source, checkpoint, quick_gelu = _resolve_pretrained(
            model_name, pretrained, quick_gelu
        )

        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            clip = _create_clip(model_name, checkpoint, pretrained, context_length, quick_gelu)
        del clip.visual  # the image tower is never used: free its memory at once
        self.token_embedding = clip.token_embedding
        self.positional_embedding = clip.positional_embedding
        self.transformer = clip.transformer
        self.ln_final = clip.ln_final
        self.register_buffer("attn_mask", clip.attn_mask, persistent=False)  # (L, L) causal
        self.tokenizer = open_clip.get_tokenizer(model_name, context_length=context_length)
        self.requires_grad_(False)
        self.train(False)

        if pretrained is None:
            self.source = f"random(seed={seed})"
        self.quick_gelu = quick_gelu
        self.identity = (
            f"open_clip:{model_name}|pretrained={self.source}|quick_gelu={quick_gelu}"
            f"|context={context_length}|weights={weights_digest(self)[:16]}"
        )
        if pretrained is None:
            _announce(
                f"text encoder {model_name} is RANDOMLY INITIALISED (seed {seed}, width "
                f"{self.width}): its features are not CLIP features. Use it for tests and the "
                "demo only; set pretrained to 'openai' or a checkpoint file for real runs."
            )
        else:
            log.info("text encoder %s loaded from %s (frozen)", model_name, self.source)

    @property
    def width(self) -> int:
        """D, the width of the per-token features."""
        return int(self.token_embedding.weight.shape[1])

    @property
    def device(self) -> torch.device:
        return self.token_embedding.weight.device

    def train(self, mode: bool = True) -> FrozenCLIPTextEncoder:
        """The tower is frozen: it stays in eval mode whatever the caller asks."""
        return super().train(False)

    def tokenize(self, captions: Sequence[str]) -> torch.Tensor:
        """B captions -> (B, L) int64 CLIP token ids (start, BPE tokens, end, zero padding)."""
        if isinstance(captions, str):
            raise TypeError("captions must be a sequence of strings, got a single string")
        if len(captions) == 0:
            raise ValueError("captions is empty: nothing to encode")
        return self.tokenizer(list(captions)).to(torch.int64)

    @torch.no_grad()
    def encode(self, captions: Sequence[str]) -> TextFeatures:
        """B captions -> TextFeatures: tokens (B, L, D), eot_index (B,), padding_mask (B, L).

        A row's features are a function of its caption alone, to the last bit: each caption
        goes through the tower on its own. In a batch, CLIP's causal mask keeps the captions
        apart, but the matmuls do not round a row the same way for every batch size: on AVX2
        kernels every feature of a caption encoded among 300 differs from the same caption
        encoded alone (by up to 2.6e-6, and in fp16 as well). The features feed a cache that jobs
        share (:class:`intermask.text.cache.TextFeatureCache`), so batch-dependent features
        made one job's numbers depend on which captions an earlier job had encoded together.
        """
        ids = self.tokenize(captions).to(self.device)  # (B, L)
        x = torch.cat([self._tower(row[None]) for row in ids])  # (B, L, D)
        # the end-of-text token has the largest id of CLIP's vocabulary (open_clip pools the same way)
        eot_index = ids.argmax(dim=-1)  # (B,)
        return TextFeatures(x, eot_index, padding_mask_from_eot(eot_index, ids.shape[1]))

    def _tower(self, ids: torch.Tensor) -> torch.Tensor:
        """(1, L) token ids -> (1, L, D) features after the final LayerNorm."""
        cast_dtype = self.transformer.get_cast_dtype()
        x = self.token_embedding(ids).to(cast_dtype) + self.positional_embedding.to(cast_dtype)
        return self.ln_final(self.transformer(x, attn_mask=self.attn_mask))

    def forward(self, captions: Sequence[str]) -> TextFeatures:
        return self.encode(captions)

    def extra_repr(self) -> str:
        return f"model_name={self.model_name!r}, source={self.source!r}, frozen=True"


def _resolve_pretrained(
    model_name: str, pretrained: str | None, quick_gelu: bool | None
) -> tuple[str, str | None, bool]:
    """-> (source for the identity, checkpoint file or None, quick_gelu)."""
    import open_clip

    config_quick_gelu = bool(open_clip.get_model_config(model_name).get("quick_gelu", False))
    if pretrained is None:
        return "random", None, config_quick_gelu if quick_gelu is None else quick_gelu
    tags = open_clip.list_pretrained_tags_by_model(model_name)
    if pretrained in tags:
        tag_quick_gelu = bool(
            open_clip.get_pretrained_cfg(model_name, pretrained).get("quick_gelu")
        )
        return pretrained, None, tag_quick_gelu if quick_gelu is None else quick_gelu
    path = Path(pretrained).expanduser()
    if not path.is_file():
        raise FileNotFoundError(
            f"pretrained={pretrained!r} is neither an open_clip tag for {model_name} "
            f"(known tags: {tags}) nor an existing checkpoint file: {path.resolve()} not found"
        )
    if quick_gelu is None:
        log.warning(
            "%s: activation follows the %s config (quick_gelu=%s); OpenAI CLIP weights need "
            "quick_gelu=True",
            path,
            model_name,
            config_quick_gelu,
        )
        quick_gelu = config_quick_gelu
    return str(path.resolve()), str(path.resolve()), quick_gelu


def _create_clip(
    model_name: str,
    checkpoint: str | None,
    pretrained: str | None,
    context_length: int,
    quick_gelu: bool,
) -> Any:
    import open_clip

    weights = checkpoint if checkpoint is not None else pretrained
    try:
        return open_clip.create_model(
            model_name,
            pretrained=weights,
            force_context_length=context_length,
            force_quick_gelu=quick_gelu,
            pretrained_text=False,
        )
    except Exception as error:
        if checkpoint is not None:
            raise RuntimeError(
                f"could not load the CLIP checkpoint {checkpoint} into {model_name}: {error}"
            ) from error
        url = open_clip.get_pretrained_url(model_name, weights) if weights else ""
        raise RuntimeError(
            f"could not obtain CLIP weights {model_name}/{weights} ({error}). Offline? Download "
            f"them once on a machine with network access ({url or 'see open_clip'}) and set "
            f"the encoder's `pretrained` to the local file, e.g. "
            f"text.encoder.pretrained=/path/to/{model_name}.pt"
        ) from error
