"""Protocol results as JSON and as a Markdown table in the layout of InterMask's Table 1."""

from __future__ import annotations

import json
from pathlib import Path

from intermask.evaluation.protocol import ProtocolResult, Summary

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


def write_results(result: ProtocolResult, directory: str | Path) -> tuple[Path, Path]:
    """-> (results.json, results.md) written into ``directory``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    json_path, markdown_path = directory / "results.json", directory / "results.md"
    json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    markdown_path.write_text(markdown_table(result))
    return json_path, markdown_path
