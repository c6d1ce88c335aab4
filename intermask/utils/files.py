"""Identifying files: every result names the checkpoints that produced it by content hash."""

from __future__ import annotations

import hashlib
from pathlib import Path

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
