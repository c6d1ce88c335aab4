"""BVH (Biovision hierarchy) files: a small writer and parser, and forward kinematics of a clip.

One skeleton per file (Blender's importer, like most tools, reads a single ROOT). Rotations are
written as Euler angles in degrees, by default in the ``ZXY`` channel order that most mocap BVH
files use; the parser reads any order. A channel list ``Zrotation Xrotation Yrotation`` means the
local rotation ``R = Rz(a) @ Rx(b) @ Ry(c)`` (BVH applies the listed rotations left to right).
The root's OFFSET is written as zero and its position channels hold the world position, so the
two common readings of a root offset agree on our files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from intermask.motion.kinematics import forward_kinematics

_AXES = "XYZ"
_SIGNS = {"XYZ": 1, "YZX": 1, "ZXY": 1, "XZY": -1, "YXZ": -1, "ZYX": -1}
END_SITE_LENGTH = 0.08  # metres: a short continuation of the last bone, so leaves have a length


@dataclass(frozen=True)
class BvhClip:
    """One animated skeleton.

    offsets: (J, 3) rest offset of each joint from its parent (row 0 is ignored: the root is at
    root_positions); root_positions: (T, 3) world position of joint 0; rotations: (T, J, 3, 3)
    local rotation of each joint relative to its parent, row 0 the root's world orientation;
    end_sites: leaf joint -> (3,) offset of its end site (defaults to END_SITE_LENGTH along the
    leaf's own offset).
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    root_positions: np.ndarray
    rotations: np.ndarray
    frame_time: float
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        joints = len(self.names)
        if len(self.parents) != joints or self.parents[0] != -1:
            raise ValueError(
                f"BvhClip: need one parent per joint with parents[0] = -1; got {len(self.parents)} "
                f"parents for {joints} joints"
            )
        if any(not 0 <= p < j for j, p in enumerate(self.parents) if j > 0):
            raise ValueError(
                f"BvhClip: parents[j] must lie in [0, j) for j > 0, got {self.parents}"
            )
        if len(set(self.names)) != joints or any(
            not n or any(c.isspace() for c in n) for n in self.names
        ):
            raise ValueError(
                f"BvhClip: joint names must be unique and free of whitespace, got {self.names}"
            )
        frames = self.root_positions.shape[0] if self.root_positions.ndim == 2 else -1
        if self.offsets.shape != (joints, 3):
            raise ValueError(f"BvhClip: offsets must be ({joints}, 3), got {self.offsets.shape}")
        if self.root_positions.shape != (frames, 3) or frames < 1:
            raise ValueError(
                f"BvhClip: root_positions must be (T >= 1, 3), got {self.root_positions.shape}"
            )
        if self.rotations.shape != (frames, joints, 3, 3):
            raise ValueError(
                f"BvhClip: rotations must be ({frames}, {joints}, 3, 3), got {self.rotations.shape}"
            )
        if self.frame_time <= 0:
            raise ValueError(f"BvhClip: frame_time must be > 0 seconds, got {self.frame_time}")
        for name, array in (
            ("offsets", self.offsets),
            ("root_positions", self.root_positions),
            ("rotations", self.rotations),
        ):
            if not np.isfinite(array).all():
                raise ValueError(f"BvhClip: {name} contains NaN or infinite values")

    @property
    def frames(self) -> int:
        return self.root_positions.shape[0]

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time


def euler_to_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """(..., 3) Euler angles in degrees, applied as R = R_order[0] @ R_order[1] @ R_order[2]."""
    _check_order(order)
    result = np.broadcast_to(np.eye(3), (*angles_deg.shape[:-1], 3, 3)).copy()
    for k, axis in enumerate(order):
        result = result @ _axis_matrix(np.radians(angles_deg[..., k]), _AXES.index(axis))
    return result


def matrix_to_euler(matrix: np.ndarray, order: str) -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 3) Euler angles in degrees for euler_to_matrix(order).

    Closed form for R = R_i(a) R_j(b) R_k(c): sin b = s R[i, k] with s the parity of (i, j, k).
    At gimbal lock (|cos b| ~ 0) c is set to 0 and a absorbs the whole remaining rotation.
    """
    _check_order(order)
    i, j, k = (_AXES.index(axis) for axis in order)
    s = _SIGNS[order]
    sin_b = np.clip(s * matrix[..., i, k], -1.0, 1.0)
    b = np.arcsin(sin_b)
    a = np.arctan2(-s * matrix[..., j, k], matrix[..., k, k])
    c = np.arctan2(-s * matrix[..., i, j], matrix[..., i, i])
    locked = np.abs(sin_b) > 1 - 1e-9
    a = np.where(locked, np.arctan2(s * matrix[..., k, j], matrix[..., j, j]), a)
    c = np.where(locked, 0.0, c)
    return np.degrees(np.stack((a, b, c), axis=-1))


def _check_order(order: str) -> None:
    if order not in _SIGNS:
        raise ValueError(f"Euler order must be one of {', '.join(_SIGNS)}, got {order!r}")


def _axis_matrix(angle: np.ndarray, axis: int) -> np.ndarray:
    cos, sin = np.cos(angle), np.sin(angle)
    matrix = np.zeros((*np.shape(angle), 3, 3))
    a, b = [(1, 2), (2, 0), (0, 1)][axis]
    matrix[..., axis, axis] = 1.0
    matrix[..., a, a], matrix[..., a, b] = cos, -sin
    matrix[..., b, a], matrix[..., b, b] = sin, cos
    return matrix


def _end_site(clip: BvhClip, joint: int) -> np.ndarray:
    if joint in clip.end_sites:
        return np.asarray(clip.end_sites[joint], dtype=np.float64)
    offset = clip.offsets[joint]
    length = float(np.linalg.norm(offset))
    return (
        offset / length * END_SITE_LENGTH
        if length > 1e-9
        else np.array([0.0, END_SITE_LENGTH, 0.0])
    )


def write_bvh(
    path: str | Path,
    clip: BvhClip,
    *,
    euler_order: str = "ZXY",
    scale: float = 1.0,
    precision: int = 6,
) -> Path:
    """Write one skeleton to a .bvh file; lengths are multiplied by scale (100: centimetres).

    Each channel's angles are unwrapped over time (adding 360 degrees to one angle gives the same
    rotation), so keyframe interpolation in Blender does not spin through a whole turn.
    """
    _check_order(euler_order)
    if scale <= 0:
        raise ValueError(f"write_bvh: scale must be > 0, got {scale}")
    children: dict[int, list[int]] = {j: [] for j in range(len(clip.names))}
    for joint, parent in enumerate(clip.parents[1:], start=1):
        children[parent].append(joint)
    rotation_channels = " ".join(f"{axis}rotation" for axis in euler_order)
    fmt = f"{{:.{precision}f}}"
    lines = ["HIERARCHY"]
    written: list[int] = []  # MOTION columns follow the depth-first order of the hierarchy

    def emit(joint: int, depth: int) -> None:
        written.append(joint)
        pad = "\t" * depth
        keyword = "ROOT" if joint == 0 else "JOINT"
        offset = np.zeros(3) if joint == 0 else clip.offsets[joint] * scale
        lines.append(f"{pad}{keyword} {clip.names[joint]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}\tOFFSET " + " ".join(fmt.format(v) for v in offset))
        if joint == 0:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rotation_channels}")
        else:
            lines.append(f"{pad}\tCHANNELS 3 {rotation_channels}")
        for child in children[joint]:
            emit(child, depth + 1)
        if not children[joint]:
            site = _end_site(clip, joint) * scale
            lines.extend(
                [
                    f"{pad}\tEnd Site",
                    f"{pad}\t{{",
                    f"{pad}\t\tOFFSET " + " ".join(fmt.format(v) for v in site),
                    f"{pad}\t}}",
                ]
            )
        lines.append(f"{pad}}}")

    emit(0, 0)
    angles = np.unwrap(
        matrix_to_euler(clip.rotations, euler_order), period=360.0, axis=0
    )  # (T, J, 3)
    values = np.concatenate([clip.root_positions * scale] + [angles[:, j] for j in written], axis=1)
    lines += ["MOTION", f"Frames: {clip.frames}", f"Frame Time: {clip.frame_time:.8f}"]
    lines += [" ".join(fmt.format(v) for v in row) for row in values]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n", encoding="ascii")
    return path


class _Tokens:
    def __init__(self, text: str, path: Path) -> None:
        self.items, self.position, self.path = text.split(), 0, path

    def next(self, expected: str | None = None) -> str:
        if self.position >= len(self.items):
            raise ValueError(
                f"{self.path}: unexpected end of file"
                + (f", expected {expected!r}" if expected else "")
            )
        token = self.items[self.position]
        self.position += 1
        if expected is not None and token != expected:
            raise ValueError(
                f"{self.path}: expected {expected!r}, got {token!r} (token {self.position})"
            )
        return token

    def floats(self, count: int) -> list[float]:
        try:
            return [float(self.next()) for _ in range(count)]
        except ValueError as error:
            raise ValueError(
                f"{self.path}: expected {count} numbers near token {self.position}: {error}"
            ) from None


def read_bvh(path: str | Path, *, scale: float = 1.0) -> BvhClip:
    """Parse a .bvh file (one ROOT, any rotation channel order) into a BvhClip in metres/scale."""
    path = Path(path)
    text = path.read_text(encoding="utf-8", errors="replace")
    if "MOTION" not in text:
        raise ValueError(f"{path}: not a BVH file (no MOTION section)")
    tokens = _Tokens(text, path)
    hierarchy = _read_hierarchy(tokens, scale)
    if tokens.next() != "MOTION":
        raise ValueError(f"{path}: only one ROOT per file is supported")
    frame_time, data = _read_motion(tokens, sum(len(c) for c in hierarchy.channels))
    root_positions, rotations = _pose_channels(hierarchy, data, path)
    return BvhClip(
        names=tuple(hierarchy.names),
        parents=tuple(hierarchy.parents),
        offsets=np.array(hierarchy.offsets) / scale,
        root_positions=root_positions / scale,
        rotations=rotations,
        frame_time=frame_time,
        end_sites=hierarchy.end_sites,
    )


@dataclass
class _Hierarchy:
    """A BVH HIERARCHY section, joints in file (depth-first) order: offsets as written, end
    sites already divided by the reader's scale."""

    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[list[float]] = field(default_factory=list)
    channels: list[list[str]] = field(default_factory=list)
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)


def _read_hierarchy(tokens: _Tokens, scale: float) -> _Hierarchy:
    """Read ``HIERARCHY ROOT ...`` up to the end of the first root joint."""
    hierarchy = _Hierarchy()

    def joint(parent: int) -> None:
        index = len(hierarchy.names)
        hierarchy.names.append(tokens.next())
        hierarchy.parents.append(parent)
        tokens.next("{")
        tokens.next("OFFSET")
        hierarchy.offsets.append(tokens.floats(3))
        tokens.next("CHANNELS")
        count = int(tokens.next())
        hierarchy.channels.append([tokens.next() for _ in range(count)])
        while True:
            keyword = tokens.next()
            if keyword == "}":
                return
            if keyword == "JOINT":
                joint(index)
            elif keyword == "End":
                tokens.next("Site")
                tokens.next("{")
                tokens.next("OFFSET")
                hierarchy.end_sites[index] = np.array(tokens.floats(3)) / scale
                tokens.next("}")
            else:
                raise ValueError(
                    f"{tokens.path}: unexpected {keyword!r} inside joint {hierarchy.names[index]!r}"
                )

    tokens.next("HIERARCHY")
    tokens.next("ROOT")
    joint(-1)
    return hierarchy


def _read_motion(tokens: _Tokens, width: int) -> tuple[float, np.ndarray]:
    """The MOTION section after its keyword: frame time and the (frames, width) channel values."""
    tokens.next("Frames:")
    frames = int(tokens.next())
    tokens.next("Frame")
    tokens.next("Time:")
    frame_time = float(tokens.next())
    data = np.array(tokens.items[tokens.position :], dtype=np.float64)
    if data.size != frames * width:
        raise ValueError(
            f"{tokens.path}: expected {frames} frames x {width} channels = {frames * width} "
            f"numbers, got {data.size}"
        )
    return frame_time, data.reshape(frames, width)


def _pose_channels(
    hierarchy: _Hierarchy, data: np.ndarray, path: Path
) -> tuple[np.ndarray, np.ndarray]:
    """(frames, width) channel values -> (T, 3) root positions (the root's OFFSET plus its
    position channels, unscaled) and (T, J, 3, 3) local rotations, each joint's rotation
    channels applied left to right."""
    frames, names = len(data), hierarchy.names
    rotations = np.broadcast_to(np.eye(3), (frames, len(names), 3, 3)).copy()
    root_positions = np.broadcast_to(np.array(hierarchy.offsets[0]), (frames, 3)).copy()
    column = 0
    for index, joint_channels in enumerate(hierarchy.channels):
        for k, channel in enumerate(joint_channels):
            values = data[:, column + k]
            if channel.endswith("rotation") and channel[0] in _AXES:
                rotations[:, index] = rotations[:, index] @ _axis_matrix(
                    np.radians(values), _AXES.index(channel[0])
                )
            elif channel.endswith("position") and channel[0] in _AXES:
                if index != 0:
                    raise ValueError(
                        f"{path}: position channels on the non-root joint {names[index]!r} are not supported"
                    )
                root_positions[:, _AXES.index(channel[0])] += values
            else:
                raise ValueError(f"{path}: unknown channel {channel!r} of joint {names[index]!r}")
        column += len(joint_channels)
    return root_positions, rotations


def bvh_joint_positions(clip: BvhClip) -> np.ndarray:
    """Forward kinematics of a clip: (T, J, 3) world joint positions."""
    result = forward_kinematics(
        torch.from_numpy(clip.rotations),
        torch.from_numpy(clip.root_positions),
        torch.from_numpy(clip.offsets),
        parents=clip.parents,
    )
    return result.positions.numpy()
