"""HumanML3D reader (one person, text to motion) for the official processed release, read as is.

    <root>/new_joint_vecs/<id>.npy   float32 (T, 263) features (``intermask.motion.humanml3d``)
    <root>/new_joints/<id>.npy       float32 (T, 22, 3) joint positions, Y up (read on demand)
    <root>/texts/<id>.txt            lines "caption#word/POS word/POS ...#start#end" (seconds)
    <root>/Mean.npy, <root>/Std.npy  (263,) statistics the items are z-scored with
    <root>/{train,val,test}.txt      one id per line

Items follow the reference ``Text2MotionDataset`` (T2M, MoMask):

- A clip with T outside [min_length, max_frames) = [40, 200) is skipped with all its captions
  (the reference tests the whole clip before it reads the captions).
- Captions tagged 0.0/0.0 (NaN reads as 0.0) describe the whole clip: together they make one item
  with the clip's id. A clip with no such caption has no whole-clip item.
- A caption tagged [start, end) seconds describes frames ``int(start * 20):int(end * 20)`` (cut at
  the clip's end, as a slice is): an item of its own when that span passes the same length rule,
  with the id ``f"{tag}_{id}"``. The reference draws the tag at random from the letters A..W
  (retrying on collisions); here the k-th time-tagged line of the file gets the k-th letter
  (``A1``, ``B1``, ... after W), so ids are the same in every run.
- Per item: L = floor(F / 4) * 4 frames, one unit of 4 fewer with p = 1/3 (``length_jitter``, the
  reference's 'double' coin), at most floor(max_length / 4) * 4; the crop starts anywhere in the
  span; z-scored; zero-padded to ``max_length`` (196, MoMask's ``max_motion_length``).

Everything left out (clips and sub-clips outside the length rule, clips without a whole-clip
caption) is listed in :attr:`HumanML3DDataset.skipped` and logged; every malformed file raises a
:class:`DataError` naming it. The two-person :class:`~intermask.data.reader.ClipReader` protocol
(persons, windows, dataset kinds) does not apply, so this reader is a plain ``Dataset``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from intermask.data.common import (
    ItemKey,
    check_motion_array,
    item_rng,
    log_skipped,
    read_caption_lines,
    read_id_list,
    read_npy,
    split_key,
)
from intermask.data.errors import DataError, SkippedClip
from intermask.data.normalization import Normalizer
from intermask.motion.humanml3d import FEATURE_DIM, FPS
from intermask.motion.skeleton import NUM_JOINTS

SUBCLIP_LETTERS = "ABCDEFGHIJKLMNOPQRSTUVW"  # the reference's tag alphabet


@dataclass(frozen=True)
class HumanML3DLayout:
    root: Path

    def motion_file(self, clip_id: str) -> Path:
        return self.root / "new_joint_vecs" / f"{clip_id}.npy"

    def joints_file(self, clip_id: str) -> Path:
        return self.root / "new_joints" / f"{clip_id}.npy"

    def caption_file(self, clip_id: str) -> Path:
        return self.root / "texts" / f"{clip_id}.txt"

    def split_file(self, split: str) -> Path:
        return self.root / f"{split}.txt"

    @property
    def mean_file(self) -> Path:
        return self.root / "Mean.npy"

    @property
    def std_file(self) -> Path:
        return self.root / "Std.npy"


@dataclass(frozen=True)
class TaggedCaption:
    """One caption line: text, word/POS tokens and the described span in seconds."""

    text: str
    tokens: tuple[str, ...]  # ("a/DET", "man/NOUN", ...) for the T2M (GloVe + POS) evaluator
    start: float
    end: float

    @property
    def whole(self) -> bool:
        """True when the caption describes the whole clip (tags 0.0 and 0.0)."""
        return self.start == 0.0 and self.end == 0.0


def _parse_tag(text: str, path: Path, number: int) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise DataError(
            f"{path}: line {number}: time tags must be numbers (seconds), got {text!r}"
        ) from err
    if math.isnan(value):
        return 0.0  # the reference reads NaN as 0.0
    if math.isinf(value) or value < 0:
        raise DataError(f"{path}: line {number}: time tag must be finite and >= 0, got {value}")
    return value


def parse_tagged_caption(line: str, path: Path, number: int) -> TaggedCaption:
    """One ``caption#word/POS ...#start#end`` line (``number`` counts from 1); DataError naming the
    file and the line when malformed."""
    parts = line.split("#")
    if len(parts) != 4 or not parts[0].strip():
        raise DataError(
            f"{path}: line {number}: expected 'caption#word/POS ...#start#end' (4 fields), "
            f"got {len(parts)} fields in {line!r}"
        )
    tokens = tuple(parts[1].split())
    bad = [t for t in tokens if not t.rpartition("/")[0] or not t.rpartition("/")[2]]
    if not tokens or bad:
        raise DataError(f"{path}: line {number}: expected tokens 'word/POS ...', got {parts[1]!r}")
    start, end = (_parse_tag(p.strip(), path, number) for p in parts[2:4])
    return TaggedCaption(parts[0].strip(), tokens, start, end)


def read_tagged_captions(path: Path) -> list[TaggedCaption]:
    """Parse ``caption#word/POS ...#start#end`` lines; DataError (file and line) at the first
    malformed one (``intermask data check`` lists every one)."""
    return [
        parse_tagged_caption(line, path, number)
        for number, line in enumerate(read_caption_lines(path), start=1)
    ]


def subclip_tag(rank: int) -> str:
    """Tag of the ``rank``-th time-tagged caption of a file: A..W, then A1..W1, ..."""
    letter, cycle = SUBCLIP_LETTERS[rank % len(SUBCLIP_LETTERS)], rank // len(SUBCLIP_LETTERS)
    return letter if cycle == 0 else f"{letter}{cycle}"


def load_npy(path: Path, *, trailing: tuple[int, ...], what: str) -> np.ndarray:
    """A (T, *trailing) finite float .npy file as float32; DataError naming the file otherwise."""
    return check_motion_array(read_npy(path, what=what), path, trailing=trailing)


@dataclass(frozen=True)
class ItemSpan:
    """An item: frames [start, stop) of clip ``clip`` and the captions describing them."""

    item_id: str
    clip: int
    start: int
    stop: int
    captions: tuple[TaggedCaption, ...]

    @property
    def frames(self) -> int:
        return self.stop - self.start


class HumanML3DDataset(Dataset):
    """One split of HumanML3D as text-motion items (module docstring for the rules).

    Items: {"motion": (max_length, 263) z-scored, zero after ``length``, "length", "caption",
    "tokens" ("word/POS word/POS ...", one string so that batches collate), "id" (the item's,
    derived for sub-clips), "clip_id" (the file's), "start" (first frame of the crop in the file)}.
    """

    fps = FPS
    feature_dim = FEATURE_DIM

    def __init__(
        self,
        *,
        root: str | Path,
        split: str,
        max_length: int = 196,  # MoMask's max_motion_length
        min_length: int = 40,  # reference: min_motion_len = 40 for HumanML3D
        max_frames: int = 200,  # reference: clips of 200 frames or more are left out
        unit_length: int = 4,
        length_jitter: bool = True,
        normalizer: Normalizer | None = None,
        normalize: bool = True,
        seed: int = 3407,
        epoch: int = 0,
    ):
        if not (1 <= unit_length and 2 * unit_length <= min_length <= max_frames):
            raise ValueError(
                f"need 1 <= unit_length, 2 * unit_length <= min_length <= max_frames, got "
                f"{unit_length}, {min_length}, {max_frames}"
            )
        if max_length < unit_length:
            raise ValueError(f"max_length must be >= unit_length ({unit_length}), got {max_length}")
        self.layout = HumanML3DLayout(Path(root))
        self.split = split
        self.max_length, self.min_length, self.max_frames = max_length, min_length, max_frames
        self.unit_length, self.length_jitter = unit_length, length_jitter
        self.seed, self.epoch = seed, epoch
        if not self.layout.root.is_dir():
            raise DataError(
                f"{self.layout.root}: dataset root not found (expected the HumanML3D folder)"
            )
        if normalizer is None and normalize:
            normalizer = Normalizer.from_files(
                self.layout.mean_file, self.layout.std_file, feature_shape=(FEATURE_DIM,)
            )
        if normalizer is not None and normalizer.feature_shape != (FEATURE_DIM,):
            raise ValueError(
                f"normalizer must have shape ({FEATURE_DIM},), got {normalizer.feature_shape}"
            )
        self.normalizer = normalizer if normalize else None
        self._load()

    @property
    def split_file(self) -> Path:
        return self.layout.split_file(self.split)

    def _passes(self, frames: int) -> bool:
        return self.min_length <= frames < self.max_frames

    def _load(self) -> None:
        listed = read_id_list(self.split_file, what=f"{self.split} split")
        rule = f"outside [{self.min_length}, {self.max_frames})"
        self.skipped: list[SkippedClip] = []
        self.clip_ids: list[str] = []
        self.items: list[ItemSpan] = []
        motions = []
        for clip_id in listed:
            motion = load_npy(
                self.layout.motion_file(clip_id),
                trailing=(FEATURE_DIM,),
                what=f"motion (listed in {self.split_file.name})",
            )
            captions = read_tagged_captions(self.layout.caption_file(clip_id))
            if not self._passes(len(motion)):
                self.skipped.append(SkippedClip(clip_id, f"{len(motion)} frames, {rule}"))
                continue
            clip = len(self.clip_ids)
            spans = self._clip_items(clip_id, clip, len(motion), captions, rule)
            if spans:
                self.clip_ids.append(clip_id)
                motions.append(motion)
                self.items.extend(spans)
        log_skipped(self.skipped, where=str(self.split_file))
        if not self.items:
            raise DataError(
                f"{self.split_file}: split resolves to zero items ({len(listed)} listed, "
                f"{len(self.skipped)} skipped: length {rule} or no whole-clip caption)"
            )
        self.frames = np.array([len(m) for m in motions], dtype=np.int64)
        self._offsets = np.concatenate(([0], np.cumsum(self.frames)))
        self._raw = np.concatenate(motions, axis=0)  # (sum T, 263) float32

    def _clip_items(
        self, clip_id: str, clip: int, frames: int, captions: list[TaggedCaption], rule: str
    ) -> list[ItemSpan]:
        """The whole-clip item (if any caption covers the whole clip), then one per sub-clip."""
        whole = tuple(c for c in captions if c.whole)
        spans = [ItemSpan(clip_id, clip, 0, frames, whole)] if whole else []
        if not whole:
            self.skipped.append(
                SkippedClip(clip_id, "no whole-clip caption (every caption is time-tagged)")
            )
        tagged = [c for c in captions if not c.whole]
        for rank, caption in enumerate(tagged):
            item_id = f"{subclip_tag(rank)}_{clip_id}"
            # int() truncates as the reference does; the slice bounds clamp to the clip.
            start, stop, _ = slice(int(caption.start * FPS), int(caption.end * FPS)).indices(frames)
            span = max(stop - start, 0)
            if not self._passes(span):
                reason = f"sub-clip [{caption.start}, {caption.end}) s of {clip_id}: {span} frames, {rule}"
                self.skipped.append(SkippedClip(item_id, reason))
                continue
            spans.append(ItemSpan(item_id, clip, start, stop, (caption,)))
        return spans

    # ------------------------------------------------------------------ features

    def clip_features(self, clip: int) -> torch.Tensor:
        """Un-normalized (T, 263) features of a whole clip as stored."""
        return torch.from_numpy(self._raw[self._offsets[clip] : self._offsets[clip + 1]])

    def features(self, index: int) -> torch.Tensor:
        """Un-normalized (F, 263) features of item ``index``'s whole span."""
        span = self.items[index]
        return self.clip_features(span.clip)[span.start : span.stop]

    def joints(self, index: int) -> torch.Tensor:
        """(F, 22, 3) released joint positions (``new_joints``) of item ``index``'s span."""
        span = self.items[index]
        clip_id = self.clip_ids[span.clip]
        path = self.layout.joints_file(clip_id)
        positions = load_npy(path, trailing=(NUM_JOINTS, 3), what="joints")
        expected = int(self.frames[span.clip])
        if len(positions) != expected:
            raise DataError(
                f"{path}: expected {expected} frames like {self.layout.motion_file(clip_id)}, "
                f"got {len(positions)}"
            )
        return torch.from_numpy(positions[span.start : span.stop])

    # ------------------------------------------------------------------ items

    def crop_length(self, frames: int, rng: np.random.Generator) -> int:
        """Crop length for a span of ``frames`` frames (module docstring)."""
        unit = self.unit_length
        jitter = self.length_jitter and unit < 10 and int(rng.integers(3)) == 2
        length = (frames // unit - (1 if jitter else 0)) * unit
        return min(length, (self.max_length // unit) * unit)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, key: ItemKey) -> dict[str, Any]:
        index, epoch = split_key(key, self.epoch)
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} out of range for {len(self)} items")
        rng = item_rng(self.seed, epoch, index)
        span = self.items[index]
        caption = span.captions[int(rng.integers(len(span.captions)))]
        length = self.crop_length(span.frames, rng)
        start = int(rng.integers(0, span.frames - length + 1))
        features = self.features(index)[start : start + length]
        if self.normalizer is not None:
            features = self.normalizer.normalize(features)
        motion = features.new_zeros(self.max_length, FEATURE_DIM)
        motion[:length] = features
        return {
            "motion": motion,
            "length": length,
            "caption": caption.text,
            "tokens": " ".join(caption.tokens),
            "id": span.item_id,
            "clip_id": self.clip_ids[span.clip],
            "start": span.start + start,
        }


class HumanML3DWindows(Dataset):
    """One split of HumanML3D as fixed-length motion windows, the tokenizer's training data.

    As the reference's ``MotionDataset`` (MoMask's RVQ): every clip of the split with at least
    ``window + 1`` frames contributes ``T - window`` windows, those starting at frames
    ``0, stride, 2 stride, ...`` below ``T - window`` (the reference: ``stride`` 1, so a window
    never ends at the last frame); captions are not read and the [40, 200) length rule does not
    apply. Shorter clips are listed in :attr:`skipped`. Items: {"motion": (window, 263)
    z-scored, "length": window, "id": the clip's id, "start": first frame}. The windows are
    fixed: ``epoch`` only changes the sampler's order.
    """

    fps = FPS
    feature_dim = FEATURE_DIM

    def __init__(
        self,
        *,
        root: str | Path,
        split: str,
        window: int = 64,  # MoMask's window_size
        stride: int = 1,
        normalizer: Normalizer | None = None,
        normalize: bool = True,
    ):
        if window < 1 or stride < 1:
            raise ValueError(f"window and stride must be >= 1, got {window} and {stride}")
        self.layout = HumanML3DLayout(Path(root))
        self.split, self.window, self.stride = split, window, stride
        if not self.layout.root.is_dir():
            raise DataError(
                f"{self.layout.root}: dataset root not found (expected the HumanML3D folder)"
            )
        if normalizer is None and normalize:
            normalizer = Normalizer.from_files(
                self.layout.mean_file, self.layout.std_file, feature_shape=(FEATURE_DIM,)
            )
        self.normalizer = normalizer if normalize else None
        split_file = self.layout.split_file(split)
        self.skipped: list[SkippedClip] = []
        self.clip_ids: list[str] = []
        motions: list[np.ndarray] = []
        starts: list[np.ndarray] = []
        for clip_id in read_id_list(split_file, what=f"{split} split"):
            motion = load_npy(
                self.layout.motion_file(clip_id),
                trailing=(FEATURE_DIM,),
                what=f"motion (listed in {split_file.name})",
            )
            if len(motion) <= window:
                reason = f"{len(motion)} frames, no {window}-frame window (needs {window + 1})"
                self.skipped.append(SkippedClip(clip_id, reason))
                continue
            offset = sum(len(m) for m in motions)
            starts.append(offset + np.arange(0, len(motion) - window, stride))
            self.clip_ids.append(clip_id)
            motions.append(motion)
        log_skipped(self.skipped, where=f"{split_file} (windows)")
        if not motions:
            raise DataError(
                f"{split_file}: no clip has a {window}-frame window "
                f"({len(self.skipped)} clips, all of {window} frames or fewer)"
            )
        self._raw = np.concatenate(motions, axis=0)
        self._starts = np.concatenate(starts)
        self._clips = np.concatenate(
            [np.full(len(s), clip, dtype=np.int64) for clip, s in enumerate(starts)]
        )
        self._clip_offsets = np.concatenate(([0], np.cumsum([len(m) for m in motions])))

    def __len__(self) -> int:
        return len(self._starts)

    def __getitem__(self, key: ItemKey) -> dict[str, Any]:
        index, _ = split_key(key, 0)
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} out of range for {len(self)} windows")
        start = int(self._starts[index])
        features = torch.from_numpy(self._raw[start : start + self.window])
        if self.normalizer is not None:
            features = self.normalizer.normalize(features)
        clip = int(self._clips[index])
        return {
            "motion": features,
            "length": self.window,
            "id": self.clip_ids[clip],
            "start": start - int(self._clip_offsets[clip]),
        }
