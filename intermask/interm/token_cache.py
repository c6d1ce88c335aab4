"""Exact cache of the frozen tokenizer's codes for Inter-M training.

Inter-M learns on the base-layer codes of a frozen VQ-VAE; the reference re-encodes both persons
at every step. One person's codes are a pure function of the VQ weights and of the features the
reader produced, and those are fixed by the item's crop identity: dataset clip ``id``, crop
``start`` frame, ``mirrored``, the ``reference`` person the pair is canonicalized on, which file
person it is (``persons``), its ``length`` and the padded frame count. Keyed by exactly that, a
hit returns the codes a fresh encoding would give; the key is metadata, so a lookup costs no
hashing of features and no device-to-host copy.

Exact crops only: the reader canonicalizes every crop at its first frame (InterHuman) and the
encoder's convolutions see the crop's borders, so codes of a crop are not a crop of the whole
clip's codes. Within one run the dataset and its normalization are fixed; the VQ is not assumed
to be: the cache is keyed by a digest of the VQ's state and empties when it changes.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

from intermask.utils.fingerprint import weights_digest

log = logging.getLogger(__name__)

# ~1 KB per entry (int16 codes + key): 250k entries bound the cache at a few hundred MB on the
# paper's data; the demo (1,600 items x 8 epochs x 2 persons) needs 26k.
MAX_ENTRIES = 250_000
CROP_FIELDS = ("id", "start", "persons")  # a batch without these is encoded, not cached

CropKey = tuple[
    str, bool, int, int, int, int, int
]  # id, mirrored, start, reference, person, length, frames


def crop_keys(batch: dict[str, Any], lengths: Sequence[int], frames: int) -> list[CropKey] | None:
    """Per (sample, person) keys of a batch in (B * 2) order, or None when the batch does not
    identify its crops (hand-made batches). ``lengths`` in frames after rounding, ``frames`` the
    encoded (padded) frame count."""
    if any(field not in batch for field in CROP_FIELDS):
        return None
    count = len(batch["id"])
    mirrored = batch.get("mirrored", [False] * count)  # Inter-X: no mirror augmentation
    reference = batch.get("reference", [1] * count)  # Inter-X: no cross-person canonicalization
    keys = []
    for b in range(count):
        crop = (str(batch["id"][b]), bool(mirrored[b]), int(batch["start"][b]), int(reference[b]))
        for p in range(2):
            keys.append((*crop, int(batch["persons"][b][p]), int(lengths[b]), frames))
    return keys


class TokenCache:
    """Codes per :data:`CropKey`, valid for one VQ state (see the module docstring).

    ``lookups`` and ``hits`` count person crops since the last :meth:`reset_counts`.
    """

    def __init__(self, *, codebook_size: int, max_entries: int = MAX_ENTRIES) -> None:
        if max_entries < 1:
            raise ValueError(f"max_entries must be >= 1, got {max_entries}")
        self.max_entries = max_entries
        # codes and the padding -1 in 2 bytes where the codebook allows (every paper setting)
        self.dtype = torch.int16 if codebook_size <= torch.iinfo(torch.int16).max else torch.int32
        self.entries: dict[CropKey, torch.Tensor] = {}
        self.digest: str | None = None
        self._vq_id: int | None = None
        self._full_logged = False
        self.lookups = self.hits = 0

    def bind(self, vq: nn.Module, *, recheck: bool = False) -> None:
        """Use the codes of ``vq``: a different module, or (with ``recheck``) changed weights of
        the same one, empties the cache. Digesting costs one pass over the VQ's state, so it runs
        when the module changes and where the caller asks (once per epoch)."""
        if id(vq) == self._vq_id and not recheck:
            return
        digest = weights_digest(vq)
        if digest != self.digest:
            if self.entries:
                log.info("token cache: the VQ changed, %d cached crops dropped", len(self.entries))
            self.entries.clear()
            self.digest = digest
        self._vq_id = id(vq)

    def get(self, key: CropKey) -> torch.Tensor | None:
        """(rows, T') codes of ``key`` (CPU, int64) or None."""
        self.lookups += 1
        codes = self.entries.get(key)
        if codes is None:
            return None
        self.hits += 1
        return codes.long()

    def put(self, key: CropKey, codes: torch.Tensor) -> None:
        """Keep (rows, T') codes (-1 on padding); after ``max_entries`` (logged once) new crops
        are not kept."""
        if len(self.entries) >= self.max_entries:
            if not self._full_logged:
                log.info("token cache full (%d crops): new crops are encoded, not kept", len(self))
                self._full_logged = True
            return
        self.entries[key] = codes.detach().to("cpu", self.dtype)

    def reset_counts(self) -> None:
        self.lookups = self.hits = 0

    @property
    def hit_rate(self) -> float:
        return self.hits / self.lookups if self.lookups else 0.0

    def __len__(self) -> int:
        return len(self.entries)


class FrozenTokenizerHooks:
    """What a LightningModule training on a frozen tokenizer needs, owned once: ``vq`` and
    ``text`` (its properties) follow the module's device, a checkpoint trained on another
    tokenizer is refused on resume, and the ``token_cache`` (or None) is re-bound at each
    training epoch's start (the tokenizer's weights may have changed in place: it then starts
    over) and reports its hit rate and size at the end."""

    token_cache: TokenCache | None

    def _move_frozen(self, device: torch.device) -> None:
        if next(self.vq.parameters()).device != device:
            self.vq.to(device)
        if self.text.encoder.device != device:
            self.text.encoder.to(device)

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        """Resuming with another tokenizer would train on codes that mean other motions."""
        stored = checkpoint.get("hyper_parameters", {}).get("vq_digest")
        current = self.hparams.get("vq_digest")
        if stored is not None and current is not None and stored != current:
            raise ValueError(
                f"the checkpoint was trained on the VQ-VAE with weights digest {stored[:16]}; "
                f"this module's tokenizer has {current[:16]}: resume with the tokenizer the "
                "checkpoint's run used"
            )

    def on_train_epoch_start(self) -> None:
        if self.token_cache is not None:
            self.token_cache.bind(self.vq, recheck=True)  # weights changed in place: start over
            self.token_cache.reset_counts()

    def on_train_epoch_end(self) -> None:
        cache = self.token_cache
        if cache is not None and cache.lookups:  # this epoch's training and validation crops
            self.log("token_cache/hit_rate", cache.hit_rate)
            self.log("token_cache/crops", float(len(cache)))
