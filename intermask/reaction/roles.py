"""Who acts and who reacts: the actor/reactor split of a two-person batch.

ARFlow's datasets (NTU120-AS, Chi3D-AS, InterHuman-AS) annotate the actor of every clip. Ours:
the synthetic datasets write ``interaction_meta.json`` and Inter-X ships
``annots/interaction_order.pkl``; the readers turn either into an item field ``"actor"`` that
names the acting person, 1 or 2, in the item's *output* order (after any person swap). Clips
without the annotation (official InterHuman) have no order: person 1 (index 0) acts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import torch

DEFAULT_ACTOR = 0  # index of the actor when the batch carries no annotation


class Roles(NamedTuple):
    actor: torch.Tensor  # (B, T, *F) the action x0
    reactor: torch.Tensor  # (B, T, *F) the reaction x1
    actor_index: torch.Tensor  # (B,) int64 person index (0 or 1) of the actor in the batch


def actor_index(batch: Mapping[str, Any]) -> torch.Tensor:
    """(B,) int64 person index of the actor: ``batch["actor"] - 1`` when the batch has the
    annotation (1 or 2 per item), else 0 for every item."""
    motion = batch["motion"]
    batch_size = motion.shape[0]
    actor = batch.get("actor")
    if actor is None:
        return torch.full((batch_size,), DEFAULT_ACTOR, dtype=torch.long, device=motion.device)
    actor = torch.as_tensor(actor, device=motion.device).long().reshape(-1)
    if actor.shape[0] != batch_size:
        raise ValueError(f"batch['actor'] has {actor.shape[0]} entries for {batch_size} items")
    bad = ((actor != 1) & (actor != 2)).nonzero().flatten()
    if bad.numel():
        raise ValueError(
            f"batch['actor'] must name person 1 or 2, got {actor[bad].tolist()} at items "
            f"{bad.tolist()}"
        )
    return actor - 1


def split_roles(motion: torch.Tensor, actor: torch.Tensor) -> Roles:
    """(B, 2, T, *F) two-person motion and (B,) actor indices -> :class:`Roles`."""
    if motion.ndim < 4 or motion.shape[1] != 2:
        raise ValueError(f"motion must be (B, 2, T, *F), got {tuple(motion.shape)}")
    rows = torch.arange(motion.shape[0], device=motion.device)
    actor = actor.to(motion.device).long()
    return Roles(motion[rows, actor], motion[rows, 1 - actor], actor)


def place_reaction(
    motion: torch.Tensor, reaction: torch.Tensor, actor: torch.Tensor
) -> torch.Tensor:
    """(B, 2, T, *F) motion with the reactor's slot replaced by (B, T, *F) ``reaction``: the
    generated interaction in the batch's person order."""
    if reaction.shape != motion[:, 0].shape:
        raise ValueError(
            f"reaction must be {tuple(motion[:, 0].shape)} like one person of motion, got "
            f"{tuple(reaction.shape)}"
        )
    out = motion.clone()
    rows = torch.arange(motion.shape[0], device=motion.device)
    out[rows, 1 - actor.to(motion.device).long()] = reaction.to(out.dtype)
    return out
