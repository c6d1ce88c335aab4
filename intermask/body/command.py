"""``intermask body`` (also ``python -m intermask.body``): body files for sample folders."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from intermask.body.fit import FitSettings

# intermask.body.model's and FitSettings' values, restated so that the CLI parser imports no torch
# (``intermask --help`` answers at once); tests/body/test_sample_bodies.py ties them
KINDS = ("smplh", "smplx")
GENDERS = ("neutral", "male", "female")
DEFAULT_BETAS = 10
DEFAULT_ITERATIONS = 60
DEFAULT_THREADS = 1

DESCRIPTION = (
    "Fits one SMPL-X or SMPL-H body per person to each sample folder's joints.npy (starting from "
    "features.npy's rotations) and writes body_person<k>.npz (AMASS style, Z up), bodies.glb "
    "(glTF 2.0, Y up, metres, skinned), body_fit.json (per-joint error, time) and a viewer.html "
    "with the meshes. Without --body-model, bodies.glb holds skeletons with limb meshes. The "
    "body-model files are licensed: pass yours (docs/bodies.md says where to get them)."
)


def add_body_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "samples", nargs="+", type=Path, help="sample folders (joints.npy, features.npy)"
    )
    parser.add_argument(
        "--body-model",
        type=Path,
        help="SMPL-X / SMPL-H file (SMPLX_NEUTRAL.npz, smplh/neutral/model.npz) or a folder of them",
    )
    parser.add_argument("--model-type", choices=KINDS, help="default: the file's")
    parser.add_argument(
        "--gender", choices=GENDERS, help="default: the file's (neutral if it says none)"
    )
    parser.add_argument(
        "--betas", type=int, default=DEFAULT_BETAS, help="shape components (default 10)"
    )
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    parser.add_argument(
        "--iterations",
        type=int,
        default=DEFAULT_ITERATIONS,
        help="L-BFGS iterations of the fit",
    )
    parser.add_argument(
        "--threads", type=int, default=DEFAULT_THREADS, help="CPU threads while fitting"
    )
    parser.add_argument("--no-viewer", action="store_true", help="leave viewer.html as it is")


def write_bodies(
    folders: Sequence[Path],
    *,
    body_model: Path | None,
    kind: str | None = None,
    gender: str | None = None,
    betas: int = DEFAULT_BETAS,
    device: str = "cpu",
    settings: FitSettings | None = None,
    viewer: bool = True,
    shown: Sequence[Path] | None = None,
) -> None:
    """Body files for each sample folder (intermask.body.sample.body_outputs), one line each
    naming the folder (or its entry of ``shown``)."""
    from intermask.body.model import load_body_model
    from intermask.body.sample import body_outputs

    model = None
    if body_model is not None:
        import torch

        model = load_body_model(
            body_model,
            kind=kind,
            gender=gender,
            num_betas=betas,
            device=device,
            dtype=torch.float64 if device == "cpu" else torch.float32,
        )
    for folder, name in zip(folders, shown or folders, strict=True):
        paths = body_outputs(folder, model, settings=settings, viewer=viewer)
        print(f"{name}: {', '.join(path.name for path in paths.values())}")


def run_body(args: argparse.Namespace) -> int:
    from intermask.body.fit import FitSettings

    write_bodies(
        args.samples,
        body_model=args.body_model,
        kind=args.model_type,
        gender=args.gender,
        betas=args.betas,
        device=args.device,
        settings=FitSettings(iterations=args.iterations, threads=args.threads),
        viewer=not args.no_viewer,
    )
    return 0


def add_generate_body_options(parser: argparse.ArgumentParser) -> None:
    """``intermask generate``'s body options: with --body-model, each sample folder also gets
    its bodies (write_bodies)."""
    parser.add_argument(
        "--body-model",
        type=Path,
        help="SMPL-X / SMPL-H file or folder: also write body_person<k>.npz, bodies.glb, "
        "body_fit.json and a viewer with the meshes (docs/bodies.md)",
    )
    parser.add_argument("--body-model-type", choices=KINDS, help="default: the file's")
    parser.add_argument("--body-gender", choices=GENDERS, help="default: the file's")


def generate_bodies(
    args: argparse.Namespace, folders: Sequence[Path], *, shown: Sequence[Path] | None = None
) -> None:
    """``intermask generate``: the bodies of its sample folders when --body-model is given
    (``shown``: the names printed for ``folders``, the places a staged write moves them to)."""
    if getattr(args, "body_model", None) is not None:
        device = getattr(args, "device", None) or "cpu"
        write_bodies(
            folders,
            body_model=args.body_model,
            kind=args.body_model_type,
            gender=args.body_gender,
            device=device,
            viewer=not getattr(args, "no_render", False),
            shown=shown,
        )


def add_body_parser(commands) -> None:
    """The ``body`` sub-command of the intermask CLI."""
    parser = commands.add_parser(
        "body", help="SMPL-X / SMPL-H bodies and .glb exports of samples", description=DESCRIPTION
    )
    add_body_arguments(parser)
    parser.set_defaults(run=run_body)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m intermask.body", description=DESCRIPTION)
    add_body_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run_body(args)
    except (FileNotFoundError, ValueError) as error:  # BodyModelError is a ValueError
        print(f"intermask body: error: {error}", file=sys.stderr)
        return 2
