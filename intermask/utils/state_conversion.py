"""The outcome of converting another implementation's state dict into this framework's layout
(``intermask/interm/reference.py``, ``intermask/vq/reference.py``).

Every problem is named by the *release's* key (what the user can find in their file), with the
key of ours it was converted to beside it; only keys of ours that got no value at all are named
by our key, as nothing in the release corresponds to them.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import torch


def compare_with_target(
    converted: Mapping[str, torch.Tensor],
    target: Mapping[str, torch.Tensor] | None,
    sources: Mapping[str, str] | None = None,
) -> tuple[list[str], list[str], list[str]]:
    """(missing, extra, mismatched): ``target``'s keys that got no value, release keys whose
    converted key ``target`` lacks, and shape mismatches; all empty when ``target`` is None.
    ``sources``: converted key -> the release key it came from."""
    if target is None:
        return [], [], []
    sources = sources or {}

    def named(key: str) -> str:
        return f"{sources[key]} (-> {key})" if key in sources else f"{key} (converted)"

    missing = sorted(set(target) - set(converted))
    extra = [named(key) for key in sorted(set(converted) - set(target))]
    mismatched = [
        f"{named(key)}: release {tuple(converted[key].shape)} vs ours {tuple(target[key].shape)}"
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
    mismatched: list[str]  # "release key (-> ours): release (shape) vs ours (shape)"
    why: tuple[str, ...] = ()  # why keys are dropped or computed, for the report

    @property
    def complete(self) -> bool:
        return not (self.unmapped or self.missing or self.mismatched)

    def report(self) -> str:
        """Every key that was not copied one to one, by name (modules of many dropped keys as
        ``prefix.* (n keys)``), then the reasons."""
        copied = len(set(self.state) - set(self.computed))
        lines = [f"loaded {copied} tensor(s) from the release"]
        for title, keys, group in (
            ("dropped on purpose", self.dropped, True),
            ("computed here", self.computed, False),
            ("release keys with no place here", self.unmapped, False),
            ("keys of ours without a value", self.missing, False),
            ("shape mismatches", self.mismatched, False),
        ):
            if keys:
                listed = _grouped(keys) if group else keys
                lines.append(f"{title} ({len(keys)}): " + ", ".join(listed))
        return "\n".join(lines + list(self.why))


def _grouped(keys: Sequence[str]) -> list[str]:
    """Keys under a top-level module holding more than 3 of them as ``module.* (n keys)``."""
    modules = Counter(key.split(".")[0] for key in keys)
    listed, seen = [], set()
    for key in keys:
        module = key.split(".")[0]
        if modules[module] <= 3:
            listed.append(key)
        elif module not in seen:
            seen.add(module)
            listed.append(f"{module}.* ({modules[module]} keys)")
    return listed
