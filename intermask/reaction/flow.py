"""Action-to-reaction flow matching with x1-prediction (ARFlow section 3.1, appendix A).

The path from the action x0 to the reaction x1 (eq. 4):
    x_t = t x1 + (1 - (1 - sigma_min) t) x0,
so x_0 = x0 and x_1 = x1 + sigma_min x0. The network predicts x1_hat = G(x_t, t, c) (eq. 5).
Sampling integrates the ODE with Euler steps over 0 = t_0 < ... < t_N = 1 written with x1_hat
(eq. 9):
    x_{n+1} = c(t_{n+1}) / c(t_n) x_n + (t_{n+1} - t_n) / c(t_n) x1_hat,  c(t) = 1 - (1-s) t,
which equals re-interpolating between x1_hat and x0_hat = (x_n - t_n x1_hat) / c(t_n) (eqs. 12-13).

``steps`` = N is the number of network evaluations (N + 1 grid points). The paper's latency
(Table 4: 0.055 / 0.111 / 0.232 / 2.273 ms for 2 / 5 / 10 / 100 steps) grows like N, not N - 1.
All tensors are (B, T, D); times are (B,) or scalars.
"""

from __future__ import annotations

import torch

# sigma_min is not given by the paper ("a small amount of noise"); 1e-4 is our choice. It keeps
# c(t) > 0 at t = 1 and moves the path's end by sigma_min x0 only.
SIGMA_MIN = 1e-4
STEPS = 5  # Euler steps (paper section 4.4: 5 steps are best, as in ReGenNet)


def check_sigma_min(sigma_min: float) -> None:
    """sigma_min must lie in (0, 1): c(1) = sigma_min > 0 keeps recover_x0 finite."""
    if not 0.0 < sigma_min < 1.0:
        raise ValueError(f"sigma_min must lie in (0, 1), got {sigma_min}")


def _times(t: torch.Tensor | float, like: torch.Tensor) -> torch.Tensor:
    """Scalar or (B,) times -> broadcastable (B, 1, 1) (or scalar) tensor on like's device."""
    t = torch.as_tensor(t, dtype=like.dtype, device=like.device)
    if t.ndim == 0:
        return t
    if t.ndim != 1 or t.shape[0] != like.shape[0]:
        raise ValueError(f"t must be a scalar or ({like.shape[0]},), got {tuple(t.shape)}")
    return t.reshape(-1, *([1] * (like.ndim - 1)))


def path_scale(t: torch.Tensor | float, sigma_min: float = SIGMA_MIN) -> torch.Tensor | float:
    """c(t) = 1 - (1 - sigma_min) t, the weight of x0 on the path."""
    return 1.0 - (1.0 - sigma_min) * t


def interpolate(
    x0: torch.Tensor, x1: torch.Tensor, t: torch.Tensor | float, *, sigma_min: float = SIGMA_MIN
) -> torch.Tensor:
    """x_t = t x1 + c(t) x0 (eq. 4)."""
    if x0.shape != x1.shape:
        raise ValueError(
            f"x0 and x1 must have one shape, got {tuple(x0.shape)} and {tuple(x1.shape)}"
        )
    t = _times(t, x0)
    return t * x1 + path_scale(t, sigma_min) * x0


def recover_x0(
    x_t: torch.Tensor,
    x1_hat: torch.Tensor,
    t: torch.Tensor | float,
    *,
    sigma_min: float = SIGMA_MIN,
) -> torch.Tensor:
    """x0_hat = (x_t - t x1_hat) / c(t): the start point the current prediction implies (eq. 12)."""
    t = _times(t, x_t)
    return (x_t - t * x1_hat) / path_scale(t, sigma_min)


def velocity(
    x_t: torch.Tensor,
    x1_hat: torch.Tensor,
    t: torch.Tensor | float,
    *,
    sigma_min: float = SIGMA_MIN,
) -> torch.Tensor:
    """v = (x1_hat - (1 - sigma_min) x_t) / c(t), the vector field of an x1-prediction (eq. 7)."""
    t = _times(t, x_t)
    return (x1_hat - (1.0 - sigma_min) * x_t) / path_scale(t, sigma_min)


def euler_step(
    x_t: torch.Tensor,
    x1_hat: torch.Tensor,
    t: torch.Tensor | float,
    t_next: torch.Tensor | float,
    *,
    sigma_min: float = SIGMA_MIN,
) -> torch.Tensor:
    """x_{t_next} = c(t_next) / c(t) x_t + (t_next - t) / c(t) x1_hat (eq. 9)."""
    t, t_next = _times(t, x_t), _times(t_next, x_t)
    scale = path_scale(t, sigma_min)
    return path_scale(t_next, sigma_min) / scale * x_t + (t_next - t) / scale * x1_hat


def time_grid(steps: int, *, device: torch.device | str = "cpu") -> torch.Tensor:
    """(steps + 1,) uniform times 0 = t_0 < ... < t_steps = 1."""
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    return torch.linspace(0.0, 1.0, steps + 1, device=device)
