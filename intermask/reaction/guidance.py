"""Physical guidance of ARFlow's sampling (section 3.2, Algorithms 1-2, eqs. 10-17).

The penetration loss (eq. 10) scores the reactor decoded from the clean prediction x1_hat
against the actor's capsule body (``intermask.physics.penetration_loss``). Where its gradient is
taken is what separates the modes:

* vanilla (Algorithm 1, the paper's baseline): with respect to the current state x_t, through
  the network (x1_hat = f(x_t)); an Euler step with x1_hat, then x_{n+1} -= lambda_pene grad.
  The paper's point is that this gradient is inaccurate (the network's Jacobian distorts it)
  and costs a backward pass per step (:func:`network_penetration_gradient`).
* clean_gradient: the same update with the gradient taken at x1_hat itself, without the network
  (:func:`penetration_gradient`); this project's earlier reading of Algorithm 1, kept as a named
  variant (docs/fidelity.md).
* improved (Algorithm 2): x1' = x1_hat - lambda_pene grad; x0_hat from (x_n, x1_hat) (eq. 12)
  is pulled towards the true action, x0* = w x0_hat + (1 - w) x0 (eq. 14), and the state is
  re-interpolated, x_{n+1} = t_{n+1} x1' + c(t_{n+1}) x0* (eq. 13).
* stochastic sampling (eqs. 15-17): the projection direction d = x0* - x1' is mixed with a
  random direction, d_mix = d + beta (d_random - d), and x_{n+1} = x1' + (1 - t_{n+1}) d_mix +
  sigma_min t_{n+1} x0*. It works with mode "none" (lambda 0, w 1) and "improved".
All tensors are (B, T, D) in the flow's (normalized) space.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import torch

from intermask.physics import DEFAULT_ZETA, BodyProxy, bone_point_weights, penetration_loss
from intermask.reaction.flow import SIGMA_MIN, _times, euler_step, recover_x0
from intermask.reaction.representation import FeatureSpace

GuidanceMode = Literal["none", "vanilla", "clean_gradient", "improved"]
GUIDANCE_MODES = ("none", "vanilla", "clean_gradient", "improved")
# the reaction table's row names of the guided modes (docs/fidelity.md)
GUIDANCE_LABELS = {
    "vanilla": "vanilla guidance (Alg. 1)",
    "clean_gradient": "clean-gradient guidance",
    "improved": "guidance",
}
# Appendix F: safe distance zeta = 0.5, lambda_pene = 2, w = 0.7.
LAMBDA_PENE = 2.0
WEIGHT_W = 0.7


@dataclass(frozen=True)
class Guidance:
    """Sampling-time guidance settings (defaults: the paper's, appendix F).

    mode: "none", "vanilla" (Algorithm 1: gradient through the network), "clean_gradient"
        (Algorithm 1's update, gradient at x1_hat) or "improved" (Algorithm 2).
    lambda_pene: guidance strength; zeta: safe distance in metres (eq. 10).
    w: weight of the predicted x0_hat against the true action (eq. 14, improved only).
    beta: stochastic sampling strength (eq. 16); 0 = deterministic. Appendix C tries 0.01-0.05.
    points_per_bone: reactor points per bone scored besides the joints (penetration proxy).
    """

    mode: GuidanceMode = "improved"
    lambda_pene: float = LAMBDA_PENE
    zeta: float = DEFAULT_ZETA
    w: float = WEIGHT_W
    beta: float = 0.0
    points_per_bone: int = 2

    def __post_init__(self) -> None:
        if self.mode not in GUIDANCE_MODES:
            raise ValueError(
                f"guidance mode must be one of {', '.join(map(repr, GUIDANCE_MODES))}, "
                f"got {self.mode!r}"
            )
        if self.lambda_pene < 0 or self.zeta < 0:
            raise ValueError(
                f"lambda_pene and zeta must be >= 0, got {self.lambda_pene} and {self.zeta}"
            )
        if not 0.0 <= self.w <= 1.0 or not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"w and beta must lie in [0, 1], got {self.w} and {self.beta}")
        if self.mode in ("vanilla", "clean_gradient") and self.beta > 0:
            raise ValueError(
                "stochastic sampling (beta > 0) lives in the reprojection form: use mode "
                f"'improved' or 'none', not {self.mode!r}"
            )

    @property
    def through_network(self) -> bool:
        """True when the gradient is taken with respect to x_t through the network (vanilla)."""
        return self.mode == "vanilla"

    @property
    def euler_then_gradient(self) -> bool:
        """True for Algorithm 1's update: an Euler step, then minus lambda_pene times the gradient."""
        return self.mode in ("vanilla", "clean_gradient")

    @classmethod
    def off(cls, *, beta: float = 0.0) -> Guidance:
        """Plain x1-prediction Euler sampling (eq. 9); ``beta`` > 0 adds stochastic sampling."""
        return cls(mode="none", beta=beta)


def penetration_gradient(
    x1_hat: torch.Tensor,
    actor_joints: torch.Tensor,
    space: FeatureSpace,
    *,
    frame_mask: torch.Tensor,
    zeta: float = DEFAULT_ZETA,
    proxy: BodyProxy | None = None,
    points_per_bone: int = 2,
) -> torch.Tensor:
    """Guidance direction (B, T, D) in the flow's space for the clean prediction x1_hat.

    The reactor decoded from x1_hat is scored against ``actor_joints`` (B, T, 22, 3), padding
    excluded: L = sum over frames of the mean over the reactor's sample points of
    relu(zeta - SDF_actor). Eq. 10 sums over the points too; averaging them keeps a unit
    lambda_pene step at centimetres (our proxy scores 64 points per frame), and summing the
    frames keeps a frame's step independent of the clip length and the batch.
    The gradient is taken in the dataset's units (de-normalized features: metres, 6D), as the
    paper guides un-normalized SMPL-X parameters, and returned mapped into the normalized
    space, so ``x1_hat - lambda_pene * direction`` is a plain gradient step in those units.
    Only the features are a leaf: nothing reaches the network or the actor. Works inside
    ``torch.no_grad`` and ``torch.inference_mode`` (Lightning's validation) too.
    """
    with torch.inference_mode(False), torch.enable_grad():
        features = space.denormalize(x1_hat.detach().clone().float()).requires_grad_(True)
        loss = _guidance_loss(
            features, actor_joints, space, frame_mask, zeta, proxy, points_per_bone
        )
        (gradient,) = torch.autograd.grad(loss, features)
    return space.flatten(gradient / space.std).to(x1_hat.dtype)


def _guidance_loss(
    features: torch.Tensor,
    actor_joints: torch.Tensor,
    space: FeatureSpace,
    frame_mask: torch.Tensor,
    zeta: float,
    proxy: BodyProxy | None,
    points_per_bone: int,
) -> torch.Tensor:
    """The guidance loss of both modes on de-normalized reactor ``features``: the penetration
    summed over frames, averaged over the reactor's sample points."""
    points = len(bone_point_weights(points_per_bone))
    loss = penetration_loss(
        space.feature_joints(features),
        actor_joints.detach().clone().float(),
        zeta=zeta,
        proxy=proxy,
        points_per_bone=points_per_bone,
        frame_mask=frame_mask.clone(),
        reduction="sum",
    )
    return loss / points


def network_penetration_gradient(
    predict: Callable[[torch.Tensor], torch.Tensor],
    x_t: torch.Tensor,
    actor_joints: torch.Tensor,
    space: FeatureSpace,
    *,
    frame_mask: torch.Tensor,
    zeta: float = DEFAULT_ZETA,
    proxy: BodyProxy | None = None,
    points_per_bone: int = 2,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Algorithm 1's gradient: (x1_hat, direction), both (B, T, D) in the flow's space.

    ``predict`` maps the state x_t to the clean prediction (the network, with its condition and
    guidance scale). The loss is :func:`penetration_gradient`'s (the same sum over frames of the
    mean over sample points), differentiated with respect to x_t through ``predict``. Like
    :func:`penetration_gradient`, the step is a plain gradient step in dataset units, here of
    the state: d L / d x_t divided by std squared (x_t = (f_t - mean) / std). With an identity
    ``predict`` the two directions are equal. Only x_t is a leaf: the network's parameters get
    no ``.grad``.
    """
    with torch.inference_mode(False), torch.enable_grad():
        state = x_t.detach().clone().requires_grad_(True)
        x1_hat = predict(state)
        loss = _guidance_loss(
            space.denormalize(x1_hat.float()),
            actor_joints,
            space,
            frame_mask,
            zeta,
            proxy,
            points_per_bone,
        )
        (gradient,) = torch.autograd.grad(loss, state)
    direction = space.flatten(space.unflatten(gradient) / space.std**2)
    return x1_hat.detach(), direction.to(x_t.dtype)


def random_direction(direction: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
    """Gaussian ``noise`` rescaled to the norm of ``direction`` (B, T, D) frame by frame. The
    paper does not state the scale of d_random; matching the norm keeps beta a pure mixing
    weight, and doing it per frame keeps the online variant causal."""
    norm = direction.norm(dim=-1, keepdim=True)
    return noise * norm / noise.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def vanilla_step(
    x_t: torch.Tensor,
    x1_hat: torch.Tensor,
    gradient: torch.Tensor,
    t: torch.Tensor | float,
    t_next: torch.Tensor | float,
    *,
    lambda_pene: float,
    sigma_min: float = SIGMA_MIN,
) -> torch.Tensor:
    """Algorithm 1's update: Euler step (eq. 9), then x_{n+1} -= lambda_pene * gradient."""
    return euler_step(x_t, x1_hat, t, t_next, sigma_min=sigma_min) - lambda_pene * gradient


def reprojection_step(
    x_t: torch.Tensor,
    x1_hat: torch.Tensor,
    x0: torch.Tensor,
    t: torch.Tensor | float,
    t_next: torch.Tensor | float,
    *,
    gradient: torch.Tensor | None = None,
    lambda_pene: float = 0.0,
    w: float = 1.0,
    beta: float = 0.0,
    noise: torch.Tensor | None = None,
    sigma_min: float = SIGMA_MIN,
) -> torch.Tensor:
    """Algorithm 2 with eqs. 16-17. With no gradient, w = 1 and beta = 0 it is the Euler step."""
    x0_hat = recover_x0(x_t, x1_hat, t, sigma_min=sigma_min)  # eq. 12
    x1_guided = x1_hat if gradient is None else x1_hat - lambda_pene * gradient  # eq. 11
    x0_star = w * x0_hat + (1.0 - w) * x0  # eq. 14
    direction = x0_star - x1_guided
    if beta > 0.0:
        if noise is None:
            raise ValueError("stochastic sampling (beta > 0) needs noise")
        direction = direction + beta * (random_direction(direction, noise) - direction)  # eq. 16
    t_next = _times(t_next, x_t)
    # eq. 17; with beta = 0 equal to t' x1' + c(t') x0* (eq. 13)
    return x1_guided + (1.0 - t_next) * direction + sigma_min * t_next * x0_star
