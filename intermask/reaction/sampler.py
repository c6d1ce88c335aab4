"""Batched reaction generation: the action of a batch -> the reaction, features and joints.

One entry point, :func:`sample_reactions`, shared by validation, the evaluation protocol and
scripts, so that they can never sample differently. The ODE starts at the action itself and is
deterministic; seeds matter only for stochastic sampling (beta > 0), one generator per sample,
so a sample does not depend on its batch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import torch
from einops import rearrange

from intermask.motion.masks import length_mask
from intermask.reaction.flow import STEPS, check_sigma_min, euler_step, time_grid
from intermask.reaction.guidance import (
    Guidance,
    network_penetration_gradient,
    penetration_gradient,
    reprojection_step,
    vanilla_step,
)
from intermask.reaction.network import ReactionDecoder
from intermask.reaction.representation import FeatureSpace
from intermask.reaction.roles import actor_index, place_reaction, split_roles
from intermask.text.cache import TextFeatureCache


class ReactionParts(NamedTuple):
    """What sampling needs; ``ARFlowModule.reaction_parts()`` returns them."""

    net: ReactionDecoder
    space: FeatureSpace
    text: TextFeatureCache | None
    sigma_min: float


class ReactionSample(NamedTuple):
    features: torch.Tensor  # (B, T, *F) de-normalized reaction; zeros beyond each length
    joints: torch.Tensor  # (B, T, 2, 22, 3) metres, Y-up, batch person order; zeros beyond length


def pooled_text(
    text: TextFeatureCache, captions: Sequence[str], device: torch.device
) -> torch.Tensor:
    """Captions -> (B, text_dim) frozen features at the end-of-text token (CLIP's pooling)."""
    features = text.get_or_encode(list(captions))
    rows = torch.arange(features.features.shape[0], device=features.features.device)
    pooled = features.features[rows, features.eot_index.to(features.features.device)]
    return pooled.to(device=device, dtype=torch.float32)


def frame_mask_from_lengths(lengths: torch.Tensor, frames: int) -> torch.Tensor:
    """(B,) lengths -> (B, T) bool, True on valid frames; lengths must lie in [1, T]."""
    lengths = lengths.long()
    if lengths.ndim != 1 or bool((lengths < 1).any()) or bool((lengths > frames).any()):
        raise ValueError(f"lengths must be (B,) frames in [1, {frames}], got {lengths.tolist()}")
    return length_mask(lengths, frames)


def _noise(seeds: Sequence[int], step: int, shape: tuple[int, ...], device) -> torch.Tensor:
    """(B, *shape) standard normal noise; sample b uses generator (seeds[b], step) only."""
    draws = []
    for seed in seeds:
        generator = torch.Generator().manual_seed(int(seed) * 1_000_003 + step)
        draws.append(torch.randn(shape, generator=generator))
    return torch.stack(draws).to(device)


@torch.no_grad()
def generate_reaction(
    parts: ReactionParts,
    actor: torch.Tensor,
    frame_mask: torch.Tensor,
    *,
    text: torch.Tensor | None = None,
    steps: int = STEPS,
    guidance: Guidance | None = None,
    seeds: Sequence[int] | None = None,
    cfg_scale: float = 1.0,
) -> torch.Tensor:
    """(B, T, D) normalized action, (B, T) valid frames -> (B, T, D) normalized reaction.

    text: (B, text_dim) pooled features or None (null condition). ``cfg_scale`` != 1 mixes the
    conditional and the null prediction (classifier-free guidance) in one batched call.
    The network runs exactly ``steps`` times. Guidance differentiates the decoded joints, and
    in ``vanilla`` mode (Algorithm 1) the network too, with respect to the state only.
    """
    net, space, sigma_min = parts.net, parts.space, parts.sigma_min
    check_sigma_min(sigma_min)
    guidance = guidance or Guidance.off()
    seeds = list(range(actor.shape[0])) if seeds is None else [int(s) for s in seeds]
    if len(seeds) != actor.shape[0]:
        raise ValueError(f"got {len(seeds)} seeds for {actor.shape[0]} samples")
    guided = guidance.mode != "none" and guidance.lambda_pene > 0
    actor_joints = space.joints(actor) if guided else None
    times = time_grid(steps, device=actor.device)
    x = actor.clone()
    for n in range(steps):
        gradient = None
        loss = {"zeta": guidance.zeta, "points_per_bone": guidance.points_per_bone}
        if guided and guidance.through_network:  # Algorithm 1: d loss(f(x_t)) / d x_t
            x1_hat, gradient = network_penetration_gradient(
                lambda state, t=times[n]: _predict(
                    net, state, t, actor, frame_mask, text, cfg_scale
                ),
                x,
                actor_joints,
                space,
                frame_mask=frame_mask,
                **loss,
            )
        else:
            x1_hat = _predict(net, x, times[n], actor, frame_mask, text, cfg_scale)
            if guided:  # the gradient at the clean prediction
                gradient = penetration_gradient(
                    x1_hat, actor_joints, space, frame_mask=frame_mask, **loss
                )
        noise = None
        if guidance.beta > 0:
            noise = _noise(seeds, n, tuple(x.shape[1:]), x.device).to(x.dtype)
        x = _advance(x, x1_hat, actor, times[n], times[n + 1], gradient, noise, guidance, sigma_min)
    return torch.where(frame_mask[..., None], x, torch.zeros_like(x))


def _advance(x, x1_hat, actor, t, t_next, gradient, noise, guidance, sigma_min) -> torch.Tensor:
    """One sampling step: Algorithm 1's update (vanilla, clean_gradient), reprojection
    (Algorithm 2 and / or eqs. 16-17), or the plain Euler step (eq. 9)."""
    if guidance.euler_then_gradient and gradient is not None:
        return vanilla_step(
            x, x1_hat, gradient, t, t_next, lambda_pene=guidance.lambda_pene, sigma_min=sigma_min
        )
    if guidance.mode == "improved" or guidance.beta > 0:
        return reprojection_step(
            x,
            x1_hat,
            actor,
            t,
            t_next,
            gradient=gradient,
            lambda_pene=guidance.lambda_pene,
            w=guidance.w if guidance.mode == "improved" else 1.0,
            beta=guidance.beta,
            noise=noise,
            sigma_min=sigma_min,
        )
    return euler_step(x, x1_hat, t, t_next, sigma_min=sigma_min)


def _predict(net, x, t, actor, frame_mask, text, cfg_scale) -> torch.Tensor:
    batch = x.shape[0]
    times = t.expand(batch)
    if text is None or cfg_scale == 1.0:
        return net(x, times, actor, frame_mask, text)
    drop = torch.cat((torch.zeros(batch, dtype=torch.bool), torch.ones(batch, dtype=torch.bool)))
    both = net(
        x.repeat(2, 1, 1),
        times.repeat(2),
        actor.repeat(2, 1, 1),
        frame_mask.repeat(2, 1),
        text.repeat(2, 1),
        drop.to(x.device),
    )
    conditional, unconditional = both[:batch], both[batch:]
    return unconditional + cfg_scale * (conditional - unconditional)


def _parts(source: Any) -> ReactionParts:
    if isinstance(source, ReactionParts):
        return source
    if hasattr(source, "reaction_parts"):
        return source.reaction_parts()
    raise TypeError(f"expected an ARFlowModule or ReactionParts, got {type(source).__name__}")


def sample_reactions(
    source: Any,
    batch: Mapping[str, Any],
    *,
    steps: int = STEPS,
    guidance: Guidance | None = None,
    seeds: Sequence[int] | torch.Tensor | None = None,
    cfg_scale: float = 1.0,
) -> ReactionSample:
    """Generate the reactor of every interaction in a DataModule batch.

    source: an ARFlowModule or :class:`ReactionParts`.
    batch: "motion" (B, 2, T, *F) normalized, "length" (B,), optional "caption" (B texts; the
        null condition without them) and "actor" (1 or 2; person 1 acts without it).
    guidance: None = plain Euler sampling; e.g. ``Guidance()`` = the paper's improved guidance.
    seeds: (B,) per-sample seeds (stochastic sampling only); default 0..B-1.
    Returns de-normalized reaction features and both persons' joints (the actor from the batch).
    """
    parts = _parts(source)
    device = next(parts.net.parameters()).device
    motion = batch["motion"].to(device).float()
    actor_idx = actor_index({**batch, "motion": motion})
    roles = split_roles(motion, actor_idx)
    space = parts.space
    actor = space.flatten(roles.actor)
    frame_mask = frame_mask_from_lengths(
        torch.as_tensor(batch["length"], device=device), actor.shape[1]
    )
    text = None
    if parts.text is not None and batch.get("caption") is not None:
        text = pooled_text(parts.text, batch["caption"], device)
    if isinstance(seeds, torch.Tensor):
        seeds = seeds.tolist()
    reaction = generate_reaction(
        parts,
        actor,
        frame_mask,
        text=text,
        steps=steps,
        guidance=guidance,
        seeds=seeds,
        cfg_scale=cfg_scale,
    )
    flat_motion = space.flatten(motion)  # (B, 2, T, D)
    pair = place_reaction(flat_motion, reaction, actor_idx)
    with torch.no_grad():
        joints = rearrange(space.joints(pair), "b p t j c -> b t p j c")
        features = space.denormalize(reaction)
    valid = frame_mask.reshape(*frame_mask.shape, *([1] * (features.ndim - 2)))
    features = torch.where(valid, features, torch.zeros_like(features))
    joints = torch.where(frame_mask[:, :, None, None, None], joints, torch.zeros_like(joints))
    return ReactionSample(features, joints)
