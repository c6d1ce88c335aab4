"""Muon: orthogonalised momentum for a network's hidden weight matrices, AdamW for the rest.

Muon (K. Jordan et al., 2024) replaces the update of each hidden weight matrix by the
semi-orthogonal matrix nearest to its Nesterov momentum, ``U V^T`` of the momentum's singular
value decomposition, found by a few Newton-Schulz iterations. Every direction of the update then
moves by the same amount, where Adam's element-wise normalisation lets the few dominant
directions of a small batch's gradient take most of the step. The update is scaled to the
root-mean-square size of an AdamW update, ``0.2 * sqrt(max(rows, cols))`` (J. Liu et al., 2025,
"Muon is scalable for LLM training"), so that AdamW's learning rate, warm-up and decay carry over
unchanged.

Embeddings and output layers (whose rows are looked up or scored one by one, not mixed), biases,
norms and every other parameter that is not a 2D matrix take AdamW steps in the same optimizer:
a parameter group's ``muon`` key picks the rule (:func:`muon_groups` builds the two groups).

Measured on the CPU demo's Inter-M (docs/decisions.md: model.optimizer): validation masked
accuracy 0.614 after 600 steps against AdamW's 0.469 (AdamW reaches 0.612 after 1,800).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import torch
from torch import nn
from torch.optim import Optimizer

# The quintic iteration's coefficients (Jordan et al.): it drives every singular value in (0, 1]
# into roughly [0.7, 1.2] in five steps, which is all an update needs; an exact orthogonal
# factor would take many more.
NEWTON_SCHULZ = (3.4445, -4.7750, 2.0315)
RMS_MATCH = 0.2  # an AdamW update's typical RMS (Liu et al. 2025)


def orthogonalize(matrices: torch.Tensor, steps: int = 5, eps: float = 1e-7) -> torch.Tensor:
    """(..., m, n) -> approximately ``U V^T`` of each matrix's SVD, in float32.

    Newton-Schulz on the wide orientation (``X X^T`` is the smaller Gram matrix), after scaling
    each matrix to unit Frobenius norm so that its spectral norm is at most 1.
    """
    if matrices.ndim < 2:
        raise ValueError(f"orthogonalize needs (..., m, n) matrices, got {tuple(matrices.shape)}")
    a, b, c = NEWTON_SCHULZ
    x = matrices.float()
    tall = x.shape[-2] > x.shape[-1]
    if tall:
        x = x.mT
    x = x / (torch.linalg.matrix_norm(x, keepdim=True) + eps)
    for _ in range(steps):
        gram = x @ x.mT
        x = a * x + (b * gram + c * gram @ gram) @ x
    return x.mT if tall else x


class Muon(Optimizer):
    """Muon for the parameter groups with ``muon=True``, AdamW for the others.

    Args:
        params: parameter groups (dicts with ``params`` and optionally ``muon``, default
            False) or parameters, which then all take AdamW steps.
        lr: base learning rate of both rules (the RMS matching lets them share it).
        momentum: Muon's Nesterov momentum.
        betas, eps: AdamW's (the AdamW groups step as ``torch.optim.AdamW`` does).
        weight_decay: decoupled weight decay of both rules.
        ns_steps: Newton-Schulz iterations per update.
    """

    def __init__(
        self,
        params: Iterable[Any],
        *,
        lr: float,
        momentum: float = 0.95,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
        weight_decay: float = 0.0,
        ns_steps: int = 5,
    ) -> None:
        if lr < 0 or not 0.0 <= momentum < 1.0 or ns_steps < 1:
            raise ValueError(
                f"Muon needs lr >= 0, momentum in [0, 1) and ns_steps >= 1, got lr={lr}, "
                f"momentum={momentum}, ns_steps={ns_steps}"
            )
        defaults = {
            "lr": lr,
            "momentum": momentum,
            "betas": tuple(betas),
            "eps": eps,
            "weight_decay": weight_decay,
            "ns_steps": ns_steps,
            "muon": False,
        }
        super().__init__(params, defaults)
        for group in self.param_groups:
            shapes = [tuple(p.shape) for p in group["params"] if p.ndim < 2]
            if group["muon"] and shapes:
                raise ValueError(
                    "a muon=True parameter group takes weight matrices (2D, or convolution "
                    f"kernels read as out x fan-in), got shapes {shapes}"
                )

    @torch.no_grad()
    def step(self, closure: Callable[[], torch.Tensor] | None = None) -> torch.Tensor | None:
        loss = None
        if closure is not None:
            with torch.enable_grad():
                loss = closure()
        for group in self.param_groups:
            if group["muon"]:
                self._muon_step(group)
            else:
                self._adamw_step(group)
        return loss

    def _muon_step(self, group: dict[str, Any]) -> None:
        """Nesterov momentum, then one batched orthogonalisation per matrix shape (a
        convolution kernel (out, in, *k) as the (out, in x prod(k)) matrix it applies)."""
        lr, momentum = group["lr"], group["momentum"]
        by_shape: dict[tuple[int, ...], list[tuple[torch.Tensor, torch.Tensor]]] = {}
        for p in group["params"]:
            if p.grad is None:
                continue
            buffer = self.state[p].setdefault("momentum_buffer", torch.zeros_like(p))
            buffer.lerp_(p.grad, 1 - momentum)
            by_shape.setdefault(tuple(p.shape), []).append((p, p.grad.lerp(buffer, momentum)))
        for shape, items in by_shape.items():
            matrices = torch.stack([u.reshape(shape[0], -1) for _, u in items])
            updates = orthogonalize(matrices, group["ns_steps"])
            scale = RMS_MATCH * max(matrices.shape[-2:]) ** 0.5
            for (p, _), update in zip(items, updates, strict=True):
                p.mul_(1 - lr * group["weight_decay"])
                p.add_(update.reshape(shape).to(p.dtype), alpha=-lr * scale)

    def _adamw_step(self, group: dict[str, Any]) -> None:
        """``torch.optim.AdamW``'s update (single-tensor form, no amsgrad)."""
        lr, (beta1, beta2), eps = group["lr"], group["betas"], group["eps"]
        for p in group["params"]:
            if p.grad is None:
                continue
            state = self.state[p]
            if not state:
                state["step"] = 0
                state["exp_avg"] = torch.zeros_like(p)
                state["exp_avg_sq"] = torch.zeros_like(p)
            state["step"] += 1
            p.mul_(1 - lr * group["weight_decay"])
            exp_avg, exp_avg_sq = state["exp_avg"], state["exp_avg_sq"]
            exp_avg.lerp_(p.grad, 1 - beta1)
            exp_avg_sq.mul_(beta2).addcmul_(p.grad, p.grad, value=1 - beta2)
            denom = (exp_avg_sq / (1 - beta2 ** state["step"])).sqrt_().add_(eps)
            p.addcdiv_(exp_avg, denom, value=-lr / (1 - beta1 ** state["step"]))


def builds_muon(factory: Callable[..., Optimizer]) -> bool:
    """Whether an optimizer factory (a class, or a ``functools.partial`` of one as Hydra's
    ``_partial_`` builds) makes a :class:`Muon`."""
    target = getattr(factory, "func", factory)
    return isinstance(target, type) and issubclass(target, Muon)


def muon_groups(
    parameters: Iterable[nn.Parameter], *, adamw: Iterable[nn.Parameter] = ()
) -> list[dict[str, Any]]:
    """The two :class:`Muon` groups of ``parameters``: the weight matrices and convolution
    kernels not named in ``adamw`` (``muon=True``), and the rest (``muon=False``). Parameters
    without gradients are left out."""
    kept = {id(p) for p in adamw}
    matrices, others = [], []
    for p in parameters:
        if p.requires_grad:
            (matrices if p.ndim >= 2 and id(p) not in kept else others).append(p)
    return [{"params": matrices, "muon": True}, {"params": others, "muon": False}]
