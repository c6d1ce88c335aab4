"""Tiny hand-made datasets in the official InterHuman and Inter-X layouts, for reader tests.

Motions are plausible enough for the canonicalization to be well defined (upright skeletons that
walk, hips horizontal), random otherwise. Everything is deterministic per seed.
"""

from __future__ import annotations

import json
import pickle
from collections.abc import Mapping, Sequence
from pathlib import Path

import h5py
import numpy as np
import torch

from intermask.motion.interhuman import RAW_DIM, yup_to_zup
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import axis_angle_to_matrix, axis_angle_to_rot6d
from intermask.motion.skeleton import NUM_JOINTS, REST_OFFSETS

CAPTIONS = (
    "one person waves with the left hand and the other turns clockwise.",
    "Two people greet; the right person walks to the left.",
    "a person pushes the other, who steps back counterclockwise.",
)


def person_motion(
    rng: np.random.Generator, frames: int, *, yaw: float, start_xz: tuple[float, float]
):
    """(T, 22, 3) Y-up positions and (T, 21, 3) local axis-angle of a walking, wiggling body."""
    t = torch.arange(frames, dtype=torch.float64)[:, None]
    amp = torch.from_numpy(rng.uniform(0.05, 0.3, size=(1, NUM_JOINTS, 3)))
    phase = torch.from_numpy(rng.uniform(0, 2 * np.pi, size=(1, NUM_JOINTS, 3)))
    local_aa = amp * torch.sin(0.15 * t[..., None] + phase)  # (T, 22, 3)
    local_aa[:, 0] = 0.0
    local_aa[:, 0, 1] = yaw + 0.01 * t[:, 0]  # root yaw about +Y, slowly turning
    speed = rng.uniform(0.0, 0.02)
    heading = torch.tensor([np.sin(yaw), 0.0, np.cos(yaw)], dtype=torch.float64)
    root = torch.tensor([start_xz[0], 0.95, start_xz[1]], dtype=torch.float64) + speed * t * heading
    fk = forward_kinematics(axis_angle_to_matrix(local_aa), root, REST_OFFSETS.double())
    positions = fk.positions
    positions[..., 1] -= positions[..., 1].min() - rng.uniform(
        -0.1, 0.1
    )  # floor not at 0 in the raw data
    return positions, local_aa[:, 1:]


def interhuman_raw(
    rng: np.random.Generator, frames: int, *, yaw: float, start_xz: tuple[float, float]
) -> np.ndarray:
    """(T, 492) float32 raw InterHuman rows (Z-up), hand joints near the wrists."""
    positions, local_aa = person_motion(rng, frames, yaw=yaw, start_xz=start_xz)
    raw = np.zeros((frames, RAW_DIM), dtype=np.float64)
    hands = positions[:, [20] * 20 + [21] * 20] + torch.from_numpy(
        rng.normal(0, 0.03, size=(frames, 40, 3))
    )
    raw[:, :186] = yup_to_zup(torch.cat((positions, hands), dim=1)).reshape(frames, -1).numpy()
    rot6d = axis_angle_to_rot6d(local_aa).reshape(frames, -1).numpy()  # (T, 126)
    identity6d = np.tile([1.0, 0.0, 0.0, 1.0, 0.0, 0.0], 30)
    raw[:, 186:312] = rot6d
    raw[:, 312:] = identity6d
    return raw.astype(np.float32)


def write_interhuman(
    root: Path,
    *,
    splits: Mapping[str, Sequence[int]] = {
        "train": (40, 80, 320),
        "val": (30, 60),
        "test": (50, 70),
    },  # noqa: B006
    seed: int = 0,
    captions: Sequence[str] = CAPTIONS,
    ignore: Sequence[str] = (),
    ignore_in_split_dir: bool = False,
    trailing_newline: bool = False,
    meta: bool = False,
) -> dict[str, list[str]]:
    """Write an InterHuman-layout dataset; ``splits`` gives the frame count of every clip.

    Clip ids are consecutive integers as in the release. Returns {split: [ids]}.
    """
    rng = np.random.default_rng(seed)
    for sub in ("annots", "motions_processed/person1", "motions_processed/person2", "split"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    ids: dict[str, list[str]] = {}
    meta_clips = {}
    counter = 0
    for split, lengths in splits.items():
        ids[split] = []
        for frames in lengths:
            clip_id = str(counter)
            counter += 1
            yaw1, yaw2 = rng.uniform(-np.pi, np.pi, size=2)
            p1 = interhuman_raw(rng, frames, yaw=yaw1, start_xz=tuple(rng.uniform(-2, 2, 2)))
            p2 = interhuman_raw(rng, frames, yaw=yaw2, start_xz=tuple(rng.uniform(-2, 2, 2)))
            np.save(root / "motions_processed/person1" / f"{clip_id}.npy", p1)
            np.save(root / "motions_processed/person2" / f"{clip_id}.npy", p2)
            (root / "annots" / f"{clip_id}.txt").write_text("\n".join(captions) + "\n")
            ids[split].append(clip_id)
            meta_clips[clip_id] = {
                "action": f"act{counter % 3}",
                "action_id": counter % 3,
                "actor": 1 + counter % 2,
            }
        text = "\n".join(ids[split]) + ("\n" if trailing_newline else "")
        (root / "split" / f"{split}.txt").write_text(text)
    ignore_path = root / ("split" if ignore_in_split_dir else "") / "ignore_list.txt"
    ignore_path.write_text("".join(f"{i}\n" for i in ignore))
    if meta:
        info = {"format": "synthetic-v1", "actions": ["act0", "act1", "act2"], "clips": meta_clips}
        (root / "interaction_meta.json").write_text(json.dumps(info))
    return ids


def interx_name(index: int, action: int) -> str:
    return f"G{index // 100:03d}T{index % 100:03d}A{action:03d}R000"


def interx_raw(rng: np.random.Generator, frames: int) -> np.ndarray:
    """(T, 56, 6) float32 processed Inter-X rows: axis-angle rows 0..54, translation row 55."""
    raw = np.zeros((frames, 56, 6), dtype=np.float64)
    t = np.arange(frames)[:, None]
    for person in range(2):
        channels = slice(3 * person, 3 * person + 3)
        amp = rng.uniform(0.05, 0.4, size=(1, 55, 3))
        raw[:, :55, channels] = amp * np.sin(
            0.1 * t[..., None] + rng.uniform(0, 6, size=(1, 55, 3))
        )
        raw[:, 22:25, channels] = 0.0  # jaw and eyes are zeroed in the release
        start = rng.uniform(-1.5, 1.5, size=3) * np.array([1.0, 1.0, 0.0])
        raw[:, 55, channels] = (
            start + np.array([0.0, 0.0, 0.9]) + 0.01 * t * rng.normal(size=(1, 3))
        )
    return raw.astype(np.float32)


def write_interx(
    root: Path,
    *,
    splits: Mapping[str, Sequence[int]] = {
        "train": (24, 60, 200),
        "val": (30, 44),
        "test": (40, 1000),
    },  # noqa: B006
    seed: int = 0,
    captions: Sequence[str] = CAPTIONS,
    order: bool = True,
    meta: bool = False,
) -> dict[str, list[str]]:
    """Write an Inter-X processed-layout dataset; ``splits`` gives the frame count of every clip."""
    rng = np.random.default_rng(seed)
    for sub in ("motions", "texts_processed", "splits", "annots"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    ids: dict[str, list[str]] = {}
    orders, meta_clips, counter = {}, {}, 0
    for split, lengths in splits.items():
        ids[split] = []
        with h5py.File(root / "motions" / f"{split}.h5", "w") as f:
            for frames in lengths:
                name = interx_name(counter, counter % 40)
                counter += 1
                f.create_dataset(name, data=interx_raw(rng, frames))
                lines = [
                    f"{c}#{' '.join(w + '/NOUN' for w in c.split())}#0.0#0.0" for c in captions
                ]
                (root / "texts_processed" / f"{name}.txt").write_text("\n".join(lines) + "\n")
                orders[name] = counter % 2
                meta_clips[name] = {
                    "action": f"act{counter % 40}",
                    "action_id": (counter - 1) % 40,
                    "actor": 1 + counter % 2,
                }
                ids[split].append(name)
        (root / "splits" / f"{split}.txt").write_text("\n".join(ids[split]) + "\n")
    if order:
        with open(root / "annots" / "interaction_order.pkl", "wb") as fh:
            pickle.dump(orders, fh)
    if meta:
        info = {
            "format": "synthetic-v1",
            "actions": [f"act{i}" for i in range(40)],
            "clips": meta_clips,
        }
        (root / "interaction_meta.json").write_text(json.dumps(info))
    return ids
