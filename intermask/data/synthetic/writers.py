"""Write synthetic clips in the two official layouts (see docs/data-formats.md).

InterHuman: ``annots/<id>.txt``, ``motions_processed/person{1,2}/<id>.npy`` (T, 492) float32 Z-up,
``split/{train,val,test}.txt``, ``ignore_list.txt``.
Inter-X (processed release): ``motions/{train,val,test}.h5`` with one (T, 56, 6) float32 dataset
per ``GgggTtttAaaaRrrr`` name, ``texts_processed/<name>.txt``, ``splits/{train,val,test}.txt``,
``annots/interaction_order.pkl``.
Both get ``interaction_meta.json`` (action, action id, actor) and a README.txt. Files are written
byte-reproducibly: ``np.save``, HDF5 without timestamps, JSON with sorted keys, fixed pickle protocol.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import h5py
import numpy as np
import torch

from intermask.data.synthetic.captions import processed_line
from intermask.data.synthetic.clips import SynthClip
from intermask.motion.interhuman import yup_to_zup
from intermask.motion.rotations import matrix_to_axis_angle, matrix_to_rot6d

SPLITS = ("train", "val", "test")
META_FILE = "interaction_meta.json"
META_FORMAT = "synthetic-v1"
_HAND_ROTATIONS = 30  # raw rotations of joints 22..51: identity (rigid hands)
_INTERX_ROWS = 56
_PICKLE_PROTOCOL = 4
# Y-up -> Z-up as a rotation: (x, y, z) -> (x, -z, y).
_YUP_TO_ZUP = torch.tensor(
    [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]], dtype=torch.float64
)


def interhuman_raw(clip: SynthClip, person: int) -> np.ndarray:
    """(T, 492) float32 raw frame of person 0/1: 62 Z-up joint positions, then 6D ("rows") local
    rotations of joints 1..51 (body joints 1..21 as posed, hand joints identity)."""
    positions = yup_to_zup(
        torch.cat((clip.positions[person], clip.hands[person]), dim=1)
    )  # (T, 62, 3)
    body = matrix_to_rot6d(clip.local_rotations[person, :, 1:])  # (T, 21, 6)
    frames = body.shape[0]
    hands = matrix_to_rot6d(torch.eye(3, dtype=body.dtype)).expand(frames, _HAND_ROTATIONS, 6)
    raw = torch.cat(
        (positions.reshape(frames, -1), body.reshape(frames, -1), hands.reshape(frames, -1)), dim=1
    )
    return raw.numpy().astype(np.float32)


def interx_raw(clip: SynthClip) -> np.ndarray:
    """(T, 56, 6) float32 processed Inter-X array: per person rows 0..54 axis-angle (global
    orientation in the Z-up world, 21 body joints, jaw/eyes/hands zero), row 55 the pelvis
    position; each person floored (lowest joint at z = 0), then both moved so that person 1's
    frame-0 pelvis is above the origin. The height is kept: only the ground plane is shifted."""
    persons = []
    for person in range(2):
        rows = torch.zeros(clip.frames, _INTERX_ROWS, 3, dtype=torch.float64)
        rows[:, 0] = matrix_to_axis_angle(_YUP_TO_ZUP @ clip.local_rotations[person, :, 0])
        rows[:, 1:22] = matrix_to_axis_angle(clip.local_rotations[person, :, 1:22])
        joints = yup_to_zup(clip.positions[person])
        rows[:, 55] = joints[:, 0]
        rows[:, 55, 2] -= joints[..., 2].min()
        persons.append(rows)
    origin = persons[0][0, 55].clone()
    origin[2] = 0.0
    for rows in persons:
        rows[:, 55] -= origin
    return torch.cat(persons, dim=-1).numpy().astype(np.float32)


def interx_name(index: int, action_id: int) -> str:
    """Inter-X style sample name GgggTtttAaaaRrrr (group, take, action, repetition) of clip `index`."""
    group, take, repetition = 1 + index // 1000, (index % 1000) // 10, index % 10
    return f"G{group:03d}T{take:03d}A{action_id:03d}R{repetition:03d}"


def _write_lines(path: Path, lines: list[str]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(f"{line}\n" for line in lines), encoding="utf-8")


def _meta(clips: dict[str, SynthClip], actions: tuple[str, ...]) -> str:
    entries = {
        clip_id: {"action": clip.action, "action_id": clip.action_id, "actor": clip.actor}
        for clip_id, clip in clips.items()
    }
    return json.dumps(
        {"format": META_FORMAT, "actions": list(actions), "clips": entries},
        sort_keys=True,
        indent=1,
    )


class InterHumanWriter:
    """Streams clips into the InterHuman layout under `root`."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.splits: dict[str, list[str]] = {split: [] for split in SPLITS}
        self.clips: dict[str, SynthClip] = {}
        for person in (1, 2):
            (root / "motions_processed" / f"person{person}").mkdir(parents=True, exist_ok=True)

    def add(self, *, index: int, clip: SynthClip, split: str) -> str:
        clip_id = str(index + 1)  # InterHuman ids are 1-based integers
        for person in (0, 1):
            np.save(
                self.root / "motions_processed" / f"person{person + 1}" / f"{clip_id}.npy",
                interhuman_raw(clip, person),
            )
        _write_lines(self.root / "annots" / f"{clip_id}.txt", list(clip.captions))
        self.splits[split].append(clip_id)
        self.clips[clip_id] = _light(clip)
        return clip_id

    def close(self, actions: tuple[str, ...]) -> None:
        for split, ids in self.splits.items():
            _write_lines(self.root / "split" / f"{split}.txt", ids)
        _write_lines(self.root / "ignore_list.txt", [])
        (self.root / META_FILE).write_text(_meta(self.clips, actions), encoding="utf-8")


class InterXWriter:
    """Streams clips into the processed Inter-X layout under `root`."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.splits: dict[str, list[str]] = {split: [] for split in SPLITS}
        self.clips: dict[str, SynthClip] = {}
        (root / "motions").mkdir(parents=True, exist_ok=True)
        # track_times=False on every dataset keeps the files byte-identical across runs.
        self.files = {split: h5py.File(root / "motions" / f"{split}.h5", "w") for split in SPLITS}

    def add(self, *, index: int, clip: SynthClip, split: str) -> str:
        name = interx_name(index, clip.action_id)
        self.files[split].create_dataset(name, data=interx_raw(clip), track_times=False)
        _write_lines(
            self.root / "texts_processed" / f"{name}.txt",
            [processed_line(c) for c in clip.captions],
        )
        self.splits[split].append(name)
        self.clips[name] = _light(clip)
        return name

    def close(self, actions: tuple[str, ...]) -> None:
        for handle in self.files.values():
            handle.close()
        for split, names in self.splits.items():
            _write_lines(self.root / "splits" / f"{split}.txt", names)
        order = {name: 0 if clip.actor == 1 else 1 for name, clip in self.clips.items()}
        (self.root / "annots").mkdir(parents=True, exist_ok=True)
        (self.root / "annots" / "interaction_order.pkl").write_bytes(
            pickle.dumps(order, protocol=_PICKLE_PROTOCOL)
        )
        (self.root / META_FILE).write_text(_meta(self.clips, actions), encoding="utf-8")


def _light(clip: SynthClip) -> SynthClip:
    """Keep the labels, drop the motion tensors (the writer only needs labels at close)."""
    empty = torch.empty(0)
    return clip._replace(positions=empty, hands=empty, local_rotations=empty, offsets=empty)
