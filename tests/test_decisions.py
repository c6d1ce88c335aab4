"""Code, configs and docs cite docs/decisions.md's rows by name; every name cited is a row."""

from __future__ import annotations

import re
from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from intermask.train import CONFIG_DIR

ROOT = Path(CONFIG_DIR).parent
CODE = ("intermask", "configs", "callbacks", "tools", "tests")
CITATION = re.compile(r"docs/decisions\.md`?:[\s#@]*")


def _anchors() -> list[str]:
    table = (ROOT / "docs" / "decisions.md").read_text()
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    assert rows, "no rows"
    for row in rows:
        assert row.count(" | ") >= 3, row  # setting | default | why | evidence
    return [re.match(r"\| `([^`]+)`", row).group(1) for row in rows]


def _files(*tops: str) -> list[Path]:
    files = [ROOT / "Makefile"]
    for top in tops:
        for suffix in ("py", "yaml", "md"):
            files += [p for p in (ROOT / top).rglob(f"*.{suffix}") if "__pycache__" not in p.parts]
    return files


def test_each_row_has_its_own_name():
    anchors = _anchors()
    assert len(anchors) == len(set(anchors))


def test_every_citation_names_a_row():
    anchors = _anchors()
    unresolved = []
    for path in _files(*CODE, "docs"):
        text = path.read_text()
        for match in CITATION.finditer(text):
            rest = text[match.end() : match.end() + 80]
            if not any(
                rest.startswith(name) and not re.match(r"\w|\.\w", rest[len(name) : len(name) + 2])
                for name in anchors
            ):
                unresolved.append(f"{path.relative_to(ROOT)}: {rest.splitlines()[0]}")
    assert unresolved == []


def test_code_cites_decisions_not_the_notebook():
    notebook = re.compile(
        r"learning\.md|notebook\.md|\b(\d+(st|nd|rd|th)|third|fourth|fifth|sixth|seventh|eighth"
        r"|ninth|tenth|eleventh|twelfth|\w+teenth|\w+tieth)(-\w+)? pass(es)?\b"
    )
    this = Path(__file__).resolve()
    hits = [
        f"{path.relative_to(ROOT)}: {match.group(0)}"
        for path in _files(*CODE)
        if path.resolve() != this
        for match in notebook.finditer(path.read_text())
    ]
    assert hits == []


def test_the_config_rows_name_keys_that_exist():
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        configs = [
            compose("eval", overrides=["eval_ckpt=x.ckpt", "experiment=eval_demo"]),
            compose("train_gen", overrides=["experiment=gen_demo", "vq_ckpt=x.ckpt"]),
            compose("train_vq", overrides=["experiment=vq_demo"]),
        ]
    keys = [
        a
        for a in _anchors()
        if a.split(".")[0] in {"sampler", "model", "data", "trainer", "protocol"}
    ]
    assert len(keys) > 20
    missing = [k for k in keys if all(OmegaConf.select(c, k) is None for c in configs)]
    assert missing == []
