"""Tiny evaluator networks (nothing downloads) and random batches in the datasets' layouts.

A uniquely named module rather than conftest: `conftest` names clash across test folders."""

from __future__ import annotations

import torch

from intermask.evaluator import GRUMatcher, HumanML3DMatcher, InterCLIP
from intermask.text import TINY_MODEL_NAME

TINY_INTERCLIP = dict(
    width=32, layers=2, heads=4, ff=48, dropout=0.0, text_layers=1, text_heads=4, text_ff=48
)
TINY_GRU = dict(
    word_dim=12, movement_hidden=16, movement_latent=16, motion_hidden=20, text_hidden=18
)
WORDS = ["sos", "eos", "unk", "person", "wave", "hand", "left", "the", "hug", "other"]
TOKENS = [
    "the/DET person/NOUN wave/VERB left/ADJ hand/NOUN",
    "person/NOUN hug/VERB the/DET other/ADJ",
    "the/DET person/NOUN jump/VERB",
]
CAPTIONS = ["the person waves the left hand", "a person hugs the other", "the person jumps"]


def tiny_interclip(seed: int = 0, **overrides) -> InterCLIP:
    torch.manual_seed(seed)
    return InterCLIP(clip_model_name=TINY_MODEL_NAME, **{**TINY_INTERCLIP, **overrides}).eval()


def tiny_gru(seed: int = 0, **overrides) -> GRUMatcher:
    torch.manual_seed(seed)
    return GRUMatcher(vocabulary=WORDS, **{**TINY_GRU, **overrides}).eval()


def humanml3d_statistics(seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """(263,) mean and std (std in [0.5, 1.5]) standing for an evaluator's meta files."""
    generator = torch.Generator().manual_seed(seed)
    return torch.randn(263, generator=generator), torch.rand(263, generator=generator) + 0.5


def tiny_humanml3d(seed: int = 0, *, statistics: bool = True, **overrides) -> HumanML3DMatcher:
    torch.manual_seed(seed)
    mean, std = humanml3d_statistics(seed) if statistics else (None, None)
    return HumanML3DMatcher(
        vocabulary=WORDS, mean=mean, std=std, **{**TINY_GRU, **overrides}
    ).eval()


def interhuman_batch(batch: int = 3, frames: int = 20, seed: int = 0):
    """(B, 2, T, 262) features and (B,) lengths (all different, the first one not the longest)."""
    generator = torch.Generator().manual_seed(seed)
    motion = torch.randn(batch, 2, frames, 262, generator=generator)
    lengths = torch.tensor([frames - 7, frames, frames - 3, 5, frames - 1][:batch])
    return motion, lengths


def interx_batch(batch: int = 3, frames: int = 24, seed: int = 0):
    """(B, 2, T, 56, 6) representation-like values and (B,) lengths (multiples of 4)."""
    generator = torch.Generator().manual_seed(seed)
    motion = torch.randn(batch, 2, frames, 56, 6, generator=generator)
    lengths = torch.tensor([frames - 8, frames, frames - 4, 8, frames - 12][:batch])
    return motion, lengths


def humanml3d_batch(batch: int = 3, frames: int = 24, seed: int = 0):
    """De-normalized-like (B, T, 263) features and (B,) lengths (multiples of 4, unsorted)."""
    generator = torch.Generator().manual_seed(seed)
    motion = torch.randn(batch, frames, 263, generator=generator) * 2 + 1
    lengths = torch.tensor([frames - 8, frames, frames - 4, 8, frames - 12][:batch])
    return motion, lengths
