"""Body parameters from joint positions: start from the representation's own rotations, refine.

A generated or dataset motion is a set of joint positions (T, P, 22, 3), Y up, plus, depending
on the dataset, rotations: InterHuman's 262-d feature holds the local rotations of joints 1..21
(the root's is derived: the Kabsch rotation of the pelvis's three children, as the BVH export
does), Inter-X's representation all 55 SMPL-X rotations and the root translation, HumanML3D's
none that fit its positions (they are posed by positional inverse kinematics instead).

Positions alone cannot fix a bone's twist, nor the rotation of a leaf joint (wrists, feet, head:
no child among the 22 joints), so the fit keeps every rotation near its starting value (the
``prior`` term) and lets the joint positions decide everything they can see (``data``), with a
light penalty on the rotations' and the translation's second differences over frames
(``smooth``) and on the shape's distance from the mean body (``shape``):

    data   = mean over persons, frames and joints of |joint - target|^2 / (1 cm)^2
    prior  = mean |R - R_start|_F^2          (8 sin^2(angle / 2): 2 angle^2 for small angles)
    smooth = mean |R[t+1] - 2 R[t] + R[t-1]|_F^2 + mean |x[t+1] - 2 x[t] + x[t-1]|^2 / (1 cm)^2
    shape  = mean betas^2

All persons and frames are one batch (one optimisation, on CPU or GPU). The shape (one per
person) starts from a fit of the bone lengths alone; then L-BFGS refines rotations (6D),
translation and shape together.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

from intermask.body.model import BodyModel
from intermask.motion.interhuman import FEATURE_DIM, split_features
from intermask.motion.interx import BODY_ROWS, NUM_ROWS
from intermask.motion.kinematics import bone_lengths
from intermask.motion.rotations import geodesic_angle, matrix_to_rot6d, rot6d_to_matrix
from intermask.motion.skeleton import NUM_JOINTS
from intermask.render.bvh_export import ZUP_TO_YUP, positional_ik, root_rotation_from_joints

CENTIMETRE = 0.01
INTERX_HANDS = slice(25, 55)  # rows of the 15 left-hand and 15 right-hand rotations


@dataclass(frozen=True)
class FitSettings:
    """Weights of the fit's terms (module docstring) and its iteration counts."""

    iterations: int = 60  # L-BFGS iterations of the joint fit
    shape_iterations: int = 30  # L-BFGS iterations of the bone-length fit of the shape
    prior: float = 1.0
    smooth: float = 0.1
    shape: float = 1e-3
    # CPU threads while fitting: the tensors are small (P T 22 joints), so torch's threaded
    # kernels mostly wait on each other; one thread ran a 2 x 30-frame fit in 0.4 s where two
    # took 27 s on a loaded 2-core machine (docs/bodies.md). None: torch's current setting.
    threads: int | None = 1

    def __post_init__(self) -> None:
        if self.iterations < 0 or self.shape_iterations < 0:
            raise ValueError(
                f"FitSettings: iteration counts must be >= 0, got {self.iterations} and "
                f"{self.shape_iterations}"
            )
        if self.threads is not None and self.threads < 1:
            raise ValueError(f"FitSettings: threads must be >= 1 or None, got {self.threads}")
        for name in ("prior", "smooth", "shape"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"FitSettings: {name} must be >= 0, got {getattr(self, name)}")


class StartPose(NamedTuple):
    """Where the fit starts: rotations (P, T, 22, 3, 3), row 0 the global orientation in the
    Y-up joint frame; hands (P, T, 30, 3, 3) or None (flat); source names where they came from."""

    rotations: torch.Tensor
    hands: torch.Tensor | None
    source: str


class BodyParams(NamedTuple):
    """Fitted bodies: betas (P, B); rotations (P, T, 22, 3, 3) (row 0 global, Y up); hands
    (P, T, 30, 3, 3) or None (flat); transl (P, T, 3) with the posed pelvis at
    ``model.rest_joints(betas)[0] + transl`` (smplx's convention)."""

    betas: torch.Tensor
    rotations: torch.Tensor
    hands: torch.Tensor | None
    transl: torch.Tensor


class FitResult(NamedTuple):
    params: BodyParams
    joints: torch.Tensor  # (P, T, 22, 3) the fitted bodies' joints
    error: torch.Tensor  # (P, T, 22) metres, |fitted - target|
    seconds: float
    start: str  # where the rotations started (StartPose.source)


def representation_of(features: np.ndarray | torch.Tensor) -> str:
    """'interhuman' (P, T, 262), 'interx' (P, T, 56, 6) or 'humanml3d' (P, T, 263)."""
    shape = tuple(features.shape)
    if len(shape) == 3 and shape[-1] == FEATURE_DIM:
        return "interhuman"
    if len(shape) == 4 and shape[-2:] == (NUM_ROWS, 6):
        return "interx"
    if len(shape) == 3 and shape[-1] == 263:
        return "humanml3d"
    raise ValueError(
        f"features of shape {shape}: expected (P, T, {FEATURE_DIM}) InterHuman, (P, T, "
        f"{NUM_ROWS}, 6) Inter-X or (P, T, 263) HumanML3D"
    )


def start_pose(
    joints: torch.Tensor, features: torch.Tensor | None, offsets: torch.Tensor
) -> StartPose:
    """The rotations the fit starts from. joints (P, T, 22, 3) Y up; features (P, T', *F)
    de-normalized (T' >= T frames are read) or None; offsets (P, 22, 3) of the bodies."""
    persons, frames = joints.shape[:2]
    kind = None if features is None else representation_of(features)
    positions = joints.detach().double().cpu().numpy()
    rest = offsets.detach().double().cpu().numpy()
    if kind == "interhuman":
        children = rot6d_to_matrix(split_features(features[:, :frames].double()).rot6d)
        roots = [root_rotation_from_joints(positions[p], rest[p]) for p in range(persons)]
        root = torch.from_numpy(np.stack(roots))[:, :, None]
        return StartPose(torch.cat((root, children.cpu()), dim=2), None, "interhuman rotations")
    if kind == "interx":
        rotations = rot6d_to_matrix(features[:, :frames, : INTERX_HANDS.stop].double()).cpu()
        body = rotations[:, :, BODY_ROWS].clone()
        body[:, :, 0] = torch.from_numpy(ZUP_TO_YUP) @ body[:, :, 0]  # the raw frame is Z up
        return StartPose(body, rotations[:, :, INTERX_HANDS], "inter-x rotations")
    local = [positional_ik(positions[p], rest[p]) for p in range(persons)]
    return StartPose(torch.from_numpy(np.stack(local)), None, "inverse kinematics of the joints")


def _lbfgs(parameters: list[torch.Tensor], closure, iterations: int) -> None:
    if iterations == 0:
        return
    optimizer = torch.optim.LBFGS(
        parameters,
        lr=1.0,
        max_iter=iterations,
        history_size=20,
        tolerance_grad=1e-7,
        tolerance_change=1e-9,  # loss units (cm^2): also keeps the history away from denormals
        line_search_fn="strong_wolfe",
    )

    def step() -> torch.Tensor:
        optimizer.zero_grad()
        loss = closure()
        loss.backward()
        return loss

    optimizer.step(step)


def fit_shape(model: BodyModel, joints: torch.Tensor, *, settings: FitSettings) -> torch.Tensor:
    """(P, T, 22, 3) joints -> (P, B) betas whose bones have the motion's median lengths."""
    target = bone_lengths(joints).median(dim=1).values  # (P, 21)
    betas = torch.zeros(joints.shape[0], model.num_betas, dtype=joints.dtype, device=joints.device)
    betas.requires_grad_(True)

    def loss() -> torch.Tensor:
        offsets = model.body_offsets(betas)[:, 1:]
        lengths = torch.linalg.vector_norm(offsets, dim=-1)
        return (
            (lengths - target) / CENTIMETRE
        ).square().mean() + settings.shape * betas.square().mean()

    _lbfgs([betas], loss, settings.shape_iterations)
    return betas.detach()


def _second_difference(x: torch.Tensor) -> torch.Tensor:
    """(P, T, ...) -> (P, T-2, ...)."""
    return x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2]


@contextmanager
def cpu_threads(count: int | None) -> Iterator[None]:
    """torch's intra-op CPU threads set to count (None: unchanged) for the block."""
    previous = torch.get_num_threads()
    if count is not None:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def fit_bodies(
    model: BodyModel,
    joints: torch.Tensor,
    features: torch.Tensor | None = None,
    *,
    settings: FitSettings | None = None,
) -> FitResult:
    """Fit one body per person to joints (P, T, 22, 3) (metres, Y up), starting from the
    rotations of the de-normalized features (P, T', *F) when given (start_pose).

    Runs where the model's tensors are (model.to(device)); float64 is used on the CPU."""
    settings = settings or FitSettings()
    if joints.ndim != 4 or tuple(joints.shape[-2:]) != (NUM_JOINTS, 3) or joints.shape[1] < 1:
        raise ValueError(f"fit_bodies: joints must be (P, T, 22, 3), got {tuple(joints.shape)}")
    if not bool(torch.isfinite(joints).all()):
        raise ValueError("fit_bodies: joints contain NaN or infinite values")
    with cpu_threads(settings.threads if model.v_template.device.type == "cpu" else None):
        return _fit(model, joints, features, settings)


def _fit(
    model: BodyModel, joints: torch.Tensor, features: torch.Tensor | None, settings: FitSettings
) -> FitResult:
    started = time.perf_counter()
    device, dtype = model.v_template.device, model.v_template.dtype
    target = joints.to(device=device, dtype=dtype)
    betas0 = fit_shape(model, target, settings=settings)
    start = start_pose(target, features, model.body_offsets(betas0))
    rotations0 = start.rotations.to(device=device, dtype=dtype)
    rot6d = (
        matrix_to_rot6d(rotations0)
        .clone(memory_format=torch.contiguous_format)
        .requires_grad_(True)
    )
    transl = (
        (target[:, :, 0] - model.rest_joints(betas0)[:, None, 0])
        .clone(memory_format=torch.contiguous_format)
        .requires_grad_(True)
    )
    betas = betas0.clone(memory_format=torch.contiguous_format).requires_grad_(True)

    def loss() -> torch.Tensor:
        rotations = rot6d_to_matrix(rot6d)
        fitted = model.body_joints(betas, rotations, transl)
        data = ((fitted - target) / CENTIMETRE).square().sum(-1).mean()
        prior = (rotations - rotations0).square().sum((-1, -2)).mean()
        total = data + settings.prior * prior + settings.shape * betas.square().mean()
        if rotations.shape[1] > 2 and settings.smooth > 0:
            smooth = _second_difference(rotations).square().sum((-1, -2)).mean()
            smooth = smooth + (_second_difference(transl) / CENTIMETRE).square().sum(-1).mean()
            total = total + settings.smooth * smooth
        return total

    _lbfgs([rot6d, transl, betas], loss, settings.iterations)
    with torch.no_grad():
        rotations = rot6d_to_matrix(rot6d)
        params = BodyParams(
            betas.detach(),
            rotations,
            None if start.hands is None else start.hands.to(device=device, dtype=dtype),
            transl.detach(),
        )
        fitted = model.body_joints(params.betas, rotations, params.transl)
        error = torch.linalg.vector_norm(fitted - target, dim=-1)
    return FitResult(params, fitted, error, time.perf_counter() - started, start.source)


def pose_error_degrees(fitted: torch.Tensor, reference: torch.Tensor) -> torch.Tensor:
    """Geodesic angle in degrees between two (..., 3, 3) rotation sets -> (...)."""
    return torch.rad2deg(geodesic_angle(fitted, reference))
