"""Errors raised by the dataset readers."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


class DataError(ValueError):
    """A dataset file is missing, unreadable or malformed.

    The message always names the file and the problem (expected value and received value where
    there is one), so that a user can fix the data without reading our code.
    """


@dataclass(frozen=True)
class DataProblem:
    """One problem found in a dataset: the offending file and what is wrong with it."""

    path: Path
    problem: str

    def __str__(self) -> str:
        return f"{self.path}: {self.problem}"

    def error(self) -> DataError:
        return DataError(str(self))


@dataclass(frozen=True)
class SkippedClip:
    """A clip left out on purpose (too short, on the ignore list); kept for the explicit skip log."""

    clip_id: str
    reason: str
