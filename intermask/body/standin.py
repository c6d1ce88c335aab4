"""A generated stand-in for the licensed SMPL-X / SMPL-H files, so that loading, fitting, export,
rendering and mesh penetration run offline and in CI.

It has the official files' keys, kinematic tree (55 or 52 joints, the SMPL body skeleton first)
and dtypes, but a body of its own making and few vertices: one closed tube per bone (rings of
``RING`` vertices at the parent and child joints, capped), so about 850 vertices instead of 10475.
The rest joints are the project's template skeleton (:data:`intermask.motion.skeleton.REST_OFFSETS`)
with the pelvis placed below the model origin as in the real files, fingers fanned out beyond the
wrists, jaw and eyes ahead of the head. ``J_regressor`` averages the ring around each joint (so
it regresses the joint exactly in the rest pose), ``weights`` tie the parent ring to the parent
joint and blend the child ring half and half, ``shapedirs`` are linear bone-length, girth and
scale changes (the first ten components are named in SHAPE_COMPONENTS; later ones are small
random bone-length changes, SMPL-X's expression block zero), ``posedirs`` small random
correctives. None of its numbers are SMPL's: it tests the code paths, never the bodies.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from intermask.body.model import HAND_JOINTS, NUM_MODEL_JOINTS, BodyKind
from intermask.motion.skeleton import LEFT_JOINTS, NUM_JOINTS, PARENTS, REST_OFFSETS

RING = 6  # vertices per ring
PELVIS = np.array([0.003, -0.351, 0.012])  # rest pelvis, about where the real models put it
UINT32_ROOT = 4294967295  # the releases' kintree_table parent of the root (uint32 -1)
# SMPL-X's 400 shape directions: 300 body shape + 100 expressions; AMASS's SMPL+H: 16.
SHAPE_SPACE = {"smplx": (300, 100), "smplh": (16, 0)}
SHAPE_COMPONENTS = (
    "stature",
    "girth",
    "legs",
    "arms",
    "torso",
    "neck_and_head",
    "shoulder_width",
    "hip_width",
    "forearms",
    "shins",
)
FINGERS = ("index", "middle", "pinky", "ring", "thumb")  # the releases' hand order
_FINGER_SPREAD = {"index": 0.022, "middle": 0.0, "pinky": -0.04, "ring": -0.02, "thumb": 0.04}
_PHALANX = 0.028  # metres
_RADII = {  # tube radius of the bone ending at a joint, metres
    1: 0.085, 2: 0.085, 3: 0.11, 4: 0.07, 5: 0.07, 6: 0.12, 7: 0.05, 8: 0.05, 9: 0.13,
    10: 0.04, 11: 0.04, 12: 0.05, 13: 0.06, 14: 0.06, 15: 0.09, 16: 0.055, 17: 0.055,
    18: 0.045, 19: 0.045, 20: 0.035, 21: 0.035,
}  # fmt: skip


def joint_tree(kind: BodyKind) -> tuple[tuple[int, ...], np.ndarray]:
    """(parents, (J, 3) rest joints) of the stand-in's full skeleton."""
    parents = list(PARENTS)
    body = np.zeros((NUM_JOINTS, 3))
    offsets = REST_OFFSETS.double().numpy()
    body[0] = PELVIS
    for joint in range(1, NUM_JOINTS):
        body[joint] = body[PARENTS[joint]] + offsets[joint]
    joints = [*body]
    if kind == "smplx":  # jaw, left eye, right eye
        head = body[15]
        for offset in ((0.0, -0.04, 0.06), (0.03, 0.03, 0.08), (-0.03, 0.03, 0.08)):
            parents.append(15)
            joints.append(head + np.array(offset))
    for wrist in (20, 21):  # 15 left-hand joints, then 15 right-hand joints
        side = 1.0 if wrist in LEFT_JOINTS else -1.0
        for finger in FINGERS:
            previous = wrist
            start = body[wrist] + np.array(
                [side * (0.03 if finger == "thumb" else 0.08), -0.01, _FINGER_SPREAD[finger]]
            )
            for k in range(3):
                parents.append(previous)
                joints.append(start + np.array([side * _PHALANX * k, 0.0, 0.0]))
                previous = len(joints) - 1
    if len(parents) != NUM_MODEL_JOINTS[kind]:
        raise AssertionError(f"stand-in {kind}: built {len(parents)} joints")
    return tuple(parents), np.array(joints)


def _basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


class _Mesh:
    """Tubes, their rings and what each vertex follows, built bone by bone."""

    def __init__(self, parents: tuple[int, ...], joints: np.ndarray) -> None:
        self.parents, self.joints = parents, joints
        self.vertices: list[np.ndarray] = []
        self.faces: list[tuple[int, int, int]] = []
        self.owner: list[tuple[int, int, float]] = []  # (tube joint, end 0|1, radial share)
        self.radial: list[np.ndarray] = []  # outward offset from the tube axis
        self.end_rings: dict[int, list[int]] = {}
        self.start_rings: dict[int, list[int]] = {}
        for joint in range(1, len(parents)):
            self._tube(joint)

    def _add(self, point: np.ndarray, joint: int, end: int, radial: np.ndarray) -> int:
        self.vertices.append(point)
        self.owner.append((joint, end, 1.0))
        self.radial.append(radial)
        return len(self.vertices) - 1

    def _triangle(self, a: int, b: int, c: int, outward: np.ndarray) -> None:
        p = [self.vertices[k] for k in (a, b, c)]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        self.faces.append((a, b, c) if normal @ outward >= 0 else (a, c, b))

    def _tube(self, joint: int) -> None:
        parent = self.parents[joint]
        start, end = self.joints[parent], self.joints[joint]
        axis = (end - start) / np.linalg.norm(end - start)
        radius = _RADII.get(joint, 0.008 if joint >= NUM_JOINTS else 0.05)
        if joint >= NUM_JOINTS and self.parents[joint] == 15:  # jaw and eyes
            radius = 0.02
        u, w = _basis(axis)
        rings = []
        for which, centre in ((0, start), (1, end)):
            ring = []
            for k in range(RING):
                angle = 2 * math.pi * k / RING
                offset = radius * (math.cos(angle) * u + math.sin(angle) * w)
                ring.append(self._add(centre + offset, joint, which, offset))
            rings.append(ring)
        self.start_rings[joint], self.end_rings[joint] = rings
        caps = (
            self._add(start - 0.5 * radius * axis, joint, 0, -0.5 * radius * axis),
            self._add(end + 0.5 * radius * axis, joint, 1, 0.5 * radius * axis),
        )
        for k in range(RING):
            n = (k + 1) % RING
            a0, a1, b0, b1 = rings[0][k], rings[0][n], rings[1][k], rings[1][n]
            side = self.vertices[a0] + self.vertices[b1] - 2 * start
            self._triangle(a0, a1, b1, side - (side @ axis) * axis)
            self._triangle(a0, b1, b0, side - (side @ axis) * axis)
            self._triangle(caps[0], a1, a0, -axis)
            self._triangle(caps[1], b0, b1, axis)


def _bone_groups(parents: tuple[int, ...]) -> dict[str, list[int]]:
    legs = [1, 2, 4, 5, 7, 8, 10, 11]
    arms = [16, 17, 18, 19, 20, 21, *range(NUM_JOINTS, len(parents))]
    return {
        "legs": legs,
        "arms": arms,
        "torso": [3, 6, 9],
        "neck_and_head": [12, 15],
        "shoulder_width": [13, 14],
        "hip_width": [1, 2],
        "forearms": [20, 21],
        "shins": [7, 8],
    }


def _length_direction(mesh: _Mesh, scales: np.ndarray) -> np.ndarray:
    """(J,) relative bone-length changes -> (V, 3) vertex displacement (linear in scales)."""
    parents, joints = mesh.parents, mesh.joints
    moved = np.zeros_like(joints)
    for joint in range(1, len(parents)):
        moved[joint] = moved[parents[joint]] + scales[joint] * (
            joints[joint] - joints[parents[joint]]
        )
    return np.array([moved[parents[j]] if end == 0 else moved[j] for j, end, _ in mesh.owner])


def _shapedirs(mesh: _Mesh, kind: BodyKind, rng: np.random.Generator) -> np.ndarray:
    shape, expressions = SHAPE_SPACE[kind]
    vertices = np.array(mesh.vertices)
    count = len(mesh.parents)
    groups = _bone_groups(mesh.parents)
    directions = [0.06 * (vertices - PELVIS), 0.15 * np.array(mesh.radial)]
    for name in SHAPE_COMPONENTS[2:]:
        scales = np.zeros(count)
        scales[groups[name]] = 0.05
        directions.append(_length_direction(mesh, scales))
    while len(directions) < shape:
        directions.append(_length_direction(mesh, rng.normal(0.0, 0.004, count)))
    directions += [np.zeros_like(vertices)] * expressions
    return np.stack(directions[: shape + expressions], axis=-1)  # (V, 3, S)


def _weights(mesh: _Mesh) -> np.ndarray:
    weights = np.zeros((len(mesh.vertices), len(mesh.parents)))
    for vertex, (joint, end, _) in enumerate(mesh.owner):
        parent = mesh.parents[joint]
        if end == 0:
            weights[vertex, parent] = 1.0
        elif vertex in mesh.end_rings[joint]:
            weights[vertex, parent] += 0.5
            weights[vertex, joint] += 0.5
        else:
            weights[vertex, joint] = 1.0
    return weights


def _regressor(mesh: _Mesh) -> np.ndarray:
    regressor = np.zeros((len(mesh.parents), len(mesh.vertices)))
    regressor[0, mesh.start_rings[3]] = 1.0 / RING  # the pelvis: the spine tube's start ring
    for joint, ring in mesh.end_rings.items():
        regressor[joint, ring] = 1.0 / RING
    return regressor


def standin_arrays(kind: BodyKind = "smplx", *, seed: int = 0) -> dict[str, np.ndarray]:
    """The arrays of a stand-in model file, by the official file's keys and dtypes."""
    if kind not in NUM_MODEL_JOINTS:
        raise ValueError(
            f"stand-in kind must be one of {', '.join(NUM_MODEL_JOINTS)}, got {kind!r}"
        )
    rng = np.random.default_rng(seed)
    parents, joints = joint_tree(kind)
    mesh = _Mesh(parents, joints)
    vertices = np.array(mesh.vertices)
    count = len(parents)
    kintree = np.stack((np.array(parents, dtype=np.int64), np.arange(count, dtype=np.int64)))
    kintree[0, 0] = UINT32_ROOT
    arrays = {
        "v_template": vertices.astype(np.float64),
        "f": np.array(mesh.faces, dtype=np.uint32),
        "shapedirs": _shapedirs(mesh, kind, rng),
        "posedirs": rng.normal(0.0, 2e-4, (len(vertices), 3, 9 * (count - 1))),
        "J_regressor": _regressor(mesh),
        "weights": _weights(mesh),
        "kintree_table": kintree,
    }
    if kind == "smplx":
        faces = len(mesh.faces)
        hand = 3 * HAND_JOINTS
        arrays |= {
            "hands_componentsl": np.eye(hand),
            "hands_componentsr": np.eye(hand),
            "hands_meanl": np.zeros(hand),
            "hands_meanr": np.zeros(hand),
            "hands_coeffsl": np.zeros((4, hand)),
            "hands_coeffsr": np.zeros((4, hand)),
            "lmk_faces_idx": rng.integers(0, faces, 51).astype(np.int64),
            "lmk_bary_coords": np.full((51, 3), 1.0 / 3.0),
            "dynamic_lmk_faces_idx": rng.integers(0, faces, (79, 17)).astype(np.int64),
            "dynamic_lmk_bary_coords": np.full((79, 17, 3), 1.0 / 3.0),
            "vt": np.zeros((len(vertices), 2)),
            "ft": arrays["f"].copy(),
        }
    else:  # AMASS's extended SMPL+H model.npz
        arrays |= {
            "J_regressor_prior": arrays["J_regressor"].copy(),
            "weights_prior": arrays["weights"].copy(),
            "J": joints.astype(np.float64),
            "bs_style": np.array("lbs"),
            "bs_type": np.array("lrotmin"),
        }
    return arrays


def write_standin_model(
    folder: str | Path, kind: BodyKind = "smplx", *, gender: str = "neutral", seed: int = 0
) -> Path:
    """Write a stand-in file where the release puts it (``SMPLX_<GENDER>.npz`` or
    ``smplh/<gender>/model.npz`` under folder) and return its path."""
    folder = Path(folder)
    path = (
        folder / f"SMPLX_{gender.upper()}.npz"
        if kind == "smplx"
        else folder / "smplh" / gender / "model.npz"
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **standin_arrays(kind, seed=seed))
    return path
