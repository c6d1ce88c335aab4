"""InterHuman reader for the official layout (the README's Data section).

    <root>/annots/<id>.txt                       captions, one per line
    <root>/motions_processed/person{1,2}/<id>.npy float32 (T, 492), Z-up
    <root>/split/{train,val,test}.txt            clip ids
    <root>/ignore_list.txt or <root>/split/ignore_list.txt

Every clip of the split is read once at construction; only the 22 body positions and 21 body
rotations (192 of the 492 columns) are kept, in one contiguous array so that DataLoader workers
share it copy-on-write. The 262-d features are computed per item (crop and reference person are
random, and canonicalization depends on both) by ``intermask.motion.interhuman``.

Item modes:
    "interaction": {"motion": (2, max_length, 262), "length", "caption", "id", "mirrored",
                    "persons", "start" (crop start frame), "reference" (the file person, 1 or 2,
                    the pair is canonicalized on), and "action", "action_id", "actor" when
                    interaction_meta.json exists}. id, mirrored, start, reference and persons
                    fix the features of each person (what Inter-M's token cache keys on).
    "window":      {"motion": (window, 262), "id", "person", "mirrored", "start"}: single-person
                   windows over whole canonical sequences (person 2 in person 1's frame); with
                   ``window_persons=2`` two-person windows (window, 2, 262) and "person" 0
                   (the interaction-level VQ ablation, InterMask Table 2).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from einops import rearrange

from intermask.data.captions import swap_left_right
from intermask.data.common import (
    ClipMeta,
    read_caption_lines,
    read_id_list,
    read_interaction_meta,
    read_npy,
    single_threaded,
)
from intermask.data.errors import DataError, SkippedClip
from intermask.data.normalization import Normalizer
from intermask.data.reader import ClipReader, Mode
from intermask.motion.interhuman import (
    FEATURE_DIM,
    RAW_DIM,
    RAW_POSITIONS,
    RAW_ROTATIONS,
    interaction_features,
)

SPLITS = ("train", "val", "test")
BODY_DIM = 192  # 22 positions x 3 + 21 rotations x 6
IGNORE_FILE = "ignore_list.txt"


@dataclass(frozen=True)
class InterHumanLayout:
    """Paths of the official release under ``root``."""

    root: Path

    @property
    def annots(self) -> Path:
        return self.root / "annots"

    def motion_file(self, person: int, clip_id: str) -> Path:
        return self.root / "motions_processed" / f"person{person}" / f"{clip_id}.npy"

    def caption_file(self, clip_id: str) -> Path:
        return self.annots / f"{clip_id}.txt"

    def split_file(self, split: str) -> Path:
        return self.root / "split" / f"{split}.txt"

    def ignore_files(self) -> list[Path]:
        # The reference loaders disagree on where the ignore list lives: accept both places.
        return [
            p for p in (self.root / IGNORE_FILE, self.root / "split" / IGNORE_FILE) if p.is_file()
        ]


def check_root(root: Path) -> None:
    if not root.is_dir():
        raise DataError(f"{root}: dataset root not found (expected the InterHuman folder)")


def read_ignore_list(layout: InterHumanLayout) -> set[str]:
    ignored: set[str] = set()
    for path in layout.ignore_files():
        ignored.update(read_id_list(path, what="ignore list"))
    return ignored


def load_person(path: Path) -> np.ndarray:
    """(T, 492) raw rows -> (T, 192) body columns, float32; DataError on any problem."""
    raw = read_npy(path, what="motion")
    if raw.ndim != 2 or raw.shape[1] != RAW_DIM:
        raise DataError(f"{path}: expected shape (T, {RAW_DIM}), got {tuple(raw.shape)}")
    if not np.issubdtype(raw.dtype, np.floating):
        raise DataError(f"{path}: expected a float array, got dtype {raw.dtype}")
    body = np.concatenate((raw[:, RAW_POSITIONS], raw[:, RAW_ROTATIONS]), axis=1).astype(np.float32)
    bad = ~np.isfinite(body)
    if bad.any():
        frames = np.unique(np.nonzero(bad)[0])[:5].tolist()
        raise DataError(
            f"{path}: {int(bad.sum())} NaN/Inf values in the body columns (first bad frames {frames})"
        )
    return body


def load_clip(layout: InterHumanLayout, clip_id: str) -> tuple[np.ndarray, list[str]]:
    """One clip -> ((T, 2, 192) body columns of both persons, captions)."""
    person1 = load_person(layout.motion_file(1, clip_id))
    person2 = load_person(layout.motion_file(2, clip_id))
    if person1.shape[0] != person2.shape[0]:
        raise DataError(
            f"{layout.motion_file(2, clip_id)}: expected {person1.shape[0]} frames like person1, "
            f"got {person2.shape[0]}"
        )
    captions = read_caption_lines(layout.caption_file(clip_id))
    return np.stack((person1, person2), axis=1), captions


def body_to_raw(body: torch.Tensor) -> torch.Tensor:
    """(..., 192) body columns -> (..., 492) raw rows (hand columns zero; the features ignore them)."""
    raw = body.new_zeros(*body.shape[:-1], RAW_DIM)
    n_pos = RAW_POSITIONS.stop - RAW_POSITIONS.start
    raw[..., RAW_POSITIONS] = body[..., :n_pos]
    raw[..., RAW_ROTATIONS] = body[..., n_pos:]
    return raw


def pair_features(body: torch.Tensor, *, mirror: bool = False) -> torch.Tensor:
    """(..., T, 2, 192) body columns of both persons -> (..., T-1, 2, 262) features, the first
    person the canonical reference and the second one in its frame."""
    raw = body_to_raw(body)
    return interaction_features(raw[..., 0, :], raw[..., 1, :], mirror=mirror)


def _reference_first(body: torch.Tensor, swap: bool) -> torch.Tensor:
    """(..., T, 2, 192) in file order -> person 2 first when ``swap`` (person 2 is the reference)."""
    return body.flip(-2) if swap else body


class Crop(NamedTuple):
    """An interaction item's random choices (:meth:`InterHumanDataset._draw_crop`)."""

    clip: int
    mirrored: bool
    start: int  # first frame
    frames: int  # frames cropped (the features have one fewer)
    swap_reference: bool  # person 2 is the canonical reference
    swap_output: bool  # person 2 comes first in the item
    caption: str


class InterHumanDataset(ClipReader):
    """InterHuman clips of one split (see the module docstring for the item layout).

    Augmentation, as in the reference loaders: captions drawn at random; clips longer than
    ``max_length`` frames get a random ``max_length`` crop (features are one frame shorter:
    lengths ``min_length - 1 .. max_length - 1``, zero-padded to ``max_length``);
    ``swap_persons`` swaps the persons with p=0.5 before canonicalization (who is the reference)
    and again after (the order returned); ``mirror`` (training) adds a mirrored copy of every
    clip, with left/right words of its captions swapped. Clips shorter than ``min_length`` frames
    and ids on the ignore list go to ``self.skipped`` (logged), never silently.
    """

    kind = "interhuman"
    feature_shape = (FEATURE_DIM,)
    default_max_length = 300  # frames (InterGen)
    default_min_length = 15
    default_swap_persons = True  # interactions have no person order
    default_normalize = True
    supports_mirror = True

    def __init__(
        self,
        *,
        root: str | Path,
        split: str,
        mode: Mode = "interaction",
        max_length: int = default_max_length,
        min_length: int = default_min_length,
        window: int = 64,
        stride: int = 10,
        window_persons: int = 1,
        mirror: bool = False,
        swap_persons: bool = default_swap_persons,
        normalizer: Normalizer | None = None,
        seed: int = 3407,
        epoch: int = 0,
    ):
        self.layout = InterHumanLayout(Path(root))
        self.mirror = mirror
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

    # ------------------------------------------------------------------ construction

    def _load(self) -> None:
        check_root(self.layout.root)
        listed = read_id_list(self.split_file, what=f"{self.split} split")
        ignored = read_ignore_list(self.layout)
        meta = read_interaction_meta(self.layout.root)
        self.skipped: list[SkippedClip] = [
            SkippedClip(i, "on ignore_list.txt") for i in listed if i in ignored
        ]
        ids, bodies, captions, metas = [], [], [], []
        for clip_id in (i for i in listed if i not in ignored):
            body, clip_captions = load_clip(self.layout, clip_id)
            if body.shape[0] < self.min_length:
                self.skipped.append(SkippedClip(clip_id, f"shorter than {self.min_length} frames"))
                continue
            ids.append(clip_id)
            bodies.append(body)
            captions.append(clip_captions)
            if meta is not None:
                metas.append(_clip_meta(meta, clip_id, self.layout.root))
        self.clip_ids: list[str] = ids
        self._check_not_empty(len(listed), f"ignore list or shorter than {self.min_length} frames")
        self.captions: list[list[str]] = captions
        self.mirrored_captions = [[swap_left_right(c) for c in cs] for cs in captions]
        self.meta: list[ClipMeta] | None = metas if meta is not None else None
        self.frames = np.array([b.shape[0] for b in bodies], dtype=np.int64)  # raw frames per clip
        self._offsets = np.concatenate(([0], np.cumsum(self.frames)))
        self._body = np.concatenate(bodies, axis=0)  # (sum T, 2, 192)

    def _build_windows(self) -> None:
        # Features depend on the whole canonical sequence, so windows are sliced from features
        # computed once per clip (and mirror state) here, not per item.
        sequences, self._window_source = [], []
        for clip in range(len(self.clip_ids)):
            for mirrored in (False, True) if self.mirror else (False,):
                features = self.clip_features(clip, mirror=mirrored).numpy()  # (T-1, 2, 262)
                if self.window_persons == 2:
                    sequences.append(features)
                    self._window_source.append((clip, 0, mirrored))
                    continue
                for person in (0, 1):
                    sequences.append(features[:, person])
                    self._window_source.append((clip, person + 1, mirrored))
        lengths = [len(s) for s in sequences]
        self._window_offsets = np.concatenate(([0], np.cumsum(lengths)))
        self._window_data = np.concatenate(sequences, axis=0)  # (sum L, 262) or (sum L, 2, 262)
        short = sorted(
            {
                self.clip_ids[c]
                for (c, _, _), n in zip(self._window_source, lengths, strict=True)
                if n < self.window
            }
        )
        reason = f"fewer than {self.window} feature frames: no {self.window}-frame window"
        self._index_windows(lengths, [SkippedClip(i, reason) for i in short])

    # ------------------------------------------------------------------ features

    def clip_body(self, clip: int) -> torch.Tensor:
        """(T, 2, 192) raw body columns of clip ``clip`` (persons in file order)."""
        return torch.from_numpy(self._body[self._offsets[clip] : self._offsets[clip + 1]])

    def clip_features(
        self,
        clip: int,
        *,
        mirror: bool = False,
        swap: bool = False,
        start: int = 0,
        frames: int | None = None,
    ) -> torch.Tensor:
        """Un-normalized features (T'-1, 2, 262) of frames ``start:start+frames`` of a clip.

        Person 1 (person 2 when ``swap``) is the canonical reference; the other one is in its frame.
        """
        body = self.clip_body(clip)
        stop = len(body) if frames is None else start + frames
        with single_threaded():
            return pair_features(_reference_first(body[start:stop], swap), mirror=mirror)

    # ------------------------------------------------------------------ items

    def stats_sequences(self) -> Iterator[torch.Tensor]:
        """(T-1, 2, 262) features of every clip with both choices of reference person and both
        mirror states: the distribution training sees with person swapping and mirroring on."""
        for clip in range(len(self.clip_ids)):
            for swap in (False, True):
                for mirror in (False, True):
                    yield self.clip_features(clip, mirror=mirror, swap=swap)

    def _interaction_count(self) -> int:
        return len(self.clip_ids) * (2 if self.mirror else 1)

    def _window_item(self, index: int) -> dict[str, Any]:
        seq, start = int(self.windows.sequence[index]), int(self.windows.start[index])
        first = self._window_offsets[seq] + start
        motion = self._normalize(torch.from_numpy(self._window_data[first : first + self.window]))
        clip, person, mirrored = self._window_source[seq]
        return {
            "motion": motion,
            "id": self.clip_ids[clip],
            "person": person,
            "mirrored": mirrored,
            "start": start,
        }

    def _draw_crop(self, index: int, rng: np.random.Generator) -> Crop:
        """The random choices of item ``index``, in the order the generator draws them."""
        clip, mirrored = index % len(self.clip_ids), index >= len(self.clip_ids)
        frames = int(self.frames[clip])
        # Any start in [0, T - max_length]; the reference's range() leaves out the last one.
        start = (
            int(rng.integers(0, frames - self.max_length + 1)) if frames > self.max_length else 0
        )
        swap_reference = self.swap_persons and bool(rng.random() < 0.5)
        swap_output = self.swap_persons and bool(rng.random() < 0.5)
        captions = self.mirrored_captions[clip] if mirrored else self.captions[clip]
        caption = captions[int(rng.integers(len(captions)))]
        return Crop(
            clip,
            mirrored,
            start,
            min(frames, self.max_length),
            swap_reference,
            swap_output,
            caption,
        )

    def _crop_features(self, crops: Sequence[Crop]) -> list[torch.Tensor]:
        """Un-normalized (frames - 1, 2, 262) features of each crop, as :meth:`clip_features`
        gives them, computed in one pass per group of crops that share a length and a mirror
        state (the reference person first in each): a batch of 16 costs about half of what its
        items cost one at a time (docs/performance.md)."""
        groups: dict[tuple[int, bool], list[int]] = defaultdict(list)
        for i, crop in enumerate(crops):
            groups[(crop.frames, crop.mirrored)].append(i)
        features: list[torch.Tensor] = [torch.empty(0)] * len(crops)
        for (_, mirrored), members in groups.items():
            body = torch.stack([self._crop_body(crops[i]) for i in members])
            for i, row in zip(members, pair_features(body, mirror=mirrored), strict=True):
                features[i] = row
        return features

    def _crop_body(self, crop: Crop) -> torch.Tensor:
        """(frames, 2, 192) body columns of a crop, its reference person first."""
        body = self.clip_body(crop.clip)[crop.start : crop.start + crop.frames]
        return _reference_first(body, crop.swap_reference)

    def _interaction_item(self, index: int, rng: np.random.Generator) -> dict[str, Any]:
        return self._interaction_items([(index, rng)])[0]

    def _interaction_items(
        self, draws: Sequence[tuple[int, np.random.Generator]]
    ) -> list[dict[str, Any]]:
        crops = [self._draw_crop(index, rng) for index, rng in draws]
        return [
            self._assemble(crop, features)
            for crop, features in zip(crops, self._crop_features(crops), strict=True)
        ]

    def _assemble(self, crop: Crop, features: torch.Tensor) -> dict[str, Any]:
        """The item of ``crop`` from its un-normalized (L, 2, 262) features."""
        persons = [2, 1] if crop.swap_reference else [1, 2]
        if crop.swap_output:
            features, persons = features.flip(1), persons[::-1]
        features = self._normalize(features)
        length = features.shape[0]
        motion = features.new_zeros(2, self.max_length, FEATURE_DIM)
        motion[:, :length] = rearrange(features, "t p c -> p t c")
        item: dict[str, Any] = {
            "motion": motion,
            "length": length,
            "caption": crop.caption,
            "id": self.clip_ids[crop.clip],
            "mirrored": crop.mirrored,
            "persons": torch.tensor(persons),
            "start": crop.start,
            "reference": 2 if crop.swap_reference else 1,
        }
        if self.meta is not None:
            meta = self.meta[crop.clip]
            item.update(
                action=meta.action, action_id=meta.action_id, actor=persons.index(meta.actor) + 1
            )
        return item


def _clip_meta(meta: dict[str, ClipMeta], clip_id: str, root: Path) -> ClipMeta:
    if clip_id not in meta:
        raise DataError(f"{root / 'interaction_meta.json'}: no entry for clip {clip_id!r}")
    return meta[clip_id]
