"""The ``intermask`` console script.

``intermask data synth|check|stats|item`` work on dataset folders. Heavy imports happen inside
the sub-commands so that ``intermask --help`` answers at once.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from intermask.data.layout import FORMATS


def _add_format_option(parser: argparse.ArgumentParser, required: bool = False) -> None:
    parser.add_argument(
        "--format",
        choices=FORMATS,
        required=required,
        help="dataset layout" + ("" if required else " (default: detected from the folder)"),
    )


def _resolve_format(root: Path, requested: str | None) -> str:
    from intermask.data.layout import detect_format

    return requested or detect_format(root)


def _data_synth(args: argparse.Namespace) -> int:
    from intermask.data.synthetic import generate_dataset
    from intermask.utils.run_record import write_run_record

    start = time.perf_counter()
    summary = generate_dataset(args.out, format=args.format, clips=args.clips, seed=args.seed)
    seconds = time.perf_counter() - start
    write_run_record(
        args.out,
        extra={
            "job": "data synth",
            "format": args.format,
            "clips": args.clips,
            "seed": args.seed,
            "seconds": round(seconds, 2),
        },
    )
    print(f"wrote {summary} to {args.out} in {seconds:.1f} s")
    return 0


def _data_check(args: argparse.Namespace) -> int:
    from intermask.data.validation import check_dataset

    root = Path(args.root)
    dataset_format = _resolve_format(root, args.format)
    problems = check_dataset(root, dataset_format)
    for problem in problems:
        print(problem)
    if problems:
        print(f"{len(problems)} problem(s) in {root} ({dataset_format})", file=sys.stderr)
        return 1
    print(f"{root} ({dataset_format}): no problems found")
    return 0


def _data_stats(args: argparse.Namespace) -> int:
    from intermask.data.normalization import compute_and_save_stats, default_stats_dir

    root = Path(args.root)
    dataset_format = _resolve_format(root, args.format)
    out_dir = args.out or default_stats_dir(root)
    compute_and_save_stats(root, dataset=dataset_format, split=args.split, out_dir=out_dir)
    print(
        f"normalization statistics of {root} ({dataset_format}, split {args.split}) written to {out_dir}"
    )
    return 0


def _data_item(args: argparse.Namespace) -> int:
    from intermask.data.item import export_item

    root = Path(args.root)
    dataset_format = _resolve_format(root, args.format)
    path = export_item(
        root, dataset_format, split=args.split, clip_id=args.id, out_path=Path(args.out)
    )
    print(f"clip {args.id} ({dataset_format}, {args.split}) written to {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="intermask", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)

    data = commands.add_parser("data", help="dataset tools").add_subparsers(
        dest="data_command", required=True
    )

    synth = data.add_parser(
        "synth", help="write the procedural two-person dataset in an official layout"
    )
    synth.add_argument("--out", type=Path, required=True, help="dataset root to create")
    _add_format_option(synth, required=True)
    synth.add_argument("--clips", type=int, default=1000, help="number of clips (default 1000)")
    synth.add_argument("--seed", type=int, default=0, help="random seed; same seed, same bytes")
    synth.set_defaults(run=_data_synth)

    check = data.add_parser(
        "check", help="validate every file of a dataset and report all problems at once"
    )
    check.add_argument("root", type=Path)
    _add_format_option(check)
    check.set_defaults(run=_data_check)

    stats = data.add_parser(
        "stats", help="compute normalization statistics from a split and save them next to the data"
    )
    stats.add_argument("root", type=Path)
    _add_format_option(stats)
    stats.add_argument("--split", default="train")
    stats.add_argument(
        "--out", type=Path, default=None, help="statistics folder (default: ROOT/stats)"
    )
    stats.set_defaults(run=_data_stats)

    item = data.add_parser(
        "item", help="write one processed clip (augmentation off) to an .npz for inspection"
    )
    item.add_argument("root", type=Path)
    _add_format_option(item)
    item.add_argument("--split", default="test")
    item.add_argument("--id", required=True, help="clip id (file stem / sample name)")
    item.add_argument("--out", required=True, help="output .npz path")
    item.set_defaults(run=_data_item)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except (FileNotFoundError, FileExistsError, ValueError) as error:
        # Data problems are user errors: one clear line, no traceback.
        print(f"intermask {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
