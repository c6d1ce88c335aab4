"""Every command in README.md and docs/*.md runs as written, as far as a test can afford.

Each command line of a fenced code block is checked the way it would run, up to the point where
it would start working:

- ``make TARGET VAR=... ARGS="..."``: the target exists, ``make -n`` expands it as written, and
  every job command it would run is checked as below;
- ``python -m intermask.train --config-name JOB ...`` and ``python -m intermask.evaluate ...``:
  Hydra composes the job's config with the line's overrides (an unknown key, group or option
  fails here);
- ``intermask ...``: the console script's parser accepts the arguments;
- ``python -m intermask.body ...``: its parser accepts the arguments;
- ``python tools/...``: the script exists and defines every option the line passes;
- ``.venv-parity/bin/python tools/parity/SCRIPT ...``: the script exists and defines every
  option the line passes.

Not run: the jobs themselves (training, evaluation and generation take minutes to hours; the
demo, ``make overfit`` and the tests cover them end to end), ``git clone`` (network), and
``make parity*`` targets' scripts against the authors' code (they need those checkouts).
Placeholders (``<vq run>``, ``RUN``, ``"..."``) are replaced by a dummy path: what is checked
is the command's shape, not the user's files.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from intermask.cli import build_parser
from intermask.train import CONFIG_DIR

REPO = Path(__file__).resolve().parents[1]
# docs/extending.md's commands need the files the page has the user write: tests/test_extending.py
# writes them and runs the page's commands for real
PAGES = [
    REPO / "README.md",
    *sorted(p for p in (REPO / "docs").glob("*.md") if p.name != "extending.md"),
]
PLACEHOLDER = "placeholder"
FENCE = re.compile(r"^```[a-z]*\n(.*?)^```", re.S | re.M)
COMMANDS = ("make", "intermask", "python", ".venv-parity/bin/python", "git")


@dataclass(frozen=True)
class Command:
    page: str
    line: int
    text: str

    def __str__(self) -> str:
        return f"{self.page}:{self.line}: {self.text}"


def _commands() -> list[Command]:
    found = []
    for page in PAGES:
        text = page.read_text()
        for block in FENCE.finditer(text):
            number = text.count("\n", 0, block.start()) + 2  # the block's first line
            pending, first = "", number
            for raw in block.group(1).splitlines():
                if not pending:
                    first = number
                number += 1
                if raw.rstrip().endswith("\\"):
                    pending += raw.rstrip()[:-1] + " "
                    continue
                command = (pending + raw).split(" #", 1)[0].strip()
                pending = ""
                if command.split(" ", 1)[0] in COMMANDS:
                    found.append(Command(page.relative_to(REPO).as_posix(), first, command))
    return found


def _words(command: str) -> list[str]:
    """The line's words with placeholders made concrete."""
    command = re.sub(r"\$\((?:[^()]|\([^()]*\))*\)", PLACEHOLDER, command)  # $(ls ...)
    command = re.sub(r"<[^<>]*>", PLACEHOLDER, command)
    words = shlex.split(command)
    return [PLACEHOLDER if w in ("RUN", "MASK_RUN", "RESIDUAL_RUN", "...") else w for w in words]


def _compose(job: str, overrides: list[str], where: str) -> None:
    kept = [o for o in overrides if not o.startswith(("hydra.", "hydra/", "-m", "--multirun"))]
    if "-m" in overrides or "--multirun" in overrides:  # a sweep: each of its values composes
        for i, override in enumerate(kept):
            key, _, values = override.partition("=")
            if "," in values and not values.startswith(("[", "{", "'", '"')):
                for value in values.split(","):
                    _compose(job, [*kept[:i], f"{key}={value}", *kept[i + 1 :]], where)
                return
    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
            compose(job, overrides=kept)
    except Exception as error:  # the message names the bad override
        pytest.fail(f"{where}: the {job} config does not compose with {kept}: {error}")
    launcher = [o for o in overrides if o.startswith("hydra/launcher=")]
    for choice in launcher:
        name = choice.split("=", 1)[1]
        assert (Path(CONFIG_DIR) / "hydra" / "launcher" / f"{name}.yaml").is_file(), where


def _check_python(words: list[str], where: str) -> None:
    if words[:3] == ["python", "-m", "intermask.evaluate"]:
        _compose("eval", words[3:], where)
    elif words[:3] == ["python", "-m", "intermask.train"]:
        assert words[3] == "--config-name", f"{where}: {words}"
        _compose(words[4], words[5:], where)
    elif words[:3] == ["python", "-m", "intermask.body"]:
        from intermask.body.command import add_body_arguments

        parser = argparse.ArgumentParser(exit_on_error=False)
        add_body_arguments(parser)
        try:
            parser.parse_args(words[3:])
        except (argparse.ArgumentError, SystemExit) as error:
            pytest.fail(f"{where}: python -m intermask.body refuses it ({error})")
    elif len(words) > 1 and words[1].startswith("tools/"):
        _check_parity(words, where)
    else:
        pytest.fail(f"{where}: a python command this test does not know how to check")


def _check_intermask(words: list[str], where: str) -> None:
    try:
        build_parser().parse_args(words[1:])
    except SystemExit as stop:
        pytest.fail(f"{where}: the intermask parser refuses it (exit {stop.code})")


def _check_parity(words: list[str], where: str) -> None:
    script = REPO / words[1]
    assert script.is_file(), f"{where}: {words[1]} does not exist"
    source = script.read_text()
    for option in (w for w in words[2:] if w.startswith("--")):
        assert f'"{option}"' in source, f"{where}: {words[1]} has no option {option}"


def _job_lines(dry_run: str) -> list[list[str]]:
    """The job commands a ``make -n`` listing would run, as word lists starting at the job."""
    jobs = []
    for line in dry_run.replace("\\\n", " ").splitlines():
        words = shlex.split(re.sub(r"\$\((?:[^()]|\([^()]*\))*\)", PLACEHOLDER, line))
        for i, word in enumerate(words):
            if word.endswith("/python") and words[i + 1 : i + 2] == ["-m"]:
                if words[i + 2] in ("intermask.train", "intermask.evaluate"):
                    jobs.append(["python", *words[i + 1 :]])
            elif word.endswith("/intermask") and i == 0:
                jobs.append(["intermask", *words[i + 1 :]])
    return jobs


def _check_make(words: list[str], where: str) -> None:
    targets = [w for w in words[1:] if "=" not in w]
    variables = [w for w in words[1:] if "=" in w]
    makefile = (REPO / "Makefile").read_text()
    for target in targets:
        assert re.search(rf"^{re.escape(target)}:", makefile, re.M), f"{where}: no target {target}"
    for variable in variables:
        name = variable.split("=", 1)[0]
        assert f"$({name})" in makefile or f"{name} ?=" in makefile, (
            f"{where}: the Makefile does not read {name}"
        )
    # as a user types it: under `make test ARGS=...` (.ci/run) make exports the suite's ARGS (and
    # MAKEFLAGS) to this process, and every job line would end with pytest's options
    own = set(re.findall(r"^([A-Z_]+) \?=", makefile, re.M)) | {"MAKEFLAGS", "MFLAGS", "MAKELEVEL"}
    clean = {k: v for k, v in os.environ.items() if k not in own}
    done = subprocess.run(
        ["make", "-n", *words[1:]], cwd=REPO, env=clean, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, f"{where}: make -n failed: {done.stderr}"
    for job in _job_lines(done.stdout):
        (_check_intermask if job[0] == "intermask" else _check_python)(job, f"{where} (make)")


COMMAND_LIST = _commands()


def test_the_pages_hold_the_commands_users_run():
    pages = {c.page for c in COMMAND_LIST}
    assert {"README.md", "docs/reproducing.md", "docs/momask.md", "docs/demo.md"} <= pages
    assert len(COMMAND_LIST) >= 40


@pytest.mark.parametrize("command", COMMAND_LIST, ids=str)
def test_a_documented_command_is_well_formed(command: Command):
    words, where = _words(command.text), str(command)
    if words[0] == "make":
        _check_make(words, where)
    elif words[0] == "intermask":
        _check_intermask(words, where)
    elif words[0] == "python":
        _check_python(words, where)
    elif words[0] == ".venv-parity/bin/python":
        _check_parity(words, where)
    else:
        assert words[:2] == ["git", "clone"] and words[2].startswith("https://github.com/"), where
