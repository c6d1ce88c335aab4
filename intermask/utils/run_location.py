"""Find what a run folder depends on after the folder tree was moved or copied.

A run records its dependencies as the paths it was given: a generator's tokenizer (``vq_ckpt``),
its text tower's cache folder and weights file; absolute, or relative to the directory the
command was started from. Its ``run_record.json`` records that directory (``cwd``) and where the
run folder was (``output_dir``), so each dependency's place *relative to the run folder* is
known, and that survives moving or copying the tree that holds both (``outputs/demo/{vq,gen}``
copied to another disk or machine). Runs written before ``cwd`` was recorded fall back to Hydra's
``.hydra/hydra.yaml`` (``hydra.runtime.cwd``) and the config's ``paths.output_dir``.

A dependency is looked for (:meth:`RunLocation.candidates`):

1. where it lies relative to the run folder, as it did when the run was written;
2. where the run's command found it (absolute, or relative to the ``cwd`` of that day);
3. relative to the current working directory (a relative path, read as given).

Loaders still check what they find (a tokenizer's weights digest), so a file that only happens to
sit at one of those places is refused.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

log = logging.getLogger(__name__)

TEXT_CACHE = "intermask.text.cache.TextFeatureCache"
TEXT_ENCODER = "intermask.text.clip_encoder.FrozenCLIPTextEncoder"
WEIGHT_SUFFIXES = (".pt", ".pth", ".bin", ".safetensors", ".ckpt")


def _normal(path: Path) -> Path:
    return Path(os.path.normpath(path))


@dataclass(frozen=True)
class RunLocation:
    """A run folder as it is now, and where it and its command's working directory were."""

    folder: Path  # the run folder now
    cwd: Path | None  # the directory its command was started from (absolute), when recorded
    recorded_folder: Path | None  # the run folder as recorded (absolute, or relative to cwd)

    @classmethod
    def of(cls, folder: str | Path, config: DictConfig | None = None) -> RunLocation:
        """Read ``folder``'s ``run_record.json`` (or Hydra's record and ``config``)."""
        folder = Path(folder)
        record = _read_json(folder / "run_record.json")
        cwd = record.get("cwd") or _hydra_cwd(folder)
        recorded = record.get("output_dir")
        if recorded is None and config is not None:
            recorded = OmegaConf.select(config, "paths.output_dir", default=None)
        return cls(
            folder=folder,
            cwd=None if cwd is None else Path(cwd),
            recorded_folder=None if recorded is None else Path(str(recorded)),
        )

    def _then(self, path: Path) -> Path | None:
        """``path`` as the run's command saw it, made absolute (None: its cwd is unknown)."""
        if path.is_absolute():
            return _normal(path)
        return None if self.cwd is None else _normal(self.cwd / path)

    def candidates(self, recorded: str | Path) -> list[tuple[Path, str]]:
        """Where a recorded path may be now, in the order to try, each with where it comes from."""
        recorded = Path(recorded)
        found: list[tuple[Path, str]] = []
        if self.recorded_folder is not None:
            then, folder = self._then(recorded), self._then(self.recorded_folder)
            if then is None or folder is None:  # both relative to an unknown cwd: same base
                both_relative = not (recorded.is_absolute() or self.recorded_folder.is_absolute())
                then, folder = (recorded, self.recorded_folder) if both_relative else (None, None)
            if then is not None and folder is not None:
                inside = _normal(self.folder / os.path.relpath(then, folder))
                found.append((inside, "relative to the run folder, as when the run was written"))
        then = self._then(recorded)
        if then is not None:
            found.append((then, "as the run's command found it"))
        if not recorded.is_absolute():
            found.append((_normal(Path.cwd() / recorded), "relative to the working directory"))
        unique: dict[Path, str] = {}
        for path, why in found:
            unique.setdefault(path, why)
        return list(unique.items())

    def locate(self, recorded: str | Path, *, what: str, source: str | Path) -> Path:
        """The first existing file among :meth:`candidates`; else an error naming each place
        looked at. ``what`` names the dependency, ``source`` the file that recorded it."""
        candidates = self.candidates(recorded)
        for path, _ in candidates:
            if path.is_file():
                return path
        places = "; ".join(f"{path} ({why})" for path, why in candidates)
        raise FileNotFoundError(
            f"{what} recorded in {source} as {str(recorded)!r} is missing; looked for {places}"
        )

    def relocated(self, node: Any) -> Any:
        """A checked run config section (a plain container) with its text towers' relative
        cache folders and weights files found from here (:meth:`candidates`). A cache folder
        found nowhere is created where its parent folder exists, else it becomes None
        (features computed in memory, logged); a weights file found nowhere is left as
        recorded, for the encoder's own error."""
        if isinstance(node, list):
            return [self.relocated(value) for value in node]
        if not isinstance(node, dict):
            return node
        node = {key: self.relocated(value) for key, value in node.items()}
        target = node.get("_target_")
        if target == TEXT_CACHE and isinstance(node.get("cache_dir"), str):
            node["cache_dir"] = self._cache_dir(node["cache_dir"])
        if target == TEXT_ENCODER and _is_weights_file(node.get("pretrained")):
            existing = [p for p, _ in self.candidates(node["pretrained"]) if p.is_file()]
            if existing:
                node["pretrained"] = str(existing[0])
        return node

    def _cache_dir(self, recorded: str) -> str | None:
        candidates = [p for p, _ in self.candidates(recorded)]
        existing = [p for p in candidates if p.is_dir()]
        if existing:
            return str(existing[0])
        # not written yet (a converted release's): where its parent folder exists, as before
        creatable = [p for p in candidates if p.parent.is_dir()]
        if creatable:
            return str(creatable[0])
        log.info(
            "%s: the text cache folder %s (recorded by the run) is not found from here: text "
            "features are computed in memory",
            self.folder,
            recorded,
        )
        return None


def _is_weights_file(value: Any) -> bool:
    return isinstance(value, str) and (value.endswith(WEIGHT_SUFFIXES) or os.sep in value)


def _read_json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: unreadable run record ({error})") from error
    return record if isinstance(record, dict) else {}


def _hydra_cwd(folder: Path) -> str | None:
    path = folder / ".hydra" / "hydra.yaml"
    if not path.is_file():
        return None
    return OmegaConf.select(OmegaConf.load(path), "hydra.runtime.cwd", default=None)
