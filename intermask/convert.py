"""``intermask convert-reference``: the authors' released checkpoints as run folders of this
framework, with the reference behaviours switched on (docs/fidelity.md).

The release lays out each model as ``<name>/model/<which>.tar`` beside ``<name>/opt.txt``: the
tokenizer's checkpoint holds ``vq_model`` (or ``net``), the generator's ``t2m_transformer``.
Both are read with ``weights_only=True``. The output is two run folders that ``load_vq``,
``load_generator``, ``intermask generate`` and ``make eval`` accept::

    <out>/vq/config.yaml, <out>/vq/checkpoints/last.ckpt     (experiment=vq_<dataset>_reference)
    <out>/gen/config.yaml, <out>/gen/checkpoints/last.ckpt   (experiment=gen_<dataset> with the
                                                             reference switches of rows 1-3)

Every key that is dropped, derived, cannot be placed or has another shape is reported by name;
a conversion that leaves any of our weights without a value is refused.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf, open_dict
from torch import nn

from intermask.config_files import config_dir
from intermask.interm.reference import convert_reference_generator
from intermask.release_options import generator_overrides, vq_overrides
from intermask.utils.checkpoint_files import atomic_torch_save, read_checkpoint_file
from intermask.utils.fingerprint import weights_digest
from intermask.utils.run_record import write_run_record
from intermask.utils.staging import staged_outputs
from intermask.utils.state_conversion import Conversion
from intermask.vq.reference import convert_reference_vq, has_graph_ends

DATASETS = ("interhuman", "interx")
VQ_KEYS = ("vq_model", "net")
GENERATOR_KEYS = ("t2m_transformer", "trans")
# reference switches of the generator (docs/fidelity.md rows 1-3)
REFERENCE_GENERATOR = {
    "text_attends_padding": True,
    "double_residual_quirk": True,
    "cross_context_quirk": True,
}


@dataclass(frozen=True)
class Converted:
    vq_run: Path
    gen_run: Path | None
    reports: dict[str, str]


def read_options(checkpoint: Path) -> dict[str, str]:
    """The ``key: value`` lines of the ``opt.txt`` beside a release checkpoint (in its folder or
    the folder above ``model/``)."""
    for folder in (checkpoint.parent, checkpoint.parent.parent):
        path = folder / "opt.txt"
        if path.is_file():
            options = {}
            for line in path.read_text().splitlines():
                key, sep, value = line.partition(": ")
                if sep and not line.startswith("-"):
                    options[key.strip()] = value.strip()
            return options
    raise FileNotFoundError(
        f"{checkpoint}: no opt.txt beside it or in {checkpoint.parent.parent} (the release keeps "
        "<name>/opt.txt beside <name>/model/)"
    )


def release_state(checkpoint: Path, keys: tuple[str, ...], kind: str) -> dict[str, torch.Tensor]:
    """The state dict stored under the first of ``keys`` in a release checkpoint (weights only);
    ``kind`` names the model in the errors ("reference VQ-VAE", "MoMask masked transformer")."""
    stored = read_checkpoint_file(checkpoint)
    for key in keys:
        if isinstance(stored, dict) and key in stored:
            state = stored[key]
            if not isinstance(state, dict) or not all(
                isinstance(v, torch.Tensor) for v in state.values()
            ):
                raise ValueError(f"{checkpoint}: {key} is not a state dict of tensors")
            return state
    found = sorted(stored) if isinstance(stored, dict) else type(stored).__name__
    raise ValueError(
        f"{checkpoint}: not a {kind} checkpoint (no {' or '.join(keys)}; found {found})"
    )


def composed(job: str, overrides: list[str], options: dict[str, Any]) -> DictConfig:
    """A job's config composed with ``overrides``, then the release's mapped options applied."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        config = compose(job, overrides=overrides)
    with open_dict(config):
        for key, value in options.items():
            OmegaConf.update(config, key, value, merge=False)
    return config


def checked(conversion: Conversion, checkpoint: Path, kind: str) -> Conversion:
    """``conversion``, or a ValueError with its report when anything did not map."""
    if not conversion.complete:
        raise ValueError(
            f"{checkpoint}: the {kind} does not map onto this framework's:\n" + conversion.report()
        )
    return conversion


def run_payload(net: nn.Module, source: Path, options: dict[str, str], **extra: Any) -> dict:
    """What a converted run's last.ckpt holds: the weights and where they came from."""
    return {
        "state_dict": {f"net.{k}": v for k, v in net.state_dict().items()},
        "hyper_parameters": {"converted_from": str(source), "reference_options": options, **extra},
    }


def write_run(staged: Path, folder: Path, config: DictConfig, payload: dict[str, Any]) -> None:
    """The run folder ``folder`` written at ``staged`` (moved into place by the caller):
    config.yaml and last.ckpt, the config naming ``folder``, where the run will live."""
    with open_dict(config):
        config.paths.output_dir = str(folder)  # what a training run records as its folder
    (staged / "checkpoints").mkdir(parents=True)
    OmegaConf.save(config, staged / "config.yaml", resolve=True)
    write_run_record(staged, extra={"job": "convert-reference"}, folder=folder)
    atomic_torch_save(payload, staged / "checkpoints" / "last.ckpt")


STATISTICS = ("view.mean", "view.std", "view.has_statistics")


def _convert_vq(
    vq: Path,
    dataset: str,
    options: dict[str, str],
    statistics: tuple[Path, Path] | None,
    ignore: Collection[str],
) -> tuple[Any, nn.Module, str]:
    """(config, network with the release's weights, report) of the release's tokenizer."""
    mapped = vq_overrides(options, source=f"{vq.parent.parent / 'opt.txt'}", ignore=ignore)
    config = composed("train_vq", [f"data={dataset}", f"experiment=vq_{dataset}"], mapped)
    reference = release_state(vq, VQ_KEYS, "reference VQ-VAE")
    with open_dict(config):
        config.model.net.quantizer.stochastic_temperature = 0.5  # fidelity rows 6-7
        config.model.net.quantizer.reset = "reference"
        if has_graph_ends(reference):  # the InterHuman release: as its evaluation decodes (10b)
            config.model.net.encoder.ends = "graph_first_frame"
    net = instantiate(config.model.net)
    conversion = convert_reference_vq(reference, net.state_dict())
    if any(key in STATISTICS for key in conversion.missing):
        if statistics is None:
            raise ValueError(
                f"{vq}: this tokenizer normalizes its features: pass the release's statistics "
                "(--mean global_mean.npy --std global_std.npy)"
            )
        mean, std = (torch.from_numpy(np.load(path)).float() for path in statistics)
        net.view.set_statistics(mean, std)
        conversion = conversion._replace(
            missing=[key for key in conversion.missing if key not in STATISTICS]
        )
    checked(conversion, vq, "reference VQ-VAE")
    net.load_state_dict({**net.state_dict(), **conversion.state})
    return config, net, conversion.report()


def _convert_generator(
    generator: Path,
    dataset: str,
    vq_net: nn.Module,
    code_dim: int,
    vq_checkpoint: Path,
    ignore: Collection[str],
) -> tuple[Any, nn.Module, str]:
    """(config, network with the release's weights, report) of the release's transformer."""
    options = read_options(generator)
    mapped = generator_overrides(
        options, source=f"{generator.parent.parent / 'opt.txt'}", ignore=ignore
    )
    config = composed(
        "train_gen",
        [f"data={dataset}", f"experiment=gen_{dataset}", f"vq_ckpt={vq_checkpoint}"],
        mapped,
    )
    with open_dict(config):
        config.model.net.update(REFERENCE_GENERATOR)
        # the release embeds tokens at its tokenizer's code width (its MaskTransformer's code_dim)
        config.model.net.token_embed_dim = code_dim
    net = instantiate(config.model.net)(codebook_size=vq_net.quantizer.codebook_size)
    conversion = convert_reference_generator(
        release_state(generator, GENERATOR_KEYS, "reference generator"), net.state_dict()
    )
    checked(conversion, generator, "reference generator")
    net.load_state_dict(conversion.state)
    return config, net, conversion.report()


def convert_reference(
    *,
    vq: Path,
    generator: Path | None,
    out: Path,
    dataset: str | None = None,
    statistics: tuple[Path, Path] | None = None,
    ignore_options: Collection[str] = (),
) -> Converted:
    """Convert the release's tokenizer (and generator) into run folders under ``out``.

    Both are converted in full before anything is written; the run folders then appear whole,
    or not at all (a failure leaves no output behind).
    ``statistics``: the release's ``global_mean.npy`` and ``global_std.npy`` (InterHuman: the
    reference normalizes the 262 features with them; Inter-X has none).
    ``ignore_options``: opt.txt options the authors' code does not have that the user vouches
    do not change the network (anything else unknown is refused).
    """
    vq, out = Path(vq), Path(out)
    vq_options = read_options(vq)
    dataset = dataset or vq_options.get("dataset_name")
    if dataset not in DATASETS:
        raise ValueError(
            f"{vq}: dataset {dataset!r} (opt.txt dataset_name or --dataset) is not one of {DATASETS}"
        )
    vq_config, vq_net, vq_report = _convert_vq(vq, dataset, vq_options, statistics, ignore_options)
    reports = {"vq": vq_report}
    runs = {"vq": (vq_config, run_payload(vq_net, vq, vq_options))}
    if generator is not None:
        generator = Path(generator)
        vq_checkpoint = out.absolute() / "vq" / "checkpoints" / "last.ckpt"  # any working folder
        gen_config, net, reports["generator"] = _convert_generator(
            generator,
            dataset,
            vq_net,
            vq_config.model.net.encoder.width,
            vq_checkpoint,
            ignore_options,
        )
        runs["gen"] = (
            gen_config,
            run_payload(
                net,
                generator,
                read_options(generator),
                codebook_size=vq_net.quantizer.codebook_size,
                vq_digest=weights_digest(vq_net.eval()),
            ),
        )
    with staged_outputs(out, tuple(runs)) as staged:  # both runs appear whole, or nothing does
        for name, (config, payload) in runs.items():
            write_run(staged / name, out.absolute() / name, config, payload)
    return Converted(out / "vq", out / "gen" if generator is not None else None, reports)
