"""The package's stage order, enforced on every import (module-level and inside functions).

Low to high; a module may import its own stage and the stages below it, never above, and no two
modules import each other through any chain. The README's Layout section states the order.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "intermask"
STAGES = [
    ["utils", "config_files", "release_options"],
    ["motion"],
    ["physics"],
    ["data"],
    ["metrics"],
    ["text"],
    ["vq"],
    ["interm"],
    ["evaluator", "reaction", "render", "momask", "body"],
    ["evaluation"],
    ["train", "generate", "convert", "convert_momask"],
    ["evaluate", "overfit", "overfit_momask", "bench"],
    ["cli", "<package>"],
]
RANK = {name: level for level, names in enumerate(STAGES) for name in names}


def _modules() -> dict[str, Path]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = ("intermask", *path.relative_to(PACKAGE).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def _imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    """module -> the intermask modules it imports (resolved to a module of the package)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            targets = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [f"{node.module}.{alias.name}" for alias in node.names] + [node.module]
            elif isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            for target in targets:
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target.startswith("intermask") and target != name:
                    graph[name].add(target)
                    break
    return graph


def _stage(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "<package>"


def test_every_stage_is_named():
    stages = {_stage(name) for name in _modules()}
    assert stages <= set(RANK), stages - set(RANK)


def test_no_import_goes_up_a_stage():
    upward = sorted(
        f"{source} -> {target}"
        for source, targets in _imports(_modules()).items()
        for target in targets
        if RANK[_stage(target)] > RANK[_stage(source)]
    )
    assert upward == []


def test_no_import_cycle():
    graph = _imports(_modules())
    # a package __init__ re-exporting its own modules is not a cycle of the code
    edges = {
        source: {
            t for t in targets if not source.startswith(f"{t}.") and not t.startswith(f"{source}.")
        }
        for source, targets in graph.items()
    }
    cycles, state = [], {}

    def visit(node: str, stack: list[str]) -> None:
        state[node] = "open"
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == "open":
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt, [*stack, nxt])
        state[node] = "done"

    for module in sorted(edges):
        if module not in state:
            visit(module, [module])
    assert cycles == []
