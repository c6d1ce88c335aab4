"""On-disk cache of frozen text features, keyed by (encoder identity, caption).

CLIP is frozen, so a caption's features never change: training reads them from disk instead of
running ViT-L/14 every step. Layout under ``cache_dir``::

    <identity hash>/identity.txt        the full encoder identity, for people
    <identity hash>/<k[:2]>/<k>.pt      one caption: {"format", "caption", "tokens", "eot_index"}

``k`` = sha256(identity, caption). The identity hash covers the cache format and the encoder's
identity, which names the architecture, the weight source and a hash of the weights, so a random
tower's entries can never be served to a real CLIP. Tokens are stored as fp16 (L, D); every
result, fresh or cached, goes through the same fp16 rounding, so a hit returns exactly what the
miss returned, and the encoder computes each caption on its own, so a miss returns the same bits
whichever captions were missed with it: what a job reads does not depend on what earlier jobs
wrote. Format v1 entries (batch-dependent in their last bits on AVX2 kernels) live under other
hashes and are not read. Files are written to a temporary name and renamed, so DDP ranks writing
the same entry at once never leave a torn file.
"""

from __future__ import annotations

import hashlib
import logging
import os
import uuid
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

import torch

from intermask.text.clip_encoder import FrozenCLIPTextEncoder, TextFeatures, padding_mask_from_eot

log = logging.getLogger(__name__)

CACHE_FORMAT = "intermask-text-cache-v2"  # v2: features of each caption alone
STORAGE_DTYPE = torch.float16


def _sha256(*parts: str) -> str:
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    return digest.hexdigest()


class TextFeatureCache:
    """Memory (LRU) and disk cache in front of a frozen text encoder.

    Args:
        encoder: the frozen encoder; its ``identity`` keys the entries.
        cache_dir: folder for the fp16 files; None keeps the cache in memory only.
        memory_items: captions kept in the in-memory LRU layer (0 disables it). One ViT-L/14
            entry is 77 x 768 fp16 = 118 KB.
        batch_size: misses go to the encoder in chunks of this many captions (it bounds the
            features held at once; the features do not depend on it).
    """

    def __init__(
        self,
        *,
        encoder: FrozenCLIPTextEncoder,
        cache_dir: str | Path | None = None,
        memory_items: int = 1024,
        batch_size: int = 256,
    ) -> None:
        if memory_items < 0:
            raise ValueError(f"memory_items must be >= 0, got {memory_items}")
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.encoder = encoder
        self.memory_items, self.batch_size = memory_items, batch_size
        self.identity = encoder.identity
        self.identity_key = _sha256(CACHE_FORMAT, self.identity)[:16]
        self.directory = None if cache_dir is None else Path(cache_dir) / self.identity_key
        if self.directory is not None:
            self.directory.mkdir(parents=True, exist_ok=True)
            _atomic_write_text(self.directory / "identity.txt", self.identity + "\n")
        self._memory: OrderedDict[str, tuple[torch.Tensor, int]] = OrderedDict()
        self.hits = 0  # captions served from memory or disk
        self.misses = 0  # captions that went through the encoder
        self.disk_hits = 0  # the part of `hits` read from disk

    def key(self, caption: str) -> str:
        """Hex key of one caption under this encoder's identity."""
        return _sha256(self.identity, caption)

    def path(self, caption: str) -> Path | None:
        if self.directory is None:
            return None
        key = self.key(caption)
        return self.directory / key[:2] / f"{key}.pt"

    def get_or_encode(self, captions: Sequence[str]) -> TextFeatures:
        """B captions -> TextFeatures (B, L, D) float32 on the encoder's device.

        Only captions found neither in memory nor on disk are encoded, in chunks of
        ``batch_size``; a caption repeated within the call is encoded once.
        """
        if isinstance(captions, str):
            raise TypeError("captions must be a sequence of strings, got a single string")
        if len(captions) == 0:
            raise ValueError("captions is empty: nothing to encode")
        found: dict[str, tuple[torch.Tensor, int]] = {}
        missing: list[str] = []
        for caption in dict.fromkeys(captions):
            entry = self._lookup(caption)
            if entry is None:
                missing.append(caption)
            else:
                found[caption] = entry
        for start in range(0, len(missing), self.batch_size):
            found.update(self._encode_and_store(missing[start : start + self.batch_size]))
        self.misses += len(missing)
        self.hits += len(captions) - len(missing)

        device = self.encoder.device
        # The entries are fp16 on the CPU. Under CPU autocast (bf16-mixed training on a CPU with
        # native bf16) stack/cat refuse fp16 inputs ("Unexpected floating ScalarType in
        # at::autocast::prioritize"); this is a copy, not arithmetic, so autocast stays out of it.
        with torch.autocast(device_type="cpu", enabled=False):
            tokens = torch.stack([found[c][0] for c in captions])
        tokens = tokens.to(device=device, dtype=torch.float32)
        eot_index = torch.tensor([found[c][1] for c in captions], dtype=torch.int64, device=device)
        return TextFeatures(tokens, eot_index, padding_mask_from_eot(eot_index, tokens.shape[1]))

    def precompute(self, captions: Sequence[str]) -> int:
        """Fill the cache for many captions (e.g. a whole split); returns how many were encoded."""
        before = self.misses
        unique = list(dict.fromkeys(captions))
        for start in range(0, len(unique), self.batch_size):
            self.get_or_encode(unique[start : start + self.batch_size])
        return self.misses - before

    def _lookup(self, caption: str) -> tuple[torch.Tensor, int] | None:
        key = self.key(caption)
        if key in self._memory:
            self._memory.move_to_end(key)
            return self._memory[key]
        path = self.path(caption)
        if path is None or not path.is_file():
            return None
        entry = self._read(path, caption)
        if entry is not None:
            self.disk_hits += 1
            self._remember(key, entry)
        return entry

    def _read(self, path: Path, caption: str) -> tuple[torch.Tensor, int] | None:
        try:
            data = torch.load(path, map_location="cpu", weights_only=True)
            valid = (
                data.get("format") == CACHE_FORMAT
                and data.get("caption") == caption
                and data["tokens"].dtype == STORAGE_DTYPE
            )
        except Exception as error:  # a torn or foreign file is re-encoded, never trusted
            log.warning("text cache entry %s is unreadable (%s); re-encoding it", path, error)
            return None
        if not valid:
            log.warning("text cache entry %s does not hold %r; re-encoding it", path, caption)
            return None
        return data["tokens"], int(data["eot_index"])

    def _encode_and_store(self, captions: list[str]) -> dict[str, tuple[torch.Tensor, int]]:
        features = self.encoder.encode(captions)
        tokens = features.features.to(device="cpu", dtype=STORAGE_DTYPE)  # (b, L, D)
        entries = {}
        for row, caption in enumerate(captions):
            entry = (tokens[row].clone(), int(features.eot_index[row]))
            entries[caption] = entry
            self._remember(self.key(caption), entry)
            path = self.path(caption)
            if path is not None:
                payload = {
                    "format": CACHE_FORMAT,
                    "caption": caption,
                    "tokens": entry[0],
                    "eot_index": entry[1],
                }
                _atomic_save(payload, path)
        return entries

    def _remember(self, key: str, entry: tuple[torch.Tensor, int]) -> None:
        if self.memory_items == 0:
            return
        self._memory[key] = entry
        self._memory.move_to_end(key)
        while len(self._memory) > self.memory_items:
            self._memory.popitem(last=False)

    def clear_memory(self) -> None:
        """Drop the in-memory layer (the files stay)."""
        self._memory.clear()

    def __len__(self) -> int:
        """Entries in the memory layer."""
        return len(self._memory)


def _temporary_name(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex}.tmp")


def _atomic_save(payload: dict, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = _temporary_name(path)
    try:
        torch.save(payload, temporary)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _atomic_write_text(path: Path, text: str) -> None:
    temporary = _temporary_name(path)
    try:
        temporary.write_text(text, encoding="utf-8")
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)
