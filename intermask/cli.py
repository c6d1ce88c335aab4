"""The ``intermask`` console script.

``intermask data synth|check|stats|item|success-stats`` work on dataset folders; ``intermask
generate`` turns captions (and optionally a reference or an edited motion) into interactions
(Inter-M runs) or single-person motions (MoMask runs). Heavy imports happen inside the
sub-commands so that ``intermask --help`` answers at once.
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import re
import shutil
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from intermask.body.command import add_body_parser, add_generate_body_options
from intermask.motion.kinds import DATASET_KINDS


def _add_format_option(parser: argparse.ArgumentParser, required: bool = False) -> None:
    parser.add_argument(
        "--format",
        choices=DATASET_KINDS,
        required=required,
        help="dataset layout" + ("" if required else " (default: detected from the folder)"),
    )


def _resolve_format(root: Path, requested: str | None) -> str:
    from intermask.data.layout import detect_format

    return requested or detect_format(root)


def _data_synth(args: argparse.Namespace) -> int:
    from intermask.data.synthetic import generate_dataset
    from intermask.data.synthetic.planning import check_folder
    from intermask.utils.run_record import write_run_record
    from intermask.utils.staging import staged_outputs

    start = time.perf_counter()
    earlier = check_folder(args.out)  # refused before any work
    # written beside the folder and moved in when whole: a failure leaves the earlier dataset
    with staged_outputs(args.out, None, replace=True) as staged:
        summary = generate_dataset(staged, format=args.format, clips=args.clips, seed=args.seed)
        seconds = time.perf_counter() - start
        write_run_record(
            staged,
            extra={
                "job": "data synth",
                "format": args.format,
                "clips": args.clips,
                "seed": args.seed,
                "seconds": round(seconds, 2),
            },
            folder=args.out,
        )
        written = set(os.listdir(staged))
    for name in sorted(set(earlier) - written):  # the earlier dataset's (its statistics ...)
        _remove_entry(args.out / name)
    print(f"wrote {summary} to {args.out} in {seconds:.1f} s")
    return 0


def _remove_entry(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _data_check(args: argparse.Namespace) -> int:
    from intermask.data.layout import detect_layout
    from intermask.data.validation import check_dataset

    root = Path(args.root)
    dataset_format = args.format or detect_layout(root)  # HumanML3D folders too
    problems = check_dataset(root, dataset_format)
    for problem in problems:
        print(problem)
    if problems:
        print(f"{len(problems)} problem(s) in {root} ({dataset_format})", file=sys.stderr)
        return 1
    print(f"{root} ({dataset_format}): no problems found")
    return 0


def _data_stats(args: argparse.Namespace) -> int:
    from intermask.data.normalization import MEAN_FILE, PROVENANCE_FILE, STD_FILE, default_stats_dir
    from intermask.data.statistics import compute_and_save_stats
    from intermask.utils.staging import staged_outputs

    root = Path(args.root)
    dataset_format = _resolve_format(root, args.format)
    out_dir = args.out or default_stats_dir(root)
    # the three files replace earlier statistics together, or not at all
    with staged_outputs(out_dir, (MEAN_FILE, STD_FILE, PROVENANCE_FILE), replace=True) as staged:
        compute_and_save_stats(root, dataset=dataset_format, split=args.split, out_dir=staged)
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


def _data_success_stats(args: argparse.Namespace) -> int:
    from intermask.evaluation.success_stats import success_statistics

    root = Path(args.root)
    statistics = success_statistics(
        root,
        dataset=_resolve_format(root, args.format),
        splits=args.split or ("train", "val", "test"),
        max_length=args.max_length,
        epoch=args.epoch,
    )
    print(statistics.report())
    return 0


def _frame_range(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"(\d+):(\d+)", text)
    if not match:
        raise argparse.ArgumentTypeError(f"expected frames as A:B (e.g. 40:80), got {text!r}")
    return int(match[1]), int(match[2])


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value


def _non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text}")
    return value


def _non_negative_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return value


def _ratio(text: str) -> float:
    value = float(text)
    if not 0 < value <= 1:  # NaN fails too
        raise argparse.ArgumentTypeError(f"expected a ratio in (0, 1], got {text}")
    return value


def _output_folder(text: str) -> Path:
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} exists and is not a folder")
    return path


def _generate(args: argparse.Namespace) -> int:
    from intermask import generate as gen

    options = vars(args)
    sampler = {name: options[name] for name in args.sampler_options if options[name] is not None}
    fields = {name: options[name] for name in gen.Request.__dataclass_fields__ if name in options}
    from intermask.body.command import body_finisher

    # --body-model: the model is read before any generation; bodies, .glb and meshes are written
    # into the staged sample folders (docs/bodies.md)
    gen.run(gen.Request(**fields, sampler=sampler, finish=body_finisher(args)))
    return 0


def _convert_momask(args: argparse.Namespace) -> int:
    from intermask.convert_momask import convert_momask

    if args.mean is not None or args.std is not None:
        raise ValueError(
            "a MoMask release reads its statistics from <vq name>/meta/ (no --mean/--std)"
        )
    done = convert_momask(
        vq=Path(args.vq),
        mask=None if args.generator is None else Path(args.generator),
        residual=None if args.residual is None else Path(args.residual),
        out=args.out,
        text=args.text or "clip_vit_b32",
        clip=args.clip,
        ignore_options=args.ignore_option or (),
    )
    for name, report in done.reports.items():
        print(f"{name}: {report}")
    for name, run in done.runs.items():
        print(f"{name} run: {run}")
    if "mask" in done.runs:
        residual = f" --residual {done.runs['residual']}" if "residual" in done.runs else ""
        print(f'intermask generate --checkpoint {done.runs["mask"]}{residual} --text "..."')
    return 0


def _convert_reference(args: argparse.Namespace) -> int:
    from intermask.convert import convert_reference
    from intermask.convert_momask import is_momask_release

    if (
        args.residual is not None
        or args.dataset == "t2m"
        or (args.dataset is None and is_momask_release(Path(args.vq)))
    ):
        return _convert_momask(args)
    if args.text is not None or args.clip is not None:
        raise ValueError("--text and --clip are for a MoMask release (opt.txt dataset_name t2m)")
    if (args.mean is None) != (args.std is None):
        raise ValueError("--mean and --std go together (the release's global_mean/std.npy)")
    done = convert_reference(
        vq=Path(args.vq),
        generator=None if args.generator is None else Path(args.generator),
        out=args.out,
        dataset=args.dataset,
        statistics=None if args.mean is None else (Path(args.mean), Path(args.std)),
        ignore_options=args.ignore_option or (),
    )
    for name, report in done.reports.items():
        print(f"{name}: {report}")
    print(f"tokenizer run: {done.vq_run}")
    if done.gen_run is not None:
        print(f"generator run: {done.gen_run} (intermask generate --checkpoint {done.gen_run})")
    return 0


def _generate_defaults() -> tuple[dict, dict, dict]:
    """The values ``intermask generate`` falls back to, read from their one owner, the configs
    (configs/generate.yaml, configs/sampler/paper.yaml, configs/sampler/momask.yaml), so that the
    help says what a run will take. Plain YAML reads: ``intermask --help`` stays quick."""
    import yaml

    from intermask.config_files import config_dir

    root = config_dir()

    def read(name: str) -> dict:
        return yaml.safe_load((root / name).read_text(encoding="utf-8"))

    generate = {k: v for k, v in read("generate.yaml").items() if k != "defaults"}
    return generate, read("sampler/paper.yaml"), read("sampler/momask.yaml")


def _add_generate_parser(commands) -> None:
    defaults, _, _ = _generate_defaults()
    parser = commands.add_parser(
        "generate",
        help="captions -> two-person interactions or one-person motions (npy, JSON, GIF, MP4, "
        "HTML)",
        description="Defaults come from configs/generate.yaml and configs/sampler/ (paper.yaml; "
        "MoMask: momask.yaml). The kind of run is read from its config.yaml: an Inter-M run "
        "generates two persons, a MoMask masked transformer run (with --residual, its residual "
        f"transformer run) one HumanML3D person at {defaults['momask_fps']:g} fps.",
    )
    parser.add_argument(
        "--checkpoint",
        required=True,
        help="train_gen run directory or .ckpt: Inter-M, or MoMask's masked transformer",
    )
    parser.add_argument(
        "--residual",
        help="MoMask: the residual transformer run (default: decode the base layer alone)",
    )
    parser.add_argument("--vq-checkpoint", help="override the run's VQ checkpoint path")
    parser.add_argument("--text", action="append", help="a caption (repeat for several)")
    parser.add_argument("--prompts", help="file with one caption per line")
    length = parser.add_mutually_exclusive_group()
    length.add_argument(
        "--seconds",
        type=_positive_float,
        help=f"length in seconds (default {defaults['seconds']:g})",
    )
    length.add_argument("--length-frames", type=_positive_int, help="length in frames")
    parser.add_argument(
        "--samples",
        type=_positive_int,
        help=f"samples per caption (default {defaults['samples']})",
    )
    parser.add_argument("--seed", type=int, help=f"first seed (default {defaults['seed']})")
    sampler_options = _add_decoding_options(parser)
    parser.add_argument(
        "--batch-size",
        type=_positive_int,
        help=f"samples per forward batch ({defaults['batch_size']})",
    )
    parser.add_argument(
        "--fps",
        type=_positive_float,
        help=f"frame rate of the dataset ({defaults['fps']:g}; MoMask {defaults['momask_fps']:g})",
    )
    parser.add_argument("--reaction", help="reference person's motion: person 1 stays fixed")
    parser.add_argument("--edit", help="two-person motion to edit (needs --frames)")
    parser.add_argument(
        "--frames", dest="frames_range", type=_frame_range, help="edited frames A:B"
    )
    parser.add_argument("--person", type=int, choices=(1, 2), help="edit one person only")
    parser.add_argument("--device", help="cpu, cuda, cuda:1 ... (default: cuda when available)")
    parser.add_argument(
        "--precision",
        choices=("32", "bf16", "auto"),  # intermask.utils.precision.OPTIONS (torch-free here)
        help="Inter-M decoding: 32, bf16 autocast (other numbers; recorded in sample.json) or "
        f"auto (bf16 where the device has native bf16); default {defaults['precision']}",
    )
    parser.add_argument(
        "--out", type=_output_folder, help=f"output folder (default {defaults['out']})"
    )
    parser.add_argument("--no-render", action="store_true", help="write arrays and JSON only")
    add_generate_body_options(parser)
    parser.set_defaults(run=_generate, sampler_options=sampler_options)


def _add_decoding_options(parser: argparse.ArgumentParser) -> tuple[str, ...]:
    """The decoding settings of ``intermask generate`` -> their names, the keys of the sampler
    configs (configs/sampler/; ``--cfg-scale`` is MoMask's ``mask_cfg_scale``), whose values the
    help gives."""
    generate, paper, momask = _generate_defaults()
    add = parser.add_argument
    options = [
        add(
            "--cfg-scale",
            type=_non_negative_float,
            help=f"classifier-free guidance scale ({paper['cfg_scale']:g}; MoMask: the masked "
            f"transformer's, {momask['mask_cfg_scale']:g})",
        ),
        add(
            "--iterations",
            type=_positive_int,
            help=f"decoding iterations ({paper['iterations']}; reaction "
            f"{generate['reaction_iterations']}; MoMask {momask['iterations']})",
        ),
        add(
            "--schedule",
            choices=("paper", "reference"),
            help="re-masking counts: the paper's or the reference code's (docs/fidelity.md; "
            f"default {paper['schedule']})",
        ),
        add(
            "--noise",
            choices=("per_sample", "reference"),
            help="sampling draws: one generator per sample or the reference code's (default "
            f"{paper['noise']})",
        ),
        add(
            "--persons",
            choices=("together", "in_turn"),
            help="both persons every pass (the paper) or person A first, then B given A (default "
            f"{paper['persons']})",
        ),
        add(
            "--revisits",
            type=_non_negative_int,
            help="in_turn only: extra turns that re-decode A given B, then B given the new A "
            f"({paper['revisits']})",
        ),
        add(
            "--partner-scale",
            type=_non_negative_float,
            help="in_turn or --reaction: partner guidance, how much further a person follows "
            f"what the other's tokens add to its prediction ({paper['partner_scale']:g})",
        ),
        add(
            "--remask-noise",
            type=_non_negative_float,
            help="re-mask by log confidence plus Gumbel noise of this scale, fading over the "
            f"iterations (MaskGIT; {paper['remask_noise']:g})",
        ),
        add(
            "--top-k",
            dest="top_k_ratio",
            metavar="TOP_K",
            type=_ratio,
            help=f"top-k ratio of codes kept, in (0, 1] ({paper['top_k_ratio']:g})",
        ),
        add(
            "--temperature",
            type=_positive_float,
            help=f"sampling temperature ({paper['temperature']:g})",
        ),
        *_add_residual_options(parser, momask),
    ]
    return tuple(option.dest for option in options)


def _add_residual_options(parser: argparse.ArgumentParser, momask: dict) -> list[argparse.Action]:
    """MoMask's residual-layer decoding options (configs/sampler/momask.yaml gives the values)."""
    return [
        parser.add_argument(
            "--residual-cfg-scale",
            type=_non_negative_float,
            help=f"MoMask: the residual transformer's guidance scale "
            f"({momask['residual_cfg_scale']:g})",
        ),
        parser.add_argument(
            "--residual-temperature",
            type=_non_negative_float,
            help="MoMask: the residual layers' sampling temperature, 0 greedy "
            f"({momask['residual_temperature']:g})",
        ),
    ]


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
    check.add_argument(
        "--format",
        choices=(*DATASET_KINDS, "humanml3d"),
        help="dataset layout (default: detected from the folder)",
    )
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

    success = data.add_parser(
        "success-stats",
        help="interaction-success signals of a labelled dataset's GT, with the GT pass rates",
        description="Items are read as the evaluation protocol reads them (random crop of "
        "--max-length frames, person order drawn per item, pass --epoch); the thresholds in "
        "use and the suggested ones (intermask.evaluation.success_stats) are printed.",
    )
    success.add_argument("root", type=Path)
    _add_format_option(success)
    success.add_argument(
        "--split", action="append", help="split to read (repeat; default train, val and test)"
    )
    success.add_argument(
        "--max-length",
        type=int,
        default=None,
        help="crop length in frames (default: the full"
        " clip up to the DataModule's maximum, 300 InterHuman / 150 Inter-X)",
    )
    success.add_argument("--epoch", type=int, default=0, help="evaluation pass (crop draws)")
    success.set_defaults(run=_data_success_stats)

    _add_generate_parser(commands)
    add_body_parser(commands)
    _add_convert_parser(commands)
    return parser


def _add_convert_parser(commands) -> None:
    convert = commands.add_parser(
        "convert-reference",
        help="the authors' released checkpoints -> run folders of this framework",
        description="Reads <name>/model/<which>.tar beside <name>/opt.txt (weights only) and writes "
        "OUT/vq and OUT/gen run folders with the reference behaviours on (docs/fidelity.md). A "
        "MoMask release (opt.txt dataset_name t2m) gives OUT/vq, OUT/mask and OUT/residual.",
    )
    convert.add_argument("--vq", required=True, help="the release's VQ-VAE checkpoint (.tar)")
    convert.add_argument("--generator", help="the release's transformer checkpoint (.tar)")
    convert.add_argument("--out", required=True, type=_output_folder, help="output folder")
    convert.add_argument(
        "--dataset", choices=("interhuman", "interx", "t2m"), help="default: opt.txt's"
    )
    convert.add_argument(
        "--residual",
        help="MoMask: the release's residual transformer (.tar; --generator is its "
        "masked transformer); writes OUT/vq, OUT/mask and OUT/residual",
    )
    convert.add_argument(
        "--text",
        help="MoMask: the text config of the converted transformers (configs/text/; "
        "default clip_vit_b32), whose CLIP text projection is folded into their condition layer",
    )
    convert.add_argument("--clip", help="MoMask: a local CLIP checkpoint for that text encoder")
    convert.add_argument("--mean", help="the release's global_mean.npy (InterHuman)")
    convert.add_argument("--std", help="the release's global_std.npy (InterHuman)")
    convert.add_argument(
        "--ignore-option",
        action="append",
        metavar="NAME",
        help="an opt.txt option the authors' code does not have and that does not change the "
        "network (repeat); any other unknown option is refused",
    )
    convert.set_defaults(run=_convert_reference)


def _user_error(error: Exception, args: argparse.Namespace) -> str | None:
    """The one line a user error gets (None: a bug, whose traceback is wanted). A place that
    cannot be written (full, read-only, no permission, a file in the way) is said with what to
    do (:mod:`intermask.utils.write_errors`); data and checkpoint problems name the file."""
    from intermask.utils.write_errors import describe

    elsewhere = "choose another --out" if hasattr(args, "out") else ""
    message = describe(error, fallback=getattr(args, "out", None), elsewhere=elsewhere)
    if message is not None:
        return message
    if isinstance(error, (FileNotFoundError, FileExistsError, ValueError, pickle.UnpicklingError)):
        return str(error)
    return None


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except Exception as error:
        message = _user_error(error, args)
        if message is None:
            raise
        print(f"intermask {args.command}: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
