"""Payloads for the hostile-file tests: each writes a marker file if anything ever runs it."""

from __future__ import annotations

from pathlib import Path


class ExecPayload:
    """Pickles to a call of ``exec`` that writes ``marker``: unpickling it with ``pickle.load``
    runs it; the tests assert that the marker never appears."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').write('ran')",))


def exec_target(marker: Path) -> dict:
    """The same payload as a Hydra node: ``instantiate`` would call ``exec``."""
    return {"_target_": "builtins.exec", "_args_": [f"open({str(marker)!r}, 'w').write('ran')"]}
