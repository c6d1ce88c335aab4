"""The outcome of converting another implementation's state dict into this framework's layout
(``intermask/interm/reference.py``, ``intermask/vq/reference.py``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import torch


def compare_with_target(
    converted: Mapping[str, torch.Tensor], target: Mapping[str, torch.Tensor] | None
) -> tuple[list[str], list[str], list[str]]:
    """(missing, extra, mismatched): ``target``'s keys that got no value, converted keys it
    lacks (named "key (converted)") and shape mismatches; all empty when ``target`` is None."""
    if target is None:
        return [], [], []
    missing = sorted(set(target) - set(converted))
    extra = [f"{key} (converted)" for key in sorted(set(converted) - set(target))]
    mismatched = [
        f"{key}: ours {tuple(target[key].shape)} vs converted {tuple(converted[key].shape)}"
        for key in sorted(set(converted) & set(target))
        if target[key].shape != converted[key].shape
    ]
    return missing, extra, mismatched


class Conversion(NamedTuple):
    """A converted state dict and what did not map."""

    state: dict[str, torch.Tensor]
    dropped: list[str]  # reference keys left out on purpose (e.g. a frozen CLIP tower)
    computed: list[str]  # values this model computes itself: checked against the reference's
    # buffer, or derived from the reference's weights (the VQ's EMA statistics)
    unmapped: list[str]  # reference keys with no place here
    missing: list[str]  # keys of ``target`` that got no value (empty when target is None)
    mismatched: list[str]  # "key: ours (shape) vs converted (shape)"

    @property
    def complete(self) -> bool:
        return not (self.unmapped or self.missing or self.mismatched)

    def report(self) -> str:
        lines = [
            f"dropped {len(self.dropped)} key(s) on purpose, computed {len(self.computed)} here"
        ]
        for title, keys in (
            ("reference keys with no place", self.unmapped),
            ("keys without a value", self.missing),
            ("shape mismatches", self.mismatched),
        ):
            if keys:
                lines.append(f"{title} ({len(keys)}): " + ", ".join(keys))
        return "\n".join(lines)
