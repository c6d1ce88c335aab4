"""Checkpoint files of evaluators: file identity, released layouts, and a precise key report.

Released files:

* InterHuman ``interclip.ckpt`` (InterGen): a Lightning checkpoint whose ``state_dict`` keys carry
  a ``model.`` prefix in front of the InterCLIP module names.
* T2M's ``finest.tar`` (InterMask's Inter-X matcher, T2M's HumanML3D matcher): a dict with the
  state dicts ``movement_encoder``, ``text_encoder`` and ``motion_encoder`` (plus optimizer
  state and ``epoch``). T2M's HumanML3D release keeps the statistics its matcher z-scores motion
  with in another run folder of the same tree: ``t2m/text_mot_match/model/finest.tar`` and
  ``t2m/Comp_v6_KLD01/meta/{mean,std}.npy`` (263 values each; MoMask's evaluator zip has them
  in ``t2m/Comp_v6_KLD005/meta``, which its evaluation reads).

Both are mapped onto our module names (:func:`released_interclip_state`,
:func:`released_t2m_state`); :func:`load_state` then reports every missing, unexpected and
shape-mismatched key instead of PyTorch's first-error message.
"""

from __future__ import annotations

import logging
import pickle
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from intermask.data.normalization import Normalizer
from intermask.utils.checkpoint_files import read_checkpoint_file
from intermask.utils.files import file_hash as file_hash  # re-exported

log = logging.getLogger(__name__)

INTERCLIP_PREFIX = "model."
T2M_PARTS = ("movement_encoder", "text_encoder", "motion_encoder")
T2M_FIRST_CONV = "main.0.weight"  # movement encoder's first Conv1d: (hidden, input channels, 4)
T2M_META_FILES = ("mean.npy", "std.npy")
T2M_META_RUN = "Comp_v6_KLD01"  # the T2M run whose meta/ the evaluation code normalizes with
MOMASK_META_RUN = "Comp_v6_KLD005"  # the same statistics in MoMask's evaluator zip
VOCABULARY_KEY = "evaluator_vocabulary"  # a GRU matcher's words, in our checkpoints


class CheckpointMismatchError(RuntimeError):
    """A checkpoint's keys or shapes do not match the network (the message lists them all)."""


@dataclass(frozen=True)
class KeyReport:
    """How a state dict matches a module."""

    missing: list[str] = field(default_factory=list)  # in the module, not in the file
    unexpected: list[str] = field(default_factory=list)  # in the file, not in the module
    mismatched: list[tuple[str, tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)
    loaded: int = 0  # tensors copied

    @property
    def ok(self) -> bool:
        return not (self.missing or self.unexpected or self.mismatched)

    def describe(self) -> str:
        lines = []
        if self.missing:
            lines.append(f"missing ({len(self.missing)}): {', '.join(self.missing)}")
        if self.unexpected:
            lines.append(f"unexpected ({len(self.unexpected)}): {', '.join(self.unexpected)}")
        if self.mismatched:
            shapes = ", ".join(
                f"{k} file {list(a)} vs model {list(b)}" for k, a, b in self.mismatched
            )
            lines.append(f"shape mismatch ({len(self.mismatched)}): {shapes}")
        return "; ".join(lines) if lines else "all keys match"


def read_checkpoint(path: str | Path, *, trusted: bool = False, map_location: str = "cpu") -> Any:
    """``torch.load`` with ``weights_only=True``; a file holding other Python objects is refused
    unless ``trusted`` (then unpickled in full, which can run code from the file)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: evaluator checkpoint not found")
    try:
        return read_checkpoint_file(path, map_location=map_location)  # corrupt files: named
    except pickle.UnpicklingError as error:
        if not trusted:
            raise ValueError(
                f"{path}: holds pickled Python objects besides tensors, so it does not load with "
                f"weights_only=True ({str(error).removeprefix(f'{path}: ')}). If you trust the file, load it "
                "with trusted=True."
            ) from error
        log.warning("%s: loading with weights_only=False (trusted=True)", path)
        return torch.load(path, map_location=map_location, weights_only=False)


def compare_state(
    module: nn.Module, state: Mapping[str, torch.Tensor], *, ignore_missing: tuple[str, ...] = ()
) -> KeyReport:
    """Key-by-key comparison; module keys starting with an ``ignore_missing`` prefix may be absent."""
    own = module.state_dict()
    missing = [k for k in own if k not in state and not k.startswith(ignore_missing)]
    unexpected = [k for k in state if k not in own]
    mismatched = [
        (k, tuple(v.shape), tuple(own[k].shape))
        for k, v in state.items()
        if k in own and tuple(v.shape) != tuple(own[k].shape)
    ]
    loadable = sum(1 for k in state if k in own) - len(mismatched)
    return KeyReport(missing, unexpected, mismatched, loadable)


def load_state(
    module: nn.Module,
    state: Mapping[str, torch.Tensor],
    *,
    source: str,
    strict: bool = True,
    ignore_missing: tuple[str, ...] = (),
) -> KeyReport:
    """Copy the matching tensors of ``state`` into ``module``.

    strict: any missing / unexpected / mismatched key raises :class:`CheckpointMismatchError`
    listing all of them; otherwise they are logged and the matching keys are loaded.
    """
    report = compare_state(module, state, ignore_missing=ignore_missing)
    if not report.ok:
        message = (
            f"{source}: checkpoint does not match {type(module).__name__}: {report.describe()}"
        )
        if strict:
            raise CheckpointMismatchError(message)
        log.warning("%s (strict=False: loading the %d matching tensors)", message, report.loaded)
    bad = {k for k, _, _ in report.mismatched}
    own = module.state_dict()
    matching = {k: v for k, v in state.items() if k in own and k not in bad}
    module.load_state_dict(matching, strict=False)
    return report


def released_interclip_state(checkpoint: Any, path: str | Path) -> dict[str, torch.Tensor]:
    """InterGen's Lightning checkpoint -> InterCLIP state dict (the ``model.`` prefix removed;
    keys without it are kept unchanged and so reported as unexpected)."""
    if not isinstance(checkpoint, dict) or not isinstance(checkpoint.get("state_dict"), dict):
        raise ValueError(f"{path}: not a Lightning checkpoint (no 'state_dict')")
    return {k.removeprefix(INTERCLIP_PREFIX): v for k, v in checkpoint["state_dict"].items()}


def released_t2m_state(checkpoint: Any, path: str | Path) -> dict[str, torch.Tensor]:
    """T2M ``finest.tar`` -> T2MMatcher state dict (``<part>.<key>`` for the three parts)."""
    if not isinstance(checkpoint, dict):
        raise ValueError(
            f"{path}: expected a dict with {T2M_PARTS}, got {type(checkpoint).__name__}"
        )
    absent = [p for p in T2M_PARTS if not isinstance(checkpoint.get(p), dict)]
    if absent:
        raise ValueError(
            f"{path}: not a T2M matcher checkpoint: missing state dicts {absent} "
            f"(top-level keys: {sorted(map(str, checkpoint))})"
        )
    return {f"{part}.{k}": v for part in T2M_PARTS for k, v in checkpoint[part].items()}


def released_t2m_input_size(checkpoint: dict[str, Any]) -> int | None:
    """Channels per frame the file's movement encoder reads (None when it has no first conv)."""
    weight = checkpoint["movement_encoder"].get(T2M_FIRST_CONV)
    return int(weight.shape[1]) if isinstance(weight, torch.Tensor) and weight.ndim == 3 else None


def default_t2m_meta_dir(path: str | Path) -> Path:
    """``t2m/Comp_v6_KLD01/meta`` for ``t2m/text_mot_match/model/finest.tar`` (T2M's release
    tree), or ``t2m/Comp_v6_KLD005/meta`` where only that one holds ``mean.npy`` (MoMask's)."""
    runs = Path(path).parent.parent.parent
    for run in (T2M_META_RUN, MOMASK_META_RUN):
        if (runs / run / "meta" / T2M_META_FILES[0]).is_file():
            return runs / run / "meta"
    return runs / T2M_META_RUN / "meta"


def released_t2m_statistics(meta_dir: str | Path, *, feature_shape: tuple[int, ...]) -> Normalizer:
    """The evaluator's own ``meta/mean.npy`` and ``meta/std.npy`` (errors name the files)."""
    meta_dir = Path(meta_dir)
    missing = [str(meta_dir / name) for name in T2M_META_FILES if not (meta_dir / name).is_file()]
    if missing:
        raise FileNotFoundError(
            f"{', '.join(missing)}: the released evaluator's statistics are missing (T2M ships "
            f"them as t2m/{T2M_META_RUN}/meta/, MoMask as t2m/{MOMASK_META_RUN}/meta/, beside "
            "t2m/text_mot_match/model/finest.tar): "
            f"pass meta_dir=<folder with {' and '.join(T2M_META_FILES)}>"
        )
    mean_path, std_path = (meta_dir / name for name in T2M_META_FILES)
    return Normalizer.from_files(mean_path, std_path, feature_shape=feature_shape)


def is_released_t2m(checkpoint: Any) -> bool:
    return isinstance(checkpoint, dict) and all(p in checkpoint for p in T2M_PARTS)


def is_released_interclip(checkpoint: Any) -> bool:
    state = checkpoint.get("state_dict") if isinstance(checkpoint, dict) else None
    return isinstance(state, dict) and any(k.startswith(INTERCLIP_PREFIX) for k in state)
