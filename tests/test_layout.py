"""Repository rules that pytest itself only reports by failing collection."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def test_test_modules_have_unique_names():
    # without __init__.py files pytest imports test modules by basename: two equal names in
    # different folders break collection of the whole suite
    names = Counter(path.name for path in TESTS.rglob("*.py") if path.name != "conftest.py")
    assert [name for name, count in names.items() if count > 1] == []
