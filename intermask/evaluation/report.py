"""Protocol results as JSON and as a Markdown table in the layout of InterMask's Table 1."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path

from intermask.evaluation.protocol import ProtocolResult, Summary
from intermask.utils.staging import staged_outputs

RESULT_FILES = ("results.json", "results.md")

# (key, heading, direction): the paper's columns in its order, then the extra ones we report
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("top1", "R-Prec Top 1", "↑"),
    ("top2", "R-Prec Top 2", "↑"),
    ("top3", "R-Prec Top 3", "↑"),
    ("fid", "FID", "↓"),
    ("mm_dist", "MM Dist", "↓"),
    ("diversity", "Diversity", "→"),
    ("multimodality", "MModality", "↑"),
    ("mpjpe_mm", "MPJPE (mm)", "↓"),
    ("iv_cm3", "IV (cm³)", "↓"),
    ("if", "IF", "↓"),
    ("mesh_iv_cm3", "Mesh IV (cm³)", "↓"),  # on fitted SMPL-X / SMPL-H bodies (docs/bodies.md)
    ("mesh_if", "Mesh IF", "↓"),
    ("mesh_fit_error_mm", "Body fit (mm)", "↓"),
    ("latency_ms", "Latency (ms/sample)", "↓"),
    ("success", "Success %", "↑"),
)
PERCENT_COLUMNS = frozenset({"success"})  # rates kept in [0, 1] in the JSON, printed x 100


def format_summary(summary: Summary) -> str:
    """``0.449±.004``: three decimals, the CI without its leading zero, as the paper prints."""
    ci = f"{summary.ci95:.3f}"
    return f"{summary.mean:.3f}±{ci[1:] if ci.startswith('0.') else ci}"


def format_percent(summary: Summary) -> str:
    """``97.3±1.2``: a rate in [0, 1] as a percentage with one decimal."""
    return f"{100 * summary.mean:.1f}±{100 * summary.ci95:.1f}"


def _cell(key: str, summary: Summary) -> str:
    return format_percent(summary) if key in PERCENT_COLUMNS else format_summary(summary)


def markdown_table(result: ProtocolResult) -> str:
    """Header lines (dataset, evaluator, checkpoints, constants) and the table; a column
    appears when at least one row has it."""
    present = [c for c in COLUMNS if any(c[0] in row for row in result.rows.values())]
    lines = [f"### {_title(result)}", ""]
    for key, value in result.header.items():
        if key != "constants":
            lines.append(f"- **{key}**: {value}")
    constants = result.header.get("constants", {})
    if constants:
        lines.append("- **constants**: " + ", ".join(f"{k}={v}" for k, v in constants.items()))
    lines += [
        "",
        "| Method | " + " | ".join(f"{heading} {arrow}" for _, heading, arrow in present) + " |",
        "|---|" + "---|" * len(present),
    ]
    for row, metrics in result.rows.items():
        cells = [_cell(key, metrics[key]) if key in metrics else "-" for key, _, _ in present]
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def action_table(result: ProtocolResult) -> str:
    """Per action, the motions judged over all replications (the first row's count: every row
    judges the same test items) and each row's success rate with the check its motions fail most
    often, as a Markdown table (empty when no row has per-action success):
    ``38 (hand_gap<=hand_gap 62, median 0.35)`` reads "38% pass; 62% of this action's motions
    fail hand_gap <= hand_gap, and the median hand gap over all of its motions is 0.35 m" (the
    replications' mean of ``signal/<action>/<check>``; left out where the JSON has none)."""
    rows = [row for row, metrics in result.rows.items() if any(_is_action(k) for k in metrics)]
    actions = list(
        dict.fromkeys(
            key.split("/", 1)[1] for row in rows for key in result.rows[row] if _is_action(key)
        )
    )
    if not actions:
        return ""
    lines = [
        "Success % per action (Motions: judged over all replications); in brackets the check"
        " most of its motions fail, the % failing it and the median of what it measures:",
        "",
        "| Action | Motions | " + " | ".join(rows) + " |",
        "|---|---|" + "---|" * len(rows),
    ]
    for action in actions:
        counts = [result.rows[row].get(f"samples/{action}") for row in rows]
        count = next((c for c in counts if c is not None), None)
        cells = ["-" if count is None else f"{sum(count.values):.0f}"]
        for row in rows:
            metrics = result.rows[row]
            rate = metrics.get(f"success/{action}")
            if rate is None:
                cells.append("-")
                continue
            prefix = f"fails/{action}/"
            fails = {k[len(prefix) :]: v.mean for k, v in metrics.items() if k.startswith(prefix)}
            worst = max(fails, key=fails.get, default=None)
            cell = f"{100 * rate.mean:.0f}"
            if worst is not None and fails[worst] > 0:
                median = metrics.get(f"signal/{action}/{worst}")
                at = "" if median is None else f", median {median.mean:.2f}"
                cell += f" ({worst} {100 * fails[worst]:.0f}{at})"
            cells.append(cell)
        lines.append(f"| {action} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _is_action(key: str) -> bool:
    return key.startswith("success/")


def _title(result: ProtocolResult) -> str:
    header = result.header
    fast = (
        " (FAST MODE: fewer replications, no MultiModality; not comparable)"
        if header.get("fast")
        else ""
    )
    return (
        f"{header.get('mode', 'interaction')} evaluation on {header.get('dataset', '?')} "
        f"{header.get('split', 'test')}, {header.get('replications', '?')} replications{fast}"
    )


def write_results(
    result: ProtocolResult,
    directory: str | Path,
    *,
    beside: Mapping[str, Callable[[Path], object]] | None = None,
) -> tuple[Path, Path]:
    """-> (results.json, results.md) written into ``directory``, with the outputs of ``beside``
    (name -> a writer of ``<folder>/<name>``, e.g. the TensorBoard scalars). They are written
    into a staging folder and appear together, replacing an earlier table, or not at all: a full
    disk leaves the folder as it was (:func:`~intermask.utils.staging.staged_outputs`)."""
    directory = Path(directory)
    beside = dict(beside or {})
    actions = action_table(result)
    with staged_outputs(directory, [*RESULT_FILES, *beside], replace=True) as staged:
        (staged / "results.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
        (staged / "results.md").write_text(
            markdown_table(result) + (f"\n{actions}" if actions else "")
        )
        for name, write in beside.items():
            write(staged / name)
    return directory / "results.json", directory / "results.md"
