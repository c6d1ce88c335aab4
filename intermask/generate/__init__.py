"""Text (and optionally a reference or an edited motion) to motions on disk: two-person
interactions from an Inter-M run, single-person motions from a MoMask run.

``intermask generate --checkpoint RUN --text "two people shake hands" --seconds 4 --samples 2``
loads a train_gen run, generates every (caption, sample) pair, and writes per sample:
``joints.npy`` (T, P, 22, 3) metres Y-up, ``features.npy`` (P, T, *F) in the dataset
representation (de-normalized), ``sample.json`` (caption, settings, seed, checkpoint hashes) and
the renderings (GIF, MP4, HTML). Defaults live in ``configs/generate.yaml`` and the sampler
configs it composes (``configs/sampler/``).

Each model family has one job behind :func:`run` (:data:`JOBS`), chosen by the run's
``config.yaml`` (``model._target_``): Inter-M runs (:mod:`intermask.generate.interm`) give
P = 2 persons at the dataset's rate (30 fps); a MoMask masked transformer run
(:mod:`intermask.generate.momask`), optionally with its residual transformer run
(``--residual RUN``), gives one HumanML3D person (P = 1, F = 263) at 20 fps, at most 196
frames: ``intermask generate --checkpoint MASK_RUN --residual RESIDUAL_RUN --text "a person
walks forward" --seconds 4 --samples 2``. A job refuses the options of another family
(``--persons``, ``--reaction``, ``--edit`` ... with a MoMask run). Each job builds its family's
decoding settings (:class:`~intermask.interm.decoding.Decoding`,
:class:`~intermask.momask.sampler.MoMaskDecoding`) from the config and the options given, and
passes them whole to its sampler.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from intermask.generate import interm, momask
from intermask.generate.common import (
    MAX_FRAMES,
    Request,
    Sample,
    default_settings,
    frames_from,
    read_prompts,
    run_target,
    sample_folders,
)
from intermask.generate.interm import edit_region, load_motion_file

# a family's job: (request, configs/generate.yaml's defaults, the run's model._target_) -> the
# sample folders written. Inputs are checked before the networks are loaded, and no existing
# sample folder is overwritten.
Job = Callable[[Request, dict[str, Any], str], list[Path]]
# model._target_ -> its family's job; any other run is an Inter-M one
JOBS: dict[str, Job] = {target: momask.run for target in momask.MOMASK_MODULES}


def run(request: Request) -> list[Path]:
    """The generate job: captions (or a reaction / edit input) -> sample folders with arrays,
    JSON and renders, by the job of the run's family; returns the folders."""
    defaults = default_settings()
    target = run_target(request.checkpoint)
    return JOBS.get(target, interm.run)(request, defaults, target)


__all__ = [
    "JOBS",
    "MAX_FRAMES",
    "Job",
    "Request",
    "Sample",
    "default_settings",
    "edit_region",
    "frames_from",
    "load_motion_file",
    "read_prompts",
    "run",
    "run_target",
    "sample_folders",
]
