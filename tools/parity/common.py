"""What every parity script shares: importing the authors' code from a checkout the user names,
the CPU patches it needs (no downloads, no ``.cuda()``), seeded weights that the fast tests can
rebuild without the authors' code, and the fixture files.

Nothing of the authors' code is copied here: their modules are imported from ``--reference``.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import importlib
import sys
import types
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[2]
# run as `python tools/parity/<script>.py` from anywhere: this framework, and the fixture format
# the tests read (tests/parity/fixtures_io.py)
for _folder in (REPO, REPO / "tests" / "parity"):
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

from fixtures_io import (  # noqa: E402
    FIXTURES,
    MAX_FIXTURE_BYTES,
    build_state,
    load_fixture,
    save_fixture,
    seeded_state,
    weight_recipe,
)

__all__ = [
    "FIXTURES",
    "MAX_FIXTURE_BYTES",
    "load_fixture",
    "parser",
    "reference_modules",
    "save_fixture",
    "seeded_state",
    "weight_recipe",
    "build_state",
    "clip_stub",
    "max_abs",
]

# top-level package names the authors' repositories use, which a second checkout would shadow
_THEIR_PACKAGES = (
    "models",
    "utils",
    "data",
    "options",
    "common",
    "dataset",
    "motion_loaders",
    "datasets",
    "configs",
    "tools",
    "visualization",
)


def parser(description: str, *, marker: str) -> argparse.ArgumentParser:
    """The common command line: ``--reference PATH`` (a checkout holding ``marker``) and
    ``--write-fixture`` (regenerate the committed fixture instead of only printing)."""
    cli = argparse.ArgumentParser(description=description)
    cli.add_argument(
        "--reference",
        required=True,
        type=Path,
        help=f"a checkout of the authors' repository (it holds {marker})",
    )
    cli.add_argument(
        "--write-fixture",
        action="store_true",
        help="also (re)write the fixture under tests/parity/fixtures/",
    )
    cli.set_defaults(marker=marker)
    return cli


@contextlib.contextmanager
def reference_modules(checkout: Path, marker: str) -> Iterator[None]:
    """The authors' checkout first on ``sys.path`` (its ``models``, ``utils``, ... importable),
    removed again afterwards with every module imported from it."""
    checkout = Path(checkout).resolve()
    if not (checkout / marker).is_file():
        raise SystemExit(f"{checkout}: not the expected checkout (no {marker})")
    before = set(sys.modules)
    for name in list(sys.modules):
        if name.split(".")[0] in _THEIR_PACKAGES:
            del sys.modules[name]
    sys.path.insert(0, str(checkout))
    try:
        yield
    finally:
        sys.path.remove(str(checkout))
        for name in set(sys.modules) - before:
            if name.split(".")[0] in _THEIR_PACKAGES:
                del sys.modules[name]


def clip_stub(model: torch.nn.Module, tokenize: Any) -> types.ModuleType:
    """A ``clip`` module (OpenAI's package) whose ``load`` returns a copy of ``model`` instead of
    downloading weights and whose ``tokenize`` is ``tokenize``; installed in ``sys.modules``.

    Every call gets its own copy, as every ``clip.load`` reads its own weights: the authors'
    modules keep CLIP's embeddings as submodules, and loading a checkpoint into one of them
    (InterCLIP's ``token_embedding``) must not change another's (the generator's text input).
    """
    module = types.ModuleType("clip")
    module.load = lambda *args, **kwargs: (copy.deepcopy(model), None)
    module.tokenize = tokenize
    sys.modules["clip"] = module
    return module


def max_abs(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a.double() - b.double()).abs().max())


def import_module(name: str) -> types.ModuleType:
    return importlib.import_module(name)


def shapes_of(state: Mapping[str, torch.Tensor], *, skip: Sequence[str] = ()) -> dict[str, tuple]:
    return {k: tuple(v.shape) for k, v in state.items() if not k.startswith(tuple(skip))}


def as_numpy(x: Any) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)
