"""A capsule body proxy of the 22-joint skeleton and its signed distance.

The papers measure penetration on SMPL-X meshes, which are licence-gated; this proxy sweeps a
sphere along segments placed on the joints instead (docs/penetration.md), so its
numbers compare only with each other. K = 28 capsules: the 21 bones, spans across the hips and
shoulders, the two flanks (hip to shoulder), the hands (an extension of each forearm past the
wrist) and a head sphere (a capsule of zero length).

Every capsule endpoint is a fixed linear combination of the joints, so the whole proxy is two
(K, 22) matrices and one einsum: no loop over capsules, and gradients reach the joints.

Frame convention: any. Distances do not depend on the up axis or on any rotation, so Y-up joints
(the 262-d features, ``intermask.motion.to_joint_positions``, the synthetic generator) and Z-up
raw InterHuman joints both work as they are; the height used for optional radius scaling is
measured along bones, not along an axis.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import torch

from intermask.motion.skeleton import JOINT_NAMES, NUM_JOINTS, rest_pose_positions

_J = {name: index for index, name in enumerate(JOINT_NAMES)}

# (capsule name, radius part, start joint, end joint). An end written "joint+" is extended past
# that joint: end = joint + extension * (joint - reference), see _EXTENSIONS.
_LAYOUT: tuple[tuple[str, str, str, str], ...] = (
    ("pelvis_l", "pelvis", "pelvis", "l_hip"),
    ("pelvis_r", "pelvis", "pelvis", "r_hip"),
    ("hips", "hips", "l_hip", "r_hip"),
    ("abdomen_low", "abdomen", "pelvis", "spine1"),
    ("abdomen_high", "abdomen", "spine1", "spine2"),
    ("chest_low", "chest", "spine2", "spine3"),
    ("chest_high", "chest", "spine3", "neck"),
    ("collar_l", "collar", "spine3", "l_collar"),
    ("collar_r", "collar", "spine3", "r_collar"),
    ("shoulders", "shoulders", "l_shoulder", "r_shoulder"),
    ("flank_l", "flank", "l_hip", "l_shoulder"),
    ("flank_r", "flank", "r_hip", "r_shoulder"),
    ("neck", "neck", "neck", "head"),
    ("head", "head", "head+", "head+"),
    ("shoulder_l", "shoulder", "l_collar", "l_shoulder"),
    ("shoulder_r", "shoulder", "r_collar", "r_shoulder"),
    ("upper_arm_l", "upper_arm", "l_shoulder", "l_elbow"),
    ("upper_arm_r", "upper_arm", "r_shoulder", "r_elbow"),
    ("forearm_l", "forearm", "l_elbow", "l_wrist"),
    ("forearm_r", "forearm", "r_elbow", "r_wrist"),
    ("hand_l", "hand", "l_wrist", "l_wrist+"),
    ("hand_r", "hand", "r_wrist", "r_wrist+"),
    ("thigh_l", "thigh", "l_hip", "l_knee"),
    ("thigh_r", "thigh", "r_hip", "r_knee"),
    ("shin_l", "shin", "l_knee", "l_ankle"),
    ("shin_r", "shin", "r_knee", "r_ankle"),
    ("foot_l", "foot", "l_ankle", "l_foot"),
    ("foot_r", "foot", "r_ankle", "r_foot"),
)
CAPSULE_NAMES: tuple[str, ...] = tuple(row[0] for row in _LAYOUT)
PARTS: tuple[str, ...] = tuple(dict.fromkeys(row[1] for row in _LAYOUT))
NUM_CAPSULES = len(_LAYOUT)
# Extended joint -> (reference joint, name of the BodyProxy field giving the extension fraction).
_EXTENSIONS = {
    "head": ("neck", "head_offset"),
    "l_wrist": ("l_elbow", "hand_extension"),
    "r_wrist": ("r_elbow", "hand_extension"),
}

# Radii in metres for the SMPL template body (skeleton.REST_OFFSETS, ~1.7 m tall): rough
# anthropometric half-thicknesses of each segment. configs/physics/capsules.yaml repeats them.
DEFAULT_RADII: dict[str, float] = {
    "pelvis": 0.10,
    "hips": 0.10,
    "abdomen": 0.12,
    "chest": 0.12,
    "collar": 0.07,
    "shoulders": 0.06,
    "flank": 0.06,
    "neck": 0.05,
    "head": 0.10,
    "shoulder": 0.06,
    "upper_arm": 0.05,
    "forearm": 0.04,
    "hand": 0.035,
    "thigh": 0.075,
    "shin": 0.05,
    "foot": 0.04,
}
DEFAULT_HAND_EXTENSION = 0.5  # hand end = wrist + 0.5 forearm: ~13 cm on the template
DEFAULT_HEAD_OFFSET = 0.5  # head centre = head + 0.5 (head - neck): ~5 cm above the head joint

# Stature proxy: bone lengths from ankle to head (legs averaged), independent of pose and axis.
_LEG_BONES = (
    ("l_ankle", "l_knee"),
    ("l_knee", "l_hip"),
    ("r_ankle", "r_knee"),
    ("r_knee", "r_hip"),
)
_SPINE_CHAIN = ("pelvis", "spine1", "spine2", "spine3", "neck", "head")


class Capsules(NamedTuple):
    """Sphere-swept segments: a, b (..., K, 3) endpoints; radius (K,) or (..., K), metres."""

    a: torch.Tensor
    b: torch.Tensor
    radius: torch.Tensor


def _check_joints(joints: torch.Tensor, name: str) -> None:
    if joints.ndim < 2 or tuple(joints.shape[-2:]) != (NUM_JOINTS, 3):
        raise ValueError(
            f"{name}: expected joints of shape (..., 22, 3), got {tuple(joints.shape)}"
        )
    if not joints.is_floating_point():
        raise ValueError(f"{name}: joints must be a floating-point tensor, got {joints.dtype}")


def check_finite(tensor: torch.Tensor, name: str) -> None:
    """Raise ValueError naming `name` when `tensor` holds NaN or inf."""
    if not bool(torch.isfinite(tensor).all()):
        bad = int((~torch.isfinite(tensor)).sum())
        raise ValueError(f"{name} contains {bad} NaN or inf values")


def full_precision(tensor: torch.Tensor) -> torch.Tensor:
    """float16 / bfloat16 -> float32; float32 and float64 pass through (gradients flow)."""
    return tensor.float() if tensor.dtype in (torch.float16, torch.bfloat16) else tensor


def skeleton_height(joints: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) -> (...) stature proxy in the joints' unit: mean leg length + spine chain.

    Ankle to head joint along the bones (1.42 m on the template; no feet, no skull): a ratio
    against TEMPLATE_HEIGHT, the same in any pose and frame.
    """
    _check_joints(joints, "skeleton_height")

    def length(u: str, v: str) -> torch.Tensor:
        return torch.linalg.vector_norm(joints[..., _J[u], :] - joints[..., _J[v], :], dim=-1)

    legs = sum(length(u, v) for u, v in _LEG_BONES) / 2
    spine = sum(length(u, v) for u, v in zip(_SPINE_CHAIN[:-1], _SPINE_CHAIN[1:], strict=True))
    return legs + spine


TEMPLATE_HEIGHT = float(skeleton_height(rest_pose_positions()))


class BodyProxy:
    """The capsule table: which joints each capsule joins and its radius.

    radii: metres per part (every name in PARTS, no others), for the template body.
    hand_extension: hand capsule length as a fraction of the forearm.
    head_offset: head-sphere centre beyond the head joint, as a fraction of neck -> head.
    scale_with_height: multiply the radii by skeleton_height(joints) / TEMPLATE_HEIGHT per frame.
    """

    def __init__(
        self,
        *,
        radii: Mapping[str, float] = DEFAULT_RADII,
        hand_extension: float = DEFAULT_HAND_EXTENSION,
        head_offset: float = DEFAULT_HEAD_OFFSET,
        scale_with_height: bool = False,
    ) -> None:
        missing = sorted(set(PARTS) - set(radii))
        unknown = sorted(set(radii) - set(PARTS))
        if missing or unknown:
            raise ValueError(
                f"BodyProxy: radii must name exactly the parts {', '.join(PARTS)}; "
                f"missing {missing}, unknown {unknown}"
            )
        bad = {part: value for part, value in radii.items() if not float(value) >= 0.0}
        if bad:
            raise ValueError(f"BodyProxy: radii must be >= 0 metres, got {bad}")
        if hand_extension < 0 or head_offset < 0:
            raise ValueError(
                f"BodyProxy: hand_extension and head_offset must be >= 0, got {hand_extension} "
                f"and {head_offset}"
            )
        self.radii = {part: float(radii[part]) for part in PARTS}
        self.hand_extension = float(hand_extension)
        self.head_offset = float(head_offset)
        self.scale_with_height = bool(scale_with_height)
        self.radius = torch.tensor([self.radii[row[1]] for row in _LAYOUT])  # (K,)
        self.start_weights = self._weights(2)  # (K, 22)
        self.end_weights = self._weights(3)

    def _weights(self, column: int) -> torch.Tensor:
        weights = torch.zeros(NUM_CAPSULES, NUM_JOINTS)
        for k, row in enumerate(_LAYOUT):
            joint = row[column].rstrip("+")
            weights[k, _J[joint]] = 1.0
            if row[column].endswith("+"):
                reference, field = _EXTENSIONS[joint]
                fraction = getattr(self, field)
                weights[k, _J[joint]] += fraction
                weights[k, _J[reference]] -= fraction
        return weights

    def __repr__(self) -> str:
        return (
            f"BodyProxy(radii={self.radii}, hand_extension={self.hand_extension}, "
            f"head_offset={self.head_offset}, scale_with_height={self.scale_with_height})"
        )


DEFAULT_PROXY = BodyProxy()


def body_capsules(joints: torch.Tensor, proxy: BodyProxy | None = None) -> Capsules:
    """(..., 22, 3) joints -> Capsules(a (..., K, 3), b (..., K, 3), radius (K,) or (..., K)).

    The radius is (K,) unless proxy.scale_with_height, then (..., K).
    """
    _check_joints(joints, "body_capsules")
    proxy = DEFAULT_PROXY if proxy is None else proxy
    joints = full_precision(joints)
    # Autocast would run these einsums in bf16: centimetre errors at metre coordinates.
    with torch.autocast(joints.device.type, enabled=False):
        a = torch.einsum("kj,...jc->...kc", proxy.start_weights.to(joints), joints)
        b = torch.einsum("kj,...jc->...kc", proxy.end_weights.to(joints), joints)
    radius = proxy.radius.to(joints)
    if proxy.scale_with_height:
        radius = radius * (skeleton_height(joints) / TEMPLATE_HEIGHT)[..., None]
    return Capsules(a, b, radius)


def _safe_norm(vectors: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    # sqrt has an infinite slope at 0 (a point on a capsule's axis); clamping keeps grads finite.
    return (vectors * vectors).sum(-1).clamp_min(eps).sqrt()


def _to_capsule(
    points: torch.Tensor, a: torch.Tensor, b: torch.Tensor, radius: torch.Tensor
) -> torch.Tensor:
    """Signed distance of points (..., 3) to capsules a, b (..., 3), radius (...), broadcast."""
    ba = b - a
    pa = points - a
    length2 = (ba * ba).sum(-1).clamp_min(1e-12)  # a zero-length capsule is a sphere: t = 0
    t = ((pa * ba).sum(-1) / length2).clamp(0.0, 1.0)
    return _safe_norm(pa - t[..., None] * ba) - radius  # from the closest axis point


def _check_points(points: torch.Tensor, name: str) -> None:
    if points.ndim < 2 or points.shape[-1] != 3:
        raise ValueError(f"{name}: points must be (..., N, 3), got {tuple(points.shape)}")


def capsule_distances(points: torch.Tensor, capsules: Capsules) -> torch.Tensor:
    """Signed distance of every point to every capsule: (..., N, 3) x (..., K, 3) -> (..., N, K).

    Negative inside. Leading dims of points and capsules broadcast.
    """
    _check_points(points, "capsule_distances")
    return _to_capsule(
        points[..., :, None, :],
        capsules.a[..., None, :, :],
        capsules.b[..., None, :, :],
        capsules.radius[..., None, :],
    )


def signed_distance(points: torch.Tensor, capsules: Capsules) -> torch.Tensor:
    """(..., N, 3) points -> (..., N) signed distance to the body (min over its capsules).

    The nearest capsule is found without autograd and only the (..., N) distances to it are
    recomputed with it: the same value and gradient as a min over (..., N, K), without keeping
    (..., N, K, 3) tensors for the backward pass (what makes guidance at (32, 300) cheap).
    """
    _check_points(points, "signed_distance")
    with torch.no_grad():
        nearest = capsule_distances(points, capsules).argmin(-1)  # (..., N)
    shape = torch.broadcast_shapes(points.shape[:-2], capsules.a.shape[:-2]) + nearest.shape[-1:]
    nearest = nearest.expand(shape)

    def pick(values: torch.Tensor) -> torch.Tensor:  # (..., K, C) -> (..., N, C)
        values = values.expand(*shape[:-1], *values.shape[-2:])
        index = nearest[..., None].expand(*shape, values.shape[-1])
        return values.gather(-2, index)

    radius = capsules.radius.expand(capsules.a.shape[:-1])
    return _to_capsule(
        points, pick(capsules.a), pick(capsules.b), pick(radius[..., None]).squeeze(-1)
    )


def segment_distances(
    a1: torch.Tensor, b1: torch.Tensor, a2: torch.Tensor, b2: torch.Tensor
) -> torch.Tensor:
    """Closest distance between segments a1-b1 and a2-b2: (..., 3) each, broadcast -> (...).

    The clamped closest-parameter solution (fix s, solve t, clamp t, re-solve s); exact for
    degenerate (point) and parallel segments too.
    """
    eps = 1e-12
    d1, d2, r = b1 - a1, b2 - a2, a1 - a2
    a = (d1 * d1).sum(-1)
    e = (d2 * d2).sum(-1)
    f = (d2 * r).sum(-1)
    c = (d1 * r).sum(-1)
    b = (d1 * d2).sum(-1)
    denom = a * e - b * b
    s = torch.where(denom > eps, ((b * f - c * e) / denom.clamp_min(eps)).clamp(0, 1), 0.0)
    t = torch.where(e > eps, ((b * s + f) / e.clamp_min(eps)).clamp(0, 1), 0.0)
    # By convexity the s that is optimal for the clamped t is the joint optimum.
    s = torch.where(a > eps, ((t * b - c) / a.clamp_min(eps)).clamp(0, 1), 0.0)
    gap = r + s[..., None] * d1 - t[..., None] * d2
    return torch.linalg.vector_norm(gap, dim=-1)
