"""Which reader serves which dataset kind, and the reader a config injects.

The one place a dataset kind is mapped to code: the DataModule and the statistics ask here for
a :class:`~intermask.data.reader.ClipReader` class and read its class attributes (feature shape,
default lengths, augmentation) instead of comparing names.
"""

from __future__ import annotations

import importlib

from intermask.data.interhuman import InterHumanDataset
from intermask.data.interx import InterXDataset
from intermask.data.reader import ClipReader
from intermask.motion.kinds import DatasetKind, check_dataset_kind

READERS: dict[DatasetKind, type[ClipReader]] = {
    "interhuman": InterHumanDataset,
    "interx": InterXDataset,
}


def reader_class(kind: str, reader: str | type[ClipReader] | None = None) -> type[ClipReader]:
    """The reader of dataset ``kind``: ``reader`` when given (a class or its dotted import
    path, e.g. ``mypackage.readers.MyInterHumanLayout``), else the framework's own.

    An injected reader must be a :class:`ClipReader` producing the features of ``kind`` (its
    ``kind`` attribute), since everything downstream (VQ view, evaluator, joints) follows the kind.
    """
    kind = check_dataset_kind(kind)
    if reader is None:
        return READERS[kind]
    cls = _import_class(reader) if isinstance(reader, str) else reader
    if not (isinstance(cls, type) and issubclass(cls, ClipReader)):
        raise TypeError(f"reader {reader!r} is not a subclass of intermask.data.reader.ClipReader")
    if cls.kind != kind:
        raise ValueError(
            f"reader {cls.__module__}.{cls.__qualname__} reads {cls.kind!r} features, but the "
            f"dataset kind is {kind!r}: set data.dataset={cls.kind} or pick a {kind} reader"
        )
    return cls


def _import_class(path: str) -> object:
    module, _, name = path.rpartition(".")
    if not module:
        raise ValueError(f"reader must be a dotted path 'package.module.Class', got {path!r}")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as err:
        raise ValueError(f"reader {path!r} cannot be imported ({err})") from err
