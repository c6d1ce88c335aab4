"""The InterHuman evaluator: InterGen's contrastive text-motion model ("InterCLIP").

Motion side: de-normalized (B, 2, T, 262) -> per person drop the 4 foot-contact dims ->
(B, T, 516) -> Linear -> [query token, frames] + sinusoidal position encoding -> post-norm GELU
TransformerEncoder with a key-padding mask -> LayerNorm -> query-token output -> Linear(512).
Text side: CLIP tokenizer -> frozen CLIP token + positional embedding (CLIP's own transformer is
not used) -> trainable TransformerEncoder (no mask) -> LayerNorm -> end-of-text feature ->
Linear(512). Both sides are L2-normalized and multiplied by the learnable ``latent_scale``, so
the CLIP loss's logit scale is ``latent_scale ** 2``.

Submodule names follow the released ``interclip.ckpt`` (``motion_encoder.query_token``,
``textTransEncoder.layers.0...``, ``text_ln``, ``out``, ...), so its state dict maps directly.

Batch order: the reference sorts every batch by motion length (descending) before encoding.
Nothing here needs that: each row is encoded independently (the padding mask hides padded frames
from the query token), so outputs stay in input order and equal the sorted computation row by
row (tested).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from intermask.motion.masks import length_mask
from intermask.text.clip_encoder import FrozenCLIPTextEncoder, register_model_configs
from intermask.utils.layers import post_norm_gelu_encoder

FOOT_CONTACT_DIMS = 4  # the last 4 of the 262 InterHuman features (InterGen drops them)
FEATURE_DIM = 262


class PositionalEncoding(nn.Module):
    """Sinusoidal position encoding (sin on even, cos on odd channels) followed by dropout.

    ``pe`` is a persistent (max_len, D) buffer, as in the released checkpoint.
    """

    def __init__(self, *, dim: int, max_len: int = 2000, dropout: float = 0.1) -> None:
        super().__init__()
        if dim % 2:
            raise ValueError(f"position encoding needs an even width, got {dim}")
        position = torch.arange(max_len, dtype=torch.float32)[:, None]
        frequency = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(1e4) / dim))
        pe = torch.zeros(max_len, dim)
        pe[:, 0::2] = torch.sin(position * frequency)
        pe[:, 1::2] = torch.cos(position * frequency)
        self.register_buffer("pe", pe)
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, L, D) -> (B, L, D)."""
        if x.shape[1] > self.pe.shape[0]:
            raise ValueError(
                f"sequence of {x.shape[1]} positions exceeds the encoding's max_len {self.pe.shape[0]}"
            )
        return self.dropout(x + self.pe[None, : x.shape[1]].to(x.dtype))


class InterCLIPMotionEncoder(nn.Module):
    """(B, T, motion_dim) frames + (B,) lengths -> (B, embed_dim) un-normalized embedding."""

    def __init__(
        self,
        *,
        motion_dim: int,
        width: int,
        layers: int,
        heads: int,
        ff: int,
        dropout: float,
        max_len: int,
        embed_dim: int,
    ) -> None:
        super().__init__()
        self.query_token = nn.Parameter(torch.randn(1, width))
        self.embed_motion = nn.Linear(motion_dim, width)
        self.sequence_pos_encoder = PositionalEncoding(dim=width, max_len=max_len, dropout=dropout)
        self.transformer = post_norm_gelu_encoder(
            width=width, layers=layers, heads=heads, ff=ff, dropout=dropout
        )
        self.out_ln = nn.LayerNorm(width)
        self.out = nn.Linear(width, embed_dim)

    def forward(self, frames: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        batch, frames_count = frames.shape[:2]
        x = self.embed_motion(frames)  # (B, T, D)
        query = self.query_token.expand(batch, 1, -1).to(x.dtype)
        x = self.sequence_pos_encoder(torch.cat([query, x], dim=1))  # (B, 1 + T, D)
        padding = ~length_mask(lengths.to(frames.device), frames_count)  # (B, T) True on padding
        padding = torch.cat([padding.new_zeros(batch, 1), padding], dim=1)  # the query is valid
        x = self.transformer(x, src_key_padding_mask=padding)
        return self.out(self.out_ln(x)[:, 0])  # (B, embed_dim)


class InterCLIP(nn.Module):
    """InterGen's evaluator network (trainable; :class:`FrozenEvaluator` wraps it for metrics).

    Args:
        text_encoder: our frozen CLIP tower; only its tokenizer, token embedding and positional
            embedding are taken (copied, frozen). Give either this or ``clip_model_name``.
        clip_model_name: open_clip architecture whose tokenizer and embedding sizes to use when
            the embeddings come from a checkpoint instead (loading a trained or released file).
        motion_dim: input features per frame after dropping the foot contacts (2 x 258 = 516).
        width, layers, heads, ff, dropout, max_len: the motion transformer (1024, 8, 8, 2048,
            0.1, 2000 in InterGen's eval_model.yaml).
        text_layers, text_heads, text_ff, text_dropout: the trainable text transformer over CLIP
            token embeddings (8, 8, 2048, 0.1); its width is the CLIP width (768 for ViT-L/14).
        embed_dim: the shared embedding size (512).
        latent_scale_init: initial ``latent_scale`` (1.0 in InterGen).
        text_embedding_scale: factor applied once to the copied (frozen) CLIP token and
            positional embeddings. 1.0 = InterGen. Only for a *random* demo tower: its
            embeddings have CLIP's initial scale (std 0.02), under which the post-norm text stack
            drowns word identity in its biases and trains as a bag of words for thousands of
            steps; rescaling random vectors changes no meaning. Stored scaled in checkpoints.
    """

    architecture = "interclip"
    dataset = "interhuman"

    def __init__(
        self,
        *,
        text_encoder: FrozenCLIPTextEncoder | None = None,
        clip_model_name: str | None = None,
        context_length: int = 77,
        motion_dim: int = 2 * (FEATURE_DIM - FOOT_CONTACT_DIMS),
        width: int = 1024,
        layers: int = 8,
        heads: int = 8,
        ff: int = 2048,
        dropout: float = 0.1,
        max_len: int = 2000,
        text_layers: int = 8,
        text_heads: int = 8,
        text_ff: int = 2048,
        text_dropout: float = 0.1,
        embed_dim: int = 512,
        latent_scale_init: float = 1.0,
        text_embedding_scale: float = 1.0,
    ) -> None:
        super().__init__()
        if (text_encoder is None) == (clip_model_name is None):
            raise ValueError(
                "give exactly one of text_encoder (training) or clip_model_name (weights from a "
                f"checkpoint); got text_encoder={type(text_encoder).__name__}, "
                f"clip_model_name={clip_model_name!r}"
            )
        if not text_embedding_scale > 0:
            raise ValueError(f"text_embedding_scale must be > 0, got {text_embedding_scale}")
        if motion_dim != 2 * (FEATURE_DIM - FOOT_CONTACT_DIMS):
            raise ValueError(
                f"motion_dim must be 2 x (262 - 4) = 516 for InterHuman features, got {motion_dim}"
            )
        if text_encoder is not None:
            vocab_size, text_width = text_encoder.token_embedding.weight.shape
            context_length = text_encoder.context_length
            self.clip_model_name = text_encoder.model_name
            self.tokenizer = text_encoder.tokenizer
        else:
            import open_clip

            register_model_configs()
            config = open_clip.get_model_config(clip_model_name)
            if config is None:
                raise ValueError(f"unknown open_clip model_name {clip_model_name!r}")
            vocab_size, text_width = config["text_cfg"]["vocab_size"], config["text_cfg"]["width"]
            self.clip_model_name = clip_model_name
            self.tokenizer = open_clip.get_tokenizer(clip_model_name, context_length=context_length)
        self.context_length = context_length
        self.motion_encoder = InterCLIPMotionEncoder(
            motion_dim=motion_dim,
            width=width,
            layers=layers,
            heads=heads,
            ff=ff,
            dropout=dropout,
            max_len=max_len,
            embed_dim=embed_dim,
        )
        self.latent_scale = nn.Parameter(torch.tensor([float(latent_scale_init)]))
        self.token_embedding = nn.Embedding(vocab_size, text_width)
        self.positional_embedding = nn.Parameter(torch.zeros(context_length, text_width))
        if text_encoder is not None:
            with torch.no_grad():
                scale = float(text_embedding_scale)
                self.token_embedding.weight.copy_(text_encoder.token_embedding.weight * scale)
                self.positional_embedding.copy_(text_encoder.positional_embedding * scale)
        # frozen CLIP embeddings (the reference encodes them under no_grad)
        self.token_embedding.requires_grad_(False)
        self.positional_embedding.requires_grad_(False)
        self.textTransEncoder = post_norm_gelu_encoder(
            width=text_width, layers=text_layers, heads=text_heads, ff=text_ff, dropout=text_dropout
        )
        self.text_ln = nn.LayerNorm(text_width)
        self.out = nn.Linear(text_width, embed_dim)
        self.embed_dim = embed_dim

    @property
    def device(self) -> torch.device:
        return self.latent_scale.device

    def _scale(self, embedding: torch.Tensor) -> torch.Tensor:
        return F.normalize(embedding, dim=-1) * self.latent_scale

    def encode_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """De-normalized (B, 2, T, 262) motion + (B,) frame counts -> (B, embed_dim).

        Time is cropped to the longest sequence of the batch and padded frames are hidden from
        the attention, so the result does not depend on padding, batch order or batch company.
        """
        if motion.ndim != 4 or motion.shape[1] != 2 or motion.shape[-1] != FEATURE_DIM:
            raise ValueError(
                f"InterCLIP expects de-normalized motion (B, 2, T, {FEATURE_DIM}), "
                f"got {tuple(motion.shape)}"
            )
        lengths = check_lengths(lengths, batch=motion.shape[0], frames=motion.shape[2])
        motion = motion.to(self.device)
        lengths = lengths.to(self.device)
        longest = int(lengths.max())
        frames = rearrange(
            motion[:, :, :longest, : FEATURE_DIM - FOOT_CONTACT_DIMS], "b p t c -> b t (p c)"
        )
        return self._scale(self.motion_encoder(frames.float(), lengths))

    def encode_text(
        self, captions: Sequence[str], tokens: Sequence[str] | None = None
    ) -> torch.Tensor:
        """B captions -> (B, embed_dim). ``tokens`` (Inter-X POS tags) are not used here."""
        check_captions(captions)
        ids = self.tokenizer(list(captions)).to(self.device, torch.int64)  # (B, L)
        x = self.token_embedding(ids) + self.positional_embedding  # (B, L, W)
        x = self.text_ln(self.textTransEncoder(x))  # the reference uses no attention mask
        # the end-of-text token has the largest id of CLIP's vocabulary
        x = x[torch.arange(ids.shape[0], device=ids.device), ids.argmax(dim=-1)]
        return self._scale(self.out(x))

    def logit_scale(self) -> torch.Tensor:
        """() the CLIP loss's temperature: latent_scale ** 2 (InterGen)."""
        return self.latent_scale.squeeze(0) ** 2


def check_lengths(
    lengths: torch.Tensor | Sequence[int], *, batch: int, frames: int
) -> torch.Tensor:
    """(B,) frame counts as int64; errors name the offending values."""
    lengths = torch.as_tensor(lengths).reshape(-1).long()
    if lengths.numel() != batch:
        raise ValueError(f"lengths has {lengths.numel()} entries for a batch of {batch}")
    if bool((lengths < 1).any()) or bool((lengths > frames).any()):
        raise ValueError(
            f"lengths must lie in [1, {frames}] (the padded time axis), got min "
            f"{int(lengths.min())} and max {int(lengths.max())}"
        )
    return lengths


def check_captions(captions: Sequence[str]) -> None:
    if isinstance(captions, str):
        raise TypeError("captions must be a sequence of strings, got a single string")
    if len(captions) == 0:
        raise ValueError("captions is empty: nothing to encode")
