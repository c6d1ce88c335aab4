"""Tiny ARFlow pieces shared by the reaction tests (a uniquely named module: `conftest` names clash across test folders)."""

from __future__ import annotations

import torch
from torch import nn

from intermask.reaction.network import ReactionDecoder
from intermask.reaction.representation import FeatureSpace
from intermask.reaction.sampler import ReactionParts

TINY = {"width": 32, "depth": 2, "heads": 4, "ff": 48, "dropout": 0.0}


def make_net(*, causal: bool, feature_dim: int = 262, text_dim: int | None = None, seed: int = 0):
    torch.manual_seed(seed)
    return ReactionDecoder(feature_dim=feature_dim, causal=causal, text_dim=text_dim, **TINY).eval()


class Oracle(nn.Module):
    """A 'network' that predicts a fixed x1 and counts its calls (and the gradients it sees)."""

    def __init__(self, x1: torch.Tensor) -> None:
        super().__init__()
        self.x1 = x1
        self.scale = nn.Parameter(torch.ones(()))
        self.calls = 0
        self.feature_dim = x1.shape[-1]
        self.text_dim = None

    def forward(self, x_t, t, actor, frame_mask, text=None, drop=None):
        self.calls += 1
        return self.scale * self.x1


def parts(net: nn.Module, *, sigma_min: float = 1e-4) -> ReactionParts:
    return ReactionParts(net, FeatureSpace(representation="interhuman"), None, sigma_min)


def standing_pair(batch: int = 2, frames: int = 6, gap: float = 2.0) -> torch.Tensor:
    """(B, 2, T, 262) normalized features (identity statistics) of two rest-pose persons
    ``gap`` metres apart along +Z, facing each other; only the positions are set."""
    from intermask.motion.skeleton import rest_pose_positions

    rest = rest_pose_positions()  # (22, 3)
    rest = rest - rest[0]
    rest[:, 1] += 1.0
    motion = torch.zeros(batch, 2, frames, 262)
    motion[:, 0, :, :66] = rest.reshape(-1)
    turned = rest * torch.tensor([-1.0, 1.0, -1.0]) + torch.tensor([0.0, 0.0, gap])
    motion[:, 1, :, :66] = turned.reshape(-1)
    return motion
