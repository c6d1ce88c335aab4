"""``intermask body`` (also ``python -m intermask.body``): body files for sample folders."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

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
    model: Any = None,
) -> None:
    """Body files for each sample folder (intermask.body.sample.body_outputs), one line each
    naming the folder (or its entry of ``shown``); ``model``: a body model already read (else
    ``body_model`` is read)."""
    from intermask.body.sample import body_outputs

    if model is None and body_model is not None:
        model = read_body_model(body_model, kind=kind, gender=gender, betas=betas, device=device)
    for folder, name in zip(folders, shown or folders, strict=True):
        paths = body_outputs(folder, model, settings=settings, viewer=viewer)
        print(f"{name}: {', '.join(path.name for path in paths.values())}")


def read_body_model(
    path: Path, *, kind: str | None, gender: str | None, betas: int, device: str
) -> Any:
    """The body model of ``path`` for fitting on ``device`` (float64 on a CPU)."""
    import torch

    from intermask.body.model import load_body_model

    return load_body_model(
        path,
        kind=kind,
        gender=gender,
        num_betas=betas,
        device=device,
        dtype=torch.float64 if device == "cpu" else torch.float32,
    )


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


def body_finisher(
    args: argparse.Namespace,
) -> Callable[[Sequence[Path], Sequence[Path]], None] | None:
    """``intermask generate --body-model``: the body model read, and so checked, before any
    generation, and the step that writes the bodies into the staged sample folders
    (``Request.finish``); None without --body-model."""
    if getattr(args, "body_model", None) is None:
        return None
    device = getattr(args, "device", None) or "cpu"
    model = read_body_model(
        args.body_model,
        kind=args.body_model_type,
        gender=args.body_gender,
        betas=DEFAULT_BETAS,
        device=device,
    )
    viewer = not getattr(args, "no_render", False)

    def finish(staged: Sequence[Path], final: Sequence[Path]) -> None:
        write_bodies(staged, body_model=None, model=model, viewer=viewer, shown=final)

    return finish


def generate_bodies(
    args: argparse.Namespace, folders: Sequence[Path], *, shown: Sequence[Path] | None = None
) -> None:
    """The bodies of sample folders as ``intermask generate --body-model`` writes them
    (``shown``: the names printed for ``folders``); nothing without --body-model."""
    finish = body_finisher(args)
    if finish is not None:
        finish(folders, shown or folders)


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
