"""The frozen evaluator the metrics use: fixed weights, eval mode for good, no gradients."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from intermask.evaluator.gru_matcher import T2MMatcher
from intermask.evaluator.interclip import InterCLIP


class FrozenEvaluator(nn.Module):
    """Protocol API around a trained :class:`InterCLIP` or T2M matcher (:class:`T2MMatcher`).

    Attributes:
        name: architecture and source, e.g. ``"interclip[released]"``,
            ``"t2m_gru+learned_words[trained:synthetic_interx]"``.
        file_hash: sha256 of the checkpoint file, first 16 hex digits.
        dataset: ``"interhuman"``, ``"interx"`` or ``"humanml3d"``: which motion layout
            ``encode_motion`` takes.
        embed_dim: embedding size (512).
    """

    def __init__(self, net: InterCLIP | T2MMatcher, *, name: str, file_hash: str) -> None:
        super().__init__()
        self.net = net
        self.name, self.file_hash = name, file_hash
        self.dataset, self.embed_dim = net.dataset, net.embed_dim
        nn.Module.requires_grad_(self, False)
        super().train(False)

    def train(self, mode: bool = True) -> FrozenEvaluator:
        """Always eval mode: dropout off whatever the caller (or Lightning) asks."""
        return super().train(False)

    def requires_grad_(self, requires_grad: bool = True) -> FrozenEvaluator:
        if requires_grad:
            raise RuntimeError(f"{self.name} is a frozen evaluator: its weights never train")
        return self

    @property
    def device(self) -> torch.device:
        return self.net.device

    @torch.no_grad()
    def encode_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """De-normalized motion + (B,) frame counts -> (B, 512) on the evaluator's device.

        InterHuman: (B, 2, T, 262); Inter-X: (B, 2, T, 56, 6); HumanML3D: (B, T, 263), as the
        datamodules' items give them after de-normalization. Rows stay in input order.
        """
        return self.net.encode_motion(motion, lengths).float()

    @torch.no_grad()
    def encode_text(
        self, captions: Sequence[str], tokens: Sequence[str] | None = None
    ) -> torch.Tensor:
        """B captions (+ ``"word/POS ..."`` token strings for the T2M matchers) -> (B, 512)."""
        return self.net.encode_text(captions, tokens).float()

    def extra_repr(self) -> str:
        return f"name={self.name!r}, file_hash={self.file_hash!r}, frozen=True"
