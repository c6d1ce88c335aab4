"""BVH clips of both characters from the dataset representations.

InterHuman's 262-d feature holds joint positions and the 6D rotations of joints 1..21 relative
to their parents, but no root rotation. The root orientation is derived per frame from the
pelvis's three children (left hip, right hip, spine1): they hang rigidly off the pelvis, so the
rotation that best maps their rest offsets onto the observed pelvis-to-child vectors (Kabsch) is
the root rotation itself, exactly when the offsets are the body's. Shoulders would be a worse
witness: the spine bends between them and the pelvis.

Inter-X's representation carries the global orientation (row 0) and the pelvis translation, so
its clips need no derivation; its raw frame is Z-up and is turned to Y-up like
``motion.interx_positions``.

HumanML3D's 263-d feature is posed from its joint positions (``recover_from_ric``), not from its
6D part: those rotations come from the reference's inverse kinematics against its own unit-length,
axis-aligned rest offsets, give spine3 the rotation of only one of its three children (the last
chain processed) and the pelvis a rotation from the hips' and shoulders' across vector, so no
fixed skeleton reproduces the positions with them (``features_from_positions`` stores the
identity without rotations, and a generator's 6D need not agree with its positions). Instead an
analytic IK walks the tree: a joint with several children (pelvis, spine3) takes the Kabsch
rotation that maps their rest offsets onto the observed vectors from its posed position; a joint
with one child takes the parent's frame turned by the smallest rotation (a swing, no twist) that
aims its rest bone at the child's observed position; leaves keep their parent's frame. Aiming
from the posed (not the observed) joint keeps errors from adding up along a chain. On a rigid body
(the SMPL joints of the release) the positions come back exactly; a body whose bones stretch
keeps the bone directions and errs by the stretch.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from intermask.motion import humanml3d
from intermask.motion.interhuman import FEATURE_DIM, split_features
from intermask.motion.interx import BODY_ROWS, NUM_ROWS, TRANSLATION_ROW, UpAxis
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import rot6d_to_matrix
from intermask.motion.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, REST_OFFSETS
from intermask.render.bvh import BvhClip, bvh_joint_positions, read_bvh, write_bvh

ROOT_CHILDREN = (1, 2, 3)  # l_hip, r_hip, spine1
OFFSET_REFINEMENTS = 3  # passes of "derive the root, re-measure the offsets in the parent frames"
# Z-up (x, y, z) -> Y-up (x, z, -y) as a matrix, the rotation of motion.interhuman.zup_to_yup.
ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


CHILDREN: tuple[tuple[int, ...], ...] = tuple(
    tuple(c for c in range(NUM_JOINTS) if PARENTS[c] == j) for j in range(NUM_JOINTS)
)
SHAPE_REFINEMENTS = 3  # Procrustes passes for the mean shape of a joint's children
_EPS = 1e-9


def root_rotation_from_joints(positions: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(T, 22, 3) joint positions and (22, 3) rest offsets -> (T, 3, 3) root orientations.

    Kabsch: R = argmin sum_c |R offset_c - (p_c - p_pelvis)|^2 over the pelvis's children c.
    """
    observed = positions[:, ROOT_CHILDREN] - positions[:, :1]  # (T, 3, 3) rows are vectors
    return _best_rotation(offsets[list(ROOT_CHILDREN)], observed)


def _best_rotation(rest: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """(C, 3) or (T, C, 3) rest vectors, (T, C, 3) observed -> (T, 3, 3) Kabsch rotations R
    minimizing sum_c |R rest_c - observed_c|^2."""
    rest = np.broadcast_to(rest, observed.shape)
    covariance = np.einsum("tci,tcj->tij", rest, observed)  # sum_c rest_c observed_c^T
    u, _, vt = np.linalg.svd(covariance)
    v, ut = np.swapaxes(vt, -1, -2), np.swapaxes(u, -1, -2)
    flip = np.sign(np.linalg.det(v @ ut))  # keep a proper rotation (det +1)
    correction = np.broadcast_to(np.eye(3), covariance.shape).copy()
    correction[:, 2, 2] = flip
    return v @ correction @ ut


def _global_rotations(local: np.ndarray) -> np.ndarray:
    result = forward_kinematics(
        torch.from_numpy(local),
        torch.zeros(local.shape[0], 3, dtype=torch.float64),
        REST_OFFSETS.double(),
    )
    return result.global_rotations.numpy()


def estimate_offsets(positions: np.ndarray, child_rotations: np.ndarray) -> np.ndarray:
    """Rest offsets (22, 3) of a body seen as (T, 22, 3) positions with (T, 21, 3, 3) rotations of
    joints 1..21.

    Start from the template's bone directions scaled to the median observed bone lengths, then
    alternate: derive the root rotation, and re-measure each offset as the mean over frames of the
    bone vector expressed in its parent's frame (exact for a body whose rotations and positions
    agree; a least-squares fit otherwise).
    """
    parents = np.array(PARENTS[1:])
    bones = positions[:, 1:] - positions[:, parents]  # (T, 21, 3)
    directions = REST_OFFSETS[1:].double().numpy()
    directions = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    offsets = np.zeros((NUM_JOINTS, 3))
    offsets[1:] = directions * np.median(np.linalg.norm(bones, axis=-1), axis=0)[:, None]
    for _ in range(OFFSET_REFINEMENTS):
        root = root_rotation_from_joints(positions, offsets)
        local = np.concatenate((root[:, None], child_rotations), axis=1)
        parent_frames = _global_rotations(local)[:, parents]  # (T, 21, 3, 3)
        offsets[1:] = np.einsum("tjki,tjk->tji", parent_frames, bones).mean(0)
    return offsets


def _as_numpy(x: object) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def interhuman_bvh_clips(
    features: object, *, fps: float, offsets: object | None = None
) -> list[BvhClip]:
    """(P, T, 262) or (T, 262) de-normalized InterHuman features -> one BvhClip per person.

    offsets: (22, 3) or (P, 22, 3) rest offsets of the bodies; None estimates them from the clip
    (estimate_offsets). Positions are the feature's frame (Y-up, person 1 canonical).
    """
    array = _as_numpy(features)
    if array.ndim == 2:
        array = array[None]
    if array.ndim != 3 or array.shape[-1] != FEATURE_DIM or array.shape[1] < 1:
        raise ValueError(
            f"interhuman_bvh_clips: expected (P, T, {FEATURE_DIM}) or (T, {FEATURE_DIM}), got {np.shape(features)}"
        )
    if not np.isfinite(array).all():
        raise ValueError("interhuman_bvh_clips: features contain NaN or infinite values")
    given = (
        None
        if offsets is None
        else np.broadcast_to(_as_numpy(offsets), (array.shape[0], NUM_JOINTS, 3))
    )
    parts = split_features(torch.from_numpy(array))
    positions = parts.positions.numpy()  # (P, T, 22, 3)
    child_rotations = rot6d_to_matrix(parts.rot6d).numpy()  # (P, T, 21, 3, 3)
    clips = []
    for person in range(array.shape[0]):
        body = (
            estimate_offsets(positions[person], child_rotations[person])
            if given is None
            else given[person]
        )
        root = root_rotation_from_joints(positions[person], body)
        clips.append(
            BvhClip(
                names=JOINT_NAMES,
                parents=PARENTS,
                offsets=np.array(body, dtype=np.float64),
                root_positions=positions[person, :, 0].copy(),
                rotations=np.concatenate((root[:, None], child_rotations[person]), axis=1),
                frame_time=_frame_time(fps),
            )
        )
    return clips


def interx_bvh_clips(
    representation: object, *, fps: float, offsets: object = REST_OFFSETS, up_axis: UpAxis = "z"
) -> list[BvhClip]:
    """(P, T, 56, 6) or (T, 56, 6) Inter-X generator representation -> one Y-up BvhClip per person.

    offsets: (22, 3) or (P, 22, 3) body rest offsets (Y-up, the skeleton's template by default, as
    the Inter-X layout stores no body shape).
    """
    array = _as_numpy(representation)
    if array.ndim == 3:
        array = array[None]
    if array.ndim != 4 or array.shape[-2:] != (NUM_ROWS, 6):
        raise ValueError(
            f"interx_bvh_clips: expected (P, T, {NUM_ROWS}, 6) or (T, {NUM_ROWS}, 6), got {np.shape(representation)}"
        )
    if up_axis not in ("y", "z"):
        raise ValueError(f"interx_bvh_clips: up_axis must be 'y' or 'z', got {up_axis!r}")
    bodies = np.broadcast_to(_as_numpy(offsets), (array.shape[0], NUM_JOINTS, 3))
    rotations = rot6d_to_matrix(
        torch.from_numpy(array[:, :, BODY_ROWS])
    ).numpy()  # (P, T, 22, 3, 3)
    translations = array[:, :, TRANSLATION_ROW, :3]  # (P, T, 3)
    if up_axis == "z":
        rotations[:, :, 0] = ZUP_TO_YUP @ rotations[:, :, 0]
        translations = translations @ ZUP_TO_YUP.T
    return [
        BvhClip(
            names=JOINT_NAMES,
            parents=PARENTS,
            offsets=np.array(bodies[p]),
            root_positions=np.array(translations[p]),
            rotations=rotations[p],
            frame_time=_frame_time(fps),
        )
        for p in range(array.shape[0])
    ]


def _swing(rest: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(T, 3) directions -> (T, 3, 3) smallest rotations turning rest onto target (identity where
    either is zero, a half turn about a perpendicular axis where they are opposite)."""
    a = rest / np.maximum(np.linalg.norm(rest, axis=-1, keepdims=True), _EPS)
    b_norm = np.linalg.norm(target, axis=-1, keepdims=True)
    b = np.where(b_norm > _EPS, target / np.maximum(b_norm, _EPS), a)
    v, c = np.cross(a, b), np.einsum("ti,ti->t", a, b)
    skew = np.zeros((len(a), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    skew -= np.swapaxes(skew, -1, -2)
    opposite = c < -1 + 1e-6
    factor = np.where(opposite, 0.0, 1.0 / np.maximum(1.0 + c, 1e-6))
    result = np.eye(3) + skew + skew @ skew * factor[:, None, None]
    if opposite.any():
        helper = np.where(np.abs(a[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        axis = np.cross(a, helper)
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        half_turn = 2 * np.einsum("ti,tj->tij", axis, axis) - np.eye(3)
        result[opposite] = half_turn[opposite]
    return result


def humanml3d_offsets(positions: np.ndarray) -> np.ndarray:
    """(T, 22, 3) joint positions -> (22, 3) rest offsets of the body (row 0 zero).

    A joint with one child: the template's bone direction (REST_OFFSETS, so the rest pose is the
    template's) at the median observed length. The children of a joint with several (pelvis,
    spine3): their mean shape as seen from it (Procrustes: align every frame to the mean, average,
    repeat), turned to best match the template's directions; exact for a rigid body.
    """
    template = REST_OFFSETS.double().numpy()
    offsets = np.zeros((NUM_JOINTS, 3))
    for joint, children in enumerate(CHILDREN):
        if not children:
            continue
        vectors = positions[:, list(children)] - positions[:, joint : joint + 1]  # (T, C, 3)
        if len(children) == 1:
            direction = template[children[0]] / np.linalg.norm(template[children[0]])
            offsets[children[0]] = direction * np.median(np.linalg.norm(vectors[:, 0], axis=-1))
            continue
        mean = vectors[0]
        for _ in range(SHAPE_REFINEMENTS):
            aligned = np.einsum("tki,tck->tci", _best_rotation(mean, vectors), vectors)
            mean = aligned.mean(0)
        to_template = _best_rotation(mean, template[None, list(children)])[0]
        offsets[list(children)] = mean @ to_template.T
    return offsets


def positional_ik(positions: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(T, 22, 3) positions, (22, 3) offsets -> (T, 22, 3, 3) local rotations posing the offsets
    onto the positions (module docstring: Kabsch at branching joints, swings along chains)."""
    frames = positions.shape[0]
    posed = np.zeros_like(positions)
    posed[:, 0] = positions[:, 0]
    world = np.zeros((frames, NUM_JOINTS, 3, 3))
    local = np.zeros_like(world)
    for joint, children in enumerate(CHILDREN):
        parent = PARENTS[joint]
        parent_frame = (
            np.broadcast_to(np.eye(3), (frames, 3, 3)) if parent < 0 else world[:, parent]
        )
        if parent >= 0:
            posed[:, joint] = posed[:, parent] + parent_frame @ offsets[joint]
        targets = positions[:, list(children)] - posed[:, joint : joint + 1]  # (T, C, 3)
        if len(children) > 1 or parent < 0:
            world[:, joint] = _best_rotation(offsets[list(children)], targets)
        elif children:
            world[:, joint] = (
                _swing(parent_frame @ offsets[children[0]], targets[:, 0]) @ parent_frame
            )
        else:
            world[:, joint] = parent_frame
        local[:, joint] = np.swapaxes(parent_frame, -1, -2) @ world[:, joint]
    return local


def humanml3d_bvh_clips(
    features: object, *, fps: float = float(humanml3d.FPS), offsets: object | None = None
) -> list[BvhClip]:
    """(T, 263) or (1, T, 263) de-normalized HumanML3D features -> [BvhClip] of the one person.

    Posed from ``recover_from_ric`` by positional IK (module docstring); the 6D part is not read.
    offsets: (22, 3) rest offsets of the body; None estimates them (humanml3d_offsets).
    """
    dim = humanml3d.FEATURE_DIM
    array = _as_numpy(features)
    if array.ndim == 3 and array.shape[0] == 1:
        array = array[0]
    if array.ndim != 2 or array.shape[-1] != dim or array.shape[0] < 1:
        raise ValueError(
            f"humanml3d_bvh_clips: expected (T, {dim}) or (1, T, {dim}), got {np.shape(features)}"
        )
    if not np.isfinite(array).all():
        raise ValueError("humanml3d_bvh_clips: features contain NaN or infinite values")
    positions = humanml3d.recover_from_ric(torch.from_numpy(array)).numpy()  # (T, 22, 3)
    if offsets is None:
        body = humanml3d_offsets(positions)
    else:
        body = _as_numpy(offsets)
        if body.shape != (NUM_JOINTS, 3):
            raise ValueError(
                f"humanml3d_bvh_clips: offsets must be ({NUM_JOINTS}, 3), got {body.shape}"
            )
    return [
        BvhClip(
            names=JOINT_NAMES,
            parents=PARENTS,
            offsets=np.array(body),
            root_positions=positions[:, 0].copy(),
            rotations=positional_ik(positions, body),
            frame_time=_frame_time(fps),
        )
    ]


def _frame_time(fps: float) -> float:
    if fps <= 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    return 1.0 / fps


def write_interaction_bvh(
    directory: str | Path,
    clips: list[BvhClip],
    *,
    stem: str = "interaction",
    euler_order: str = "ZXY",
    scale: float = 1.0,
) -> list[Path]:
    """Write <stem>_person<k>.bvh for each clip (one character per file) and return the paths."""
    if not clips:
        raise ValueError("write_interaction_bvh: no clips to write")
    directory = Path(directory)
    return [
        write_bvh(
            directory / f"{stem}_person{k + 1}.bvh", clip, euler_order=euler_order, scale=scale
        )
        for k, clip in enumerate(clips)
    ]


def read_bvh_joints(
    path: str | Path, *, scale: float = 1.0, joint_names: tuple[str, ...] = JOINT_NAMES
) -> np.ndarray:
    """Parse a BVH file and pose it: (T, len(joint_names), 3) positions in joint_names order."""
    clip = read_bvh(path, scale=scale)
    missing = [name for name in joint_names if name not in clip.names]
    if missing:
        raise ValueError(
            f"{path}: joints {', '.join(missing)} are missing (file has {', '.join(clip.names)})"
        )
    positions = bvh_joint_positions(clip)
    return positions[:, [clip.names.index(name) for name in joint_names]]
