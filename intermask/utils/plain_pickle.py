"""Pickles from datasets and shared folders, read without running code.

``pickle.load`` calls whatever the file names, so a dataset's ``.pkl`` can run code the moment it
is read. The files this framework reads (Inter-X's ``interaction_order.pkl``, GloVe word lists)
hold plain containers: :func:`load_plain_pickle` builds those and numpy scalars only, and refuses
anything else naming the file and the class it asked for.
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

# numpy scalars (an np.int64 value in a dict) are rebuilt from a dtype and raw bytes: no code runs
_ALLOWED_CLASSES = frozenset(
    {
        ("numpy", "dtype"),
        ("numpy.core.multiarray", "scalar"),
        ("numpy._core.multiarray", "scalar"),
    }
)


class UnsafePickle(pickle.UnpicklingError):
    """The pickle asks for a class or function beyond plain containers and numpy scalars."""


class PlainUnpickler(pickle.Unpickler):
    """Builds dicts, lists, tuples, sets, strings, numbers and numpy scalars only."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in _ALLOWED_CLASSES:
            return super().find_class(module, name)
        raise UnsafePickle(
            f"refusing to load {module}.{name}: only plain containers and numpy scalars are read"
        )


def load_plain_pickle(path: str | Path) -> Any:
    """The plain object pickled in ``path``; errors name the file: FileNotFoundError when it is
    missing, :class:`UnsafePickle` for a payload, ValueError when it is not a readable pickle."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found")
    with path.open("rb") as handle:
        try:
            return PlainUnpickler(handle).load()
        except UnsafePickle as error:
            raise UnsafePickle(f"{path}: {error}") from None
        except (pickle.UnpicklingError, EOFError, ValueError, TypeError, IndexError) as error:
            raise ValueError(f"{path}: not a readable pickle ({error!r})") from error
