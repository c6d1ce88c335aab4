"""glTF 2.0 binary (``.glb``) files of animated characters: skinned meshes on a joint hierarchy.

One file holds every person of a sample. Each character is a skeleton (one node per joint, the
root joint at the scene root), a mesh skinned to it (4 joints per vertex) and one animation with
a rotation track per joint and a translation track on the root joint, sampled at the clip's
frame rate (LINEAR). Units are metres, Y is up, as glTF requires and as the project's joints are.

The bind pose is the rest pose with every rotation the identity, so each joint node's rest
translation is its offset from its parent and its inverse bind matrix a pure translation by
minus its rest position. Rotation tracks are made sign-continuous (q and -q are one rotation, but
a player that interpolates from one to the other swings a limb the long way round between two
frames): one of the causes of the flipped limbs that other exporters show when a character
turns its back or lies down.

Skinning here is glTF's: linear blend skinning without SMPL's pose correctives (they would need
morph targets; the mesh penetration metrics and the AMASS files use the full body model).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from intermask.motion.rotations import matrix_to_quaternion

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
FLOAT, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
_COMPONENTS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@dataclass(frozen=True)
class Character:
    """One animated character.

    parents: J parent indices, parents[0] = -1; joint_names: J names; rest_joints (J, 3) bind-pose
    joint positions; rotations (T, J, 3, 3) local rotations (row 0 the global orientation);
    root_positions (T, 3) world position of joint 0; vertices (V, 3) bind-pose mesh; faces
    (F, 3), counter-clockwise seen from outside; weights (V, J) skinning weights (rows sum to 1;
    the 4 largest are kept); color (r, g, b) in [0, 1].
    """

    name: str
    parents: tuple[int, ...]
    joint_names: tuple[str, ...]
    rest_joints: np.ndarray
    rotations: np.ndarray
    root_positions: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    color: tuple[float, float, float] = (0.8, 0.8, 0.8)

    def __post_init__(self) -> None:
        joints, frames = len(self.parents), self.rotations.shape[0]
        where = f"Character {self.name!r}"
        checks = (
            (len(self.joint_names) == joints, f"{len(self.joint_names)} joint names"),
            (self.rest_joints.shape == (joints, 3), f"rest_joints {self.rest_joints.shape}"),
            (self.rotations.shape == (frames, joints, 3, 3), f"rotations {self.rotations.shape}"),
            (
                self.root_positions.shape == (frames, 3),
                f"root_positions {self.root_positions.shape}",
            ),
            (
                self.vertices.ndim == 2 and self.vertices.shape[1] == 3,
                f"vertices {self.vertices.shape}",
            ),
            (self.faces.ndim == 2 and self.faces.shape[1] == 3, f"faces {self.faces.shape}"),
            (self.weights.shape == (len(self.vertices), joints), f"weights {self.weights.shape}"),
        )
        for ok, got in checks:
            if not ok:
                raise ValueError(
                    f"{where}: inconsistent shapes for {joints} joints, {frames} frames: {got}"
                )
        if (
            frames < 1
            or self.parents[0] != -1
            or any(not 0 <= p < j for j, p in enumerate(self.parents) if j)
        ):
            raise ValueError(f"{where}: need T >= 1 frames and parents[0] = -1, parents[j] < j")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= len(self.vertices)):
            raise ValueError(f"{where}: faces index vertices outside [0, {len(self.vertices)})")
        for name in ("rest_joints", "rotations", "root_positions", "vertices", "weights"):
            if not np.isfinite(getattr(self, name)).all():
                raise ValueError(f"{where}: {name} contain NaN or infinite values")


class _Builder:
    """Accumulates the binary buffer and the JSON arrays of a glTF document."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.doc: dict[str, list] = {"bufferViews": [], "accessors": []}

    def view(self, data: bytes, target: int | None = None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        entry = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            entry["target"] = target
        self.blob.extend(data)
        self.doc["bufferViews"].append(entry)
        return len(self.doc["bufferViews"]) - 1

    def accessor(
        self, array: np.ndarray, kind: str, *, target: int | None = None, bounds: bool = False
    ) -> int:
        component = {np.float32: FLOAT, np.uint16: UNSIGNED_SHORT, np.uint32: UNSIGNED_INT}[
            array.dtype.type
        ]
        flat = np.ascontiguousarray(array).reshape(len(array), _COMPONENTS[kind])
        entry = {
            "bufferView": self.view(flat.tobytes(), target),
            "componentType": component,
            "count": len(flat),
            "type": kind,
        }
        if bounds:  # exactly the stored values: the validator compares them
            entry["min"] = [_number(v) for v in flat.min(0)]
            entry["max"] = [_number(v) for v in flat.max(0)]
        self.doc["accessors"].append(entry)
        return len(self.doc["accessors"]) - 1


def _number(value: np.generic) -> float | int:
    return int(value) if np.issubdtype(type(value), np.integer) else float(value)


def top_weights(weights: np.ndarray, count: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(V, J) weights -> (V, 4) uint16 joint indices and (V, 4) float32 weights summing to 1.

    Empty slots get weight 0 and joint 0, as the Khronos validator asks."""
    order = np.argsort(-weights, axis=1, kind="stable")[:, :count]
    kept = np.take_along_axis(weights, order, axis=1).clip(min=0.0)
    total = kept.sum(1, keepdims=True)
    if (total <= 0).any():
        raise ValueError(
            f"skinning weights: {int((total <= 0).sum())} vertices have no positive weight"
        )
    kept = (kept / total).astype(np.float32)
    order[kept <= 0] = 0
    kept[:, 0] += 1.0 - kept.sum(1)  # float32 rounding: the sum is 1 to the last bit we can
    return order.astype(np.uint16), kept


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3), (F, 3) -> (V, 3) unit area-weighted normals ((0, 1, 0) where undefined)."""
    v = vertices.astype(np.float64)
    face_normals = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    normals = np.zeros_like(v)
    for corner in range(3):
        np.add.at(normals, faces[:, corner], face_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
    return normals.astype(np.float32)


def continuous_quaternions(rotations: np.ndarray) -> np.ndarray:
    """(T, J, 3, 3) -> (T, J, 4) glTF (x, y, z, w) unit quaternions, each frame's on the same
    side as the previous frame's (q . q_prev >= 0)."""
    wxyz = matrix_to_quaternion(torch.from_numpy(np.asarray(rotations, dtype=np.float64))).numpy()
    for t in range(1, len(wxyz)):
        flip = (wxyz[t] * wxyz[t - 1]).sum(-1) < 0
        wxyz[t, flip] *= -1
    quaternion = np.concatenate((wxyz[..., 1:], wxyz[..., :1]), axis=-1)
    return quaternion / np.linalg.norm(quaternion, axis=-1, keepdims=True)


def _character(
    builder: _Builder, character: Character, index: int, times: int, nodes: list, scene: list
) -> dict:
    rest = character.rest_joints.astype(np.float64)
    first = len(nodes)
    for j, parent in enumerate(character.parents):
        translation = rest[j] - (rest[parent] if parent >= 0 else 0.0)
        nodes.append(
            {
                "name": f"{character.name}_{character.joint_names[j]}",
                "translation": translation.tolist(),
            }
        )
        if parent >= 0:
            nodes[first + parent].setdefault("children", []).append(first + j)
    scene.append(first)
    inverse_bind = np.tile(np.eye(4, dtype=np.float32), (len(rest), 1, 1))
    inverse_bind[:, 3, :3] = -rest  # column-major: the translation is the last column
    joints, weights = top_weights(character.weights)
    vertices = character.vertices.astype(np.float32)
    attributes = {
        "POSITION": builder.accessor(vertices, "VEC3", target=ARRAY_BUFFER, bounds=True),
        "NORMAL": builder.accessor(
            vertex_normals(vertices, character.faces), "VEC3", target=ARRAY_BUFFER
        ),
        "JOINTS_0": builder.accessor(joints, "VEC4", target=ARRAY_BUFFER),
        "WEIGHTS_0": builder.accessor(weights, "VEC4", target=ARRAY_BUFFER),
    }
    indices = builder.accessor(
        character.faces.astype(np.uint32).reshape(-1), "SCALAR", target=ELEMENT_ARRAY_BUFFER
    )
    mesh_node = len(nodes)
    nodes.append({"name": f"{character.name}_mesh", "mesh": index, "skin": index})
    scene.append(mesh_node)
    skin = {
        "name": character.name,
        "joints": list(range(first, first + len(rest))),
        "skeleton": first,
        "inverseBindMatrices": builder.accessor(inverse_bind, "MAT4"),
    }
    mesh = {
        "name": character.name,
        "primitives": [{"attributes": attributes, "indices": indices, "material": index}],
    }
    material = {
        "name": character.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [*map(float, character.color), 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 0.8,
        },
    }
    quaternions = continuous_quaternions(character.rotations).astype(np.float32)
    samplers = [
        {
            "input": times,
            "output": builder.accessor(character.root_positions.astype(np.float32), "VEC3"),
            "interpolation": "LINEAR",
        }
    ]
    channels = [{"sampler": 0, "target": {"node": first, "path": "translation"}}]
    for j in range(len(rest)):
        samplers.append(
            {
                "input": times,
                "output": builder.accessor(quaternions[:, j], "VEC4"),
                "interpolation": "LINEAR",
            }
        )
        channels.append({"sampler": j + 1, "target": {"node": first + j, "path": "rotation"}})
    animation = {"name": character.name, "samplers": samplers, "channels": channels}
    return {"skin": skin, "mesh": mesh, "material": material, "animation": animation}


def glb_bytes(characters: Sequence[Character], *, fps: float) -> bytes:
    """The .glb file of characters (all with the same frame count), at fps."""
    if not characters:
        raise ValueError("glb_bytes: no characters to write")
    if not fps > 0:
        raise ValueError(f"glb_bytes: fps must be > 0, got {fps}")
    frames = {c.rotations.shape[0] for c in characters}
    if len(frames) != 1:
        raise ValueError(f"glb_bytes: the characters have different frame counts {sorted(frames)}")
    builder = _Builder()
    times = builder.accessor(
        (np.arange(frames.pop()) / fps).astype(np.float32), "SCALAR", bounds=True
    )
    nodes: list[dict] = []
    scene: list[int] = []
    parts = [_character(builder, c, k, times, nodes, scene) for k, c in enumerate(characters)]
    document = {
        "asset": {"version": "2.0", "generator": "intermask"},
        "scene": 0,
        "scenes": [{"name": "interaction", "nodes": scene}],
        "nodes": nodes,
        "meshes": [p["mesh"] for p in parts],
        "skins": [p["skin"] for p in parts],
        "materials": [p["material"] for p in parts],
        "animations": [p["animation"] for p in parts],
        **builder.doc,
        "buffers": [{"byteLength": 0}],
    }
    while len(builder.blob) % 4:
        builder.blob.append(0)
    document["buffers"][0]["byteLength"] = len(builder.blob)
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(builder.blob)
    return b"".join(
        (
            struct.pack("<III", GLB_MAGIC, 2, total),
            struct.pack("<II", len(text), CHUNK_JSON),
            text,
            struct.pack("<II", len(builder.blob), CHUNK_BIN),
            bytes(builder.blob),
        )
    )


def write_glb(characters: Sequence[Character], path: str | Path, *, fps: float) -> Path:
    """Write the .glb of characters to path (see glb_bytes)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(glb_bytes(characters, fps=fps))
    return path


def read_glb(path: str | Path) -> tuple[dict, bytes]:
    """A .glb file -> (its JSON document, its binary chunk)."""
    data = Path(path).read_bytes()
    magic, version, total = struct.unpack_from("<III", data)
    if magic != GLB_MAGIC or version != 2 or total != len(data):
        raise ValueError(
            f"{path}: not a glTF 2.0 binary file (magic {magic:#x}, version {version})"
        )
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != CHUNK_JSON:
        raise ValueError(f"{path}: the first chunk is not JSON")
    document = json.loads(data[20 : 20 + length])
    offset = 20 + length
    blob = b""
    if offset < len(data):
        blob_length, _ = struct.unpack_from("<II", data, offset)
        blob = data[offset + 8 : offset + 8 + blob_length]
    return document, blob


def accessor_array(document: dict, blob: bytes, index: int) -> np.ndarray:
    """The data of accessor ``index`` as a (count, components) array."""
    accessor = document["accessors"][index]
    view = document["bufferViews"][accessor["bufferView"]]
    dtype = {FLOAT: np.float32, UNSIGNED_SHORT: np.uint16, UNSIGNED_INT: np.uint32}[
        accessor["componentType"]
    ]
    components = _COMPONENTS[accessor["type"]]
    start = view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
    array = np.frombuffer(blob, dtype=dtype, count=accessor["count"] * components, offset=start)
    return array.reshape(accessor["count"], components)


def _limb(start: np.ndarray, end: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """An octahedral limb from start to end: 6 vertices, 8 outward faces."""
    axis = end - start
    length = float(np.linalg.norm(axis))
    direction = axis / length if length > 1e-9 else np.array([0.0, 1.0, 0.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(direction, helper)
    u /= np.linalg.norm(u)
    w = np.cross(direction, u)
    middle = start + 0.25 * axis
    ring = [middle + width * (np.cos(a) * u + np.sin(a) * w) for a in np.arange(4) * np.pi / 2]
    vertices = np.array([start, *ring, end if length > 1e-9 else start + width * direction])
    faces = []
    for k in range(4):
        n = (k + 1) % 4
        faces += [(0, 1 + n, 1 + k), (5, 1 + k, 1 + n)]
    return vertices, np.array(faces)


def limb_character(
    name: str,
    parents: tuple[int, ...],
    joint_names: tuple[str, ...],
    offsets: np.ndarray,
    rotations: np.ndarray,
    root_positions: np.ndarray,
    *,
    color: tuple[float, float, float] = (0.8, 0.8, 0.8),
    head: int | None = None,
) -> Character:
    """A skeleton with simple limb meshes (an octahedron per bone, rigid on its parent joint;
    a larger one above ``head``): what a .glb holds when no body model is given. offsets (J, 3)
    rest offsets from the parent (row 0 ignored); rotations (T, J, 3, 3); root_positions (T, 3)."""
    rest = np.zeros((len(parents), 3))
    for j in range(1, len(parents)):
        rest[j] = rest[parents[j]] + offsets[j]
    pieces, faces, weights = [], [], []
    count = 0
    for j in range(1, len(parents)):
        length = float(np.linalg.norm(offsets[j]))
        vertices, limb_faces = _limb(rest[parents[j]], rest[j], min(0.04, 0.15 * length + 0.005))
        pieces.append(vertices)
        faces.append(limb_faces + count)
        weight = np.zeros((len(vertices), len(parents)))
        weight[:, parents[j]] = 1.0
        weights.append(weight)
        count += len(vertices)
    if head is not None:
        top = rest[head] + 0.1 * (rest[head] - rest[parents[head]]) / max(
            np.linalg.norm(rest[head] - rest[parents[head]]), 1e-9
        )
        vertices, limb_faces = _limb(
            rest[head] - (top - rest[head]), top + (top - rest[head]), 0.09
        )
        pieces.append(vertices)
        faces.append(limb_faces + count)
        weight = np.zeros((len(vertices), len(parents)))
        weight[:, head] = 1.0
        weights.append(weight)
    return Character(
        name=name,
        parents=parents,
        joint_names=joint_names,
        rest_joints=rest,
        rotations=np.asarray(rotations, dtype=np.float64),
        root_positions=np.asarray(root_positions, dtype=np.float64),
        vertices=np.concatenate(pieces),
        faces=np.concatenate(faces),
        weights=np.concatenate(weights),
        color=color,
    )
