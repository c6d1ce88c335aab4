"""Inter-X reader for the processed release used by the generators.

    <root>/motions/{train,val,test}.h5        one float32 (T, 56, 6) dataset per clip name
    <root>/texts_processed/<name>.txt         lines "caption#tok/POS tok/POS ...#0.0#0.0"
    <root>/splits/{train,val,test}.txt        clip names
    <root>/annots/interaction_order.pkl       optional: name -> 0 if P1 acts first, 1 if P2
    <root>/interaction_meta.json              optional (synthetic data): action names and actors

Clips are read once at construction into one contiguous array; the (T, 56, 6) per-person
representation (6D rotations + [translation, velocity]) is computed per item on the crop, so the
last frame's velocity is 0 as in the reference.

Length rule (reference ``Text2MotionDatasetV2HHI``): clips with 24 <= T < 1000 frames are kept
(others go to the logged skip list). Per item, L = floor(T / 4) * 4, minus one more unit of 4 with
p = 1/3 (``length_jitter``, the reference's 'double' coin), capped at ``floor(max_length / 4) * 4``
= 148 for max_length 150. Lengths are therefore multiples of 4 in [20, 148], padded to max_length.
The reference caps at 150 (not a multiple of 4; its VQ then decodes 148 frames) and keeps the
first frames of a long clip; ``crop="start"`` reproduces the latter, the default ``"random"`` draws
the crop anywhere in the clip.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np
import torch
from einops import rearrange

from intermask.data.common import (
    check_motion_array,
    read_caption_lines,
    read_id_list,
    read_interaction_meta,
    single_threaded,
)
from intermask.data.errors import DataError, SkippedClip
from intermask.data.normalization import Normalizer
from intermask.data.reader import ClipReader, Mode
from intermask.motion.interx import NUM_ROWS, RAW_CHANNELS, person_representation, split_persons
from intermask.utils.plain_pickle import UnsafePickle, load_plain_pickle

Crop = Literal["random", "start"]
FEATURE_SHAPE = (NUM_ROWS, RAW_CHANNELS)  # (56, 6) per person
NAME_PATTERN = re.compile(r"^G(\d{3})T(\d{3})A(\d{3})R(\d{3})$")


@dataclass(frozen=True)
class InterXLayout:
    root: Path

    def motion_file(self, split: str) -> Path:
        return self.root / "motions" / f"{split}.h5"

    def caption_file(self, name: str) -> Path:
        return self.root / "texts_processed" / f"{name}.txt"

    def split_file(self, split: str) -> Path:
        return self.root / "splits" / f"{split}.txt"

    @property
    def order_file(self) -> Path:
        return self.root / "annots" / "interaction_order.pkl"


@dataclass(frozen=True)
class Caption:
    text: str
    tokens: str  # "word/POS word/POS ..." for the Inter-X (GloVe) evaluator


def read_captions(path: Path) -> list[Caption]:
    """Parse ``caption#tokens#from#to`` lines; DataError (file and line) when malformed."""
    captions = []
    for number, line in enumerate(read_caption_lines(path), start=1):
        parts = line.split("#")
        if len(parts) < 2 or not parts[0].strip():
            raise DataError(
                f"{path}: line {number}: expected 'caption#tok/POS ...#0.0#0.0', got {line!r}"
            )
        try:
            tags = [0.0 if np.isnan(float(p)) else float(p) for p in parts[2:4]]
        except ValueError as err:
            raise DataError(
                f"{path}: line {number}: time tags must be numbers, got {parts[2:4]}"
            ) from err
        if any(tags):
            raise DataError(
                f"{path}: line {number}: time-tagged captions are not supported (tags {tags}, expected 0.0)"
            )
        captions.append(Caption(parts[0].strip(), parts[1].strip()))
    return captions


def read_h5_clip(file: h5py.File, path: Path, name: str) -> np.ndarray:
    if name not in file:
        raise DataError(f"{path}: no dataset named {name!r}")
    try:
        array = file[name][()]
    except (OSError, KeyError, TypeError, ValueError) as err:
        raise DataError(f"{path}: cannot read dataset {name!r} ({err})") from err
    return check_motion_array(np.asarray(array), Path(f"{path}[{name}]"), trailing=FEATURE_SHAPE)


def open_h5(path: Path) -> h5py.File:
    if not path.is_file():
        raise DataError(f"{path}: motion file not found")
    try:
        return h5py.File(path, "r")
    except OSError as err:
        raise DataError(f"{path}: cannot open as HDF5 ({err})") from err


def read_order(path: Path) -> dict[str, int] | None:
    if not path.is_file():
        return None
    try:
        order = load_plain_pickle(path)  # a dataset file: read without running code
    except UnsafePickle as err:
        raise DataError(f"{err} (expected a pickled dict name -> 0|1)") from err
    except (OSError, ValueError) as err:
        raise DataError(f"{path}: expected a pickled dict name -> 0|1 ({err})") from err
    try:
        return {str(k): int(v) for k, v in order.items()}
    except (AttributeError, TypeError, ValueError) as err:
        raise DataError(f"{path}: expected a pickled dict name -> 0|1 ({err!r})") from err


def person_features(raw: torch.Tensor) -> torch.Tensor:
    """(T, 56, 6) release rows -> (2, T, 56, 6) per-person representation."""
    axis_angle = rearrange(split_persons(raw), "t p r c -> p t r c")
    return person_representation(axis_angle)


class InterXDataset(ClipReader):
    """Inter-X clips of one split; items mirror ``InterHumanDataset`` with motion (2, max_length, 56, 6).

    Interaction items: {"motion", "length", "caption", "tokens", "id", "persons", "start" (crop
    start frame; with id, length and persons it fixes each person's features)} plus "action",
    "action_id" (from the name or interaction_meta.json) and "actor" (interaction_order.pkl or the
    meta file) when available. Window items: {"motion": (window, 56, 6), "id", "person", "start"}; with
    ``window_persons=2`` the motion is (window, 2, 56, 6) and "person" is 0.
    No mirroring (the reference has none for Inter-X).
    """

    kind = "interx"
    feature_shape = FEATURE_SHAPE
    default_max_length = 150  # frames (InterMask's Inter-X setting)
    default_min_length = 24  # the reference's length rule (module docstring)
    default_swap_persons = False  # Inter-X keeps its annotated person order
    default_normalize = False  # the reference trains on the raw representation

    def __init__(
        self,
        *,
        root: str | Path,
        split: str,
        mode: Mode = "interaction",
        max_length: int = default_max_length,
        min_length: int = default_min_length,
        max_frames: int = 1000,
        unit_length: int = 4,
        length_jitter: bool = True,
        crop: Crop = "random",
        window: int = 64,
        window_persons: int = 1,
        stride: int = 10,
        swap_persons: bool = default_swap_persons,
        normalizer: Normalizer | None = None,
        seed: int = 3407,
        epoch: int = 0,
    ):
        if crop not in ("random", "start"):
            raise ValueError(f"crop must be 'random' or 'start', got {crop!r}")
        if not (unit_length >= 1 and 2 * unit_length <= min_length and unit_length <= max_length):
            raise ValueError(
                f"need 1 <= unit_length, 2 * unit_length <= min_length ({min_length}), got {unit_length}"
            )
        self.layout = InterXLayout(Path(root))
        self.crop, self.max_frames = crop, max_frames
        self.unit_length, self.length_jitter = unit_length, length_jitter
        super().__init__(
            root=root,
            split=split,
            mode=mode,
            max_length=max_length,
            min_length=min_length,
            window=window,
            stride=stride,
            window_persons=window_persons,
            swap_persons=swap_persons,
            normalizer=normalizer,
            seed=seed,
            epoch=epoch,
        )

    @property
    def split_file(self) -> Path:
        return self.layout.split_file(self.split)

    def _load(self) -> None:
        if not self.layout.root.is_dir():
            raise DataError(
                f"{self.layout.root}: dataset root not found (expected the Inter-X folder)"
            )
        listed = read_id_list(self.split_file, what=f"{self.split} split")
        h5_path = self.layout.motion_file(self.split)
        self.skipped: list[SkippedClip] = []
        ids, motions, captions = [], [], []
        with open_h5(h5_path) as file:
            for name in listed:
                motion = read_h5_clip(file, h5_path, name)
                if not self.min_length <= len(motion) < self.max_frames:
                    reason = f"{len(motion)} frames, outside [{self.min_length}, {self.max_frames})"
                    self.skipped.append(SkippedClip(name, reason))
                    continue
                captions.append(read_captions(self.layout.caption_file(name)))
                ids.append(name)
                motions.append(motion)
        self.clip_ids: list[str] = ids
        self._check_not_empty(len(listed), f"length outside [{self.min_length}, {self.max_frames})")
        self.captions: list[list[Caption]] = captions
        self.frames = np.array([len(m) for m in motions], dtype=np.int64)
        self._offsets = np.concatenate(([0], np.cumsum(self.frames)))
        self._raw = np.concatenate(motions, axis=0)  # (sum T, 56, 6)
        self._read_meta()

    def _read_meta(self) -> None:
        """Action label per clip (meta file, else the name's Aaaa field) and actor (meta file, else
        interaction_order.pkl); each is None when no clip can provide it."""
        meta = read_interaction_meta(self.layout.root)
        order = read_order(self.layout.order_file)
        meta_file = self.layout.root / "interaction_meta.json"
        if meta is not None:
            missing = [n for n in self.clip_ids if n not in meta]
            if missing:
                raise DataError(
                    f"{meta_file}: no entry for clips {missing[:5]} ({len(missing)} missing)"
                )
            self.actions = [(meta[n].action, meta[n].action_id) for n in self.clip_ids]
            self.actors = [meta[n].actor for n in self.clip_ids]
            return
        matches = [NAME_PATTERN.match(n) for n in self.clip_ids]
        self.actions = None
        if all(matches):
            self.actions = [(f"A{int(m.group(3)):03d}", int(m.group(3))) for m in matches]
        self.actors = None
        if order is not None:
            missing = [n for n in self.clip_ids if n not in order]
            if missing:
                raise DataError(
                    f"{self.layout.order_file}: no entry for clips {missing[:5]} ({len(missing)} missing)"
                )
            self.actors = [order[n] + 1 for n in self.clip_ids]

    def _build_windows(self) -> None:
        # Sequence P c + p is person p of clip c (P = 2), or clip c itself with two-person
        # windows (P = 1); features are computed per item from the stored release rows.
        per_clip = 1 if self.window_persons == 2 else 2
        lengths = [int(n) for n in self.frames for _ in range(per_clip)]
        short = [
            SkippedClip(i, f"fewer than {self.window} frames")
            for i, n in zip(self.clip_ids, self.frames, strict=True)
            if n < self.window
        ]
        self._index_windows(lengths, short)

    def clip_raw(self, clip: int) -> torch.Tensor:
        """(T, 56, 6) release rows of a clip."""
        return torch.from_numpy(self._raw[self._offsets[clip] : self._offsets[clip + 1]])

    def clip_features(
        self, clip: int, *, start: int = 0, frames: int | None = None
    ) -> torch.Tensor:
        """Un-normalized (2, T', 56, 6) representation of frames ``start:start+frames``."""
        raw = self.clip_raw(clip)
        stop = len(raw) if frames is None else start + frames
        with single_threaded():
            return person_features(raw[start:stop])

    def stats_sequences(self) -> Iterator[torch.Tensor]:
        """(2, T, 56, 6) representations of every whole clip, for optional statistics."""
        for clip in range(len(self.clip_ids)):
            yield self.clip_features(clip)

    def _interaction_count(self) -> int:
        return len(self.clip_ids)

    def _window_item(self, index: int) -> dict[str, Any]:
        seq, start = int(self.windows.sequence[index]), int(self.windows.start[index])
        if self.window_persons == 2:
            clip, person = seq, -1
            pair = self.clip_features(clip, start=start, frames=self.window)  # (2, W, 56, 6)
            motion = rearrange(pair, "p t j c -> t p j c")
        else:
            clip, person = divmod(seq, 2)
            motion = self.clip_features(clip, start=start, frames=self.window)[person]
        return {
            "motion": self._normalize(motion),
            "id": self.clip_ids[clip],
            "person": person + 1,
            "start": start,
        }

    def crop_length(self, frames: int, rng: np.random.Generator) -> tuple[int, int]:
        """(uncapped, final) crop lengths for a clip of ``frames`` frames (see the module docstring)."""
        unit = self.unit_length
        jitter = (
            self.length_jitter and unit < 10 and int(rng.integers(3)) == 2
        )  # reference: 'double' w.p. 1/3
        uncapped = (frames // unit - (1 if jitter else 0)) * unit
        return uncapped, min(uncapped, (self.max_length // unit) * unit)

    def _interaction_item(self, index: int, rng: np.random.Generator) -> dict[str, Any]:
        frames = int(self.frames[index])
        uncapped, length = self.crop_length(frames, rng)
        span = uncapped if self.crop == "start" else length
        start = int(rng.integers(0, frames - span + 1))
        swap = self.swap_persons and bool(rng.random() < 0.5)
        caption = self.captions[index][int(rng.integers(len(self.captions[index])))]
        features = self.clip_features(index, start=start, frames=length)  # (2, L, 56, 6)
        persons = [1, 2]
        if swap:
            features, persons = features.flip(0), [2, 1]
        motion = features.new_zeros(2, self.max_length, *FEATURE_SHAPE)
        motion[:, :length] = self._normalize(features)
        item: dict[str, Any] = {
            "motion": motion,
            "length": length,
            "caption": caption.text,
            "tokens": caption.tokens,
            "id": self.clip_ids[index],
            "persons": torch.tensor(persons),
            "start": start,
        }
        if self.actions is not None:
            item.update(action=self.actions[index][0], action_id=self.actions[index][1])
        if self.actors is not None:
            item["actor"] = persons.index(self.actors[index]) + 1
        return item
