"""Identifying files: every result names the checkpoints that produced it by content hash, and
every loader reaches a run's config and weights through :func:`open_run_checkpoint`."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from intermask.utils.checkpoint_files import read_checkpoint_file
from intermask.utils.run_location import RunLocation

HASH_CHARS = 16


def file_hash(path: str | Path, *, chars: int = HASH_CHARS) -> str:
    """First ``chars`` hex digits of the file's SHA-256 (read in 1 MiB chunks)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: cannot hash a missing file")
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()[:chars]


def resolve_checkpoint(path: str | Path, *, kind: str) -> Path:
    """A checkpoint file, or a run directory -> its ``checkpoints/last.ckpt``; errors name
    ``kind`` (e.g. "generator") and what was looked for."""
    path = Path(path)
    if path.is_dir():
        candidate = path / "checkpoints" / "last.ckpt"
        if not candidate.is_file():
            raise FileNotFoundError(
                f"{path}: not a {kind} checkpoint and no {candidate.relative_to(path)} inside"
            )
        return candidate
    if not path.is_file():
        raise FileNotFoundError(f"{path}: {kind} checkpoint not found")
    return path


@dataclass(frozen=True)
class RunCheckpoint:
    """A checkpoint of a training run with the run's resolved config beside it; the weights are
    read (``weights_only``) on first use, so a loader checks the config before touching them."""

    checkpoint: Path  # <run>/checkpoints/<name>.ckpt
    config_path: Path  # <run>/config.yaml
    config: DictConfig
    map_location: str = "cpu"

    @cached_property
    def location(self) -> RunLocation:
        """The run folder now and where it was: finds what the run depends on after a move."""
        return RunLocation.of(self.checkpoint.parent.parent, self.config)

    @cached_property
    def stored(self) -> dict[str, Any]:
        return read_checkpoint_file(self.checkpoint, map_location=self.map_location)

    def text(self) -> Any:
        """The run's frozen text tower (a :class:`~intermask.text.cache.TextFeatureCache` from its
        ``text`` config, checked against the loadable targets and found from the run folder
        wherever the tree moved)."""
        from hydra.utils import instantiate

        from intermask.utils.run_config import check_targets

        if "text" not in self.config:
            raise ValueError(f"{self.config_path}: the run config has no text section")
        config = check_targets(self.config.text, source=self.config_path, section="text")
        return instantiate(self.location.relocated(config))

    def weights(self, prefix: str = "") -> dict[str, Any]:
        """The state dict entries under ``prefix``, with the prefix removed."""
        state = self.stored["state_dict"]
        return {k.removeprefix(prefix): v for k, v in state.items() if k.startswith(prefix)}


def open_run_checkpoint(path: str | Path, *, kind: str, map_location: str = "cpu") -> RunCheckpoint:
    """A checkpoint file or a run directory (its last.ckpt) -> :class:`RunCheckpoint`: the one
    path every loader (VQ, generator, ARFlow) takes to a run's config and weights. Errors name
    ``kind`` and the file."""
    checkpoint = resolve_checkpoint(path, kind=kind)
    config_path = run_config_path(checkpoint, kind=kind)
    return RunCheckpoint(checkpoint, config_path, OmegaConf.load(config_path), map_location)


def run_config_path(checkpoint: Path, *, kind: str) -> Path:
    """``<run>/config.yaml`` of ``<run>/checkpoints/<name>.ckpt``; a missing one is an error
    naming ``kind`` (e.g. "VQ") and where the file was expected."""
    config_path = checkpoint.parent.parent / "config.yaml"
    if not config_path.is_file():
        raise FileNotFoundError(
            f"{config_path}: the run config of the {kind} checkpoint is missing "
            "(expected <run>/config.yaml beside <run>/checkpoints/)"
        )
    return config_path
