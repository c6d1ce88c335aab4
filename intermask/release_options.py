"""The authors' ``opt.txt`` options as config overrides of this framework, or refusals by name.

A release's weights do not show every architecture choice: the number of attention heads, the
activation, the dilation growth leave the shapes unchanged. The InterMask release records them
in ``opt.txt`` beside each model (written by its option parser: every command-line option and
``is_train``). :func:`vq_overrides` and :func:`generator_overrides` turn each architecture option
into the config value it sets, and refuse a value this framework cannot build, naming the
option, its value and what is supported. Training and bookkeeping options are listed too (they
do not change the network; they are kept in the converted checkpoint's ``reference_options``).
An option the authors' parser does not have is refused unless the user names it in
``ignore`` (a fork's extra logging flag, say), so nothing unknown is passed over in silence.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from typing import Any

Overrides = dict[str, Any]
_Rule = Callable[[str, Mapping[str, str]], Overrides]


class UnsupportedOption(ValueError):
    """An ``opt.txt`` option this framework cannot build (or does not know)."""


def _number(text: str, kind: type) -> Any:
    try:
        return kind(float(text)) if kind is int and float(text).is_integer() else kind(text)
    except ValueError as error:
        raise UnsupportedOption(f"not a {kind.__name__}: {text!r}") from error


def _mapped(key: str, kind: type = int) -> _Rule:
    return lambda value, options: {key: _number(value, kind)}


def _only(*supported: str) -> _Rule:
    """An option whose only value(s) here are ``supported`` (it sets nothing)."""

    def rule(value: str, options: Mapping[str, str]) -> Overrides:
        if value not in supported:
            raise UnsupportedOption(f"this framework builds only {' or '.join(supported)}")
        return {}

    return rule


def _same_as(other: str) -> _Rule:
    """An option that must equal another (``code_dim`` = ``width``: ours quantizes at its width)."""

    def rule(value: str, options: Mapping[str, str]) -> Overrides:
        if other in options and value != options[other]:
            raise UnsupportedOption(f"this framework's tokenizer needs it equal to {other} "
                                    f"({options[other]})")  # fmt: skip
        return {}

    return rule


def _dilations(value: str, options: Mapping[str, str]) -> Overrides:
    """The reference's residual stack: dilation growth**i for i < depth, in reverse order."""
    growth = _number(value, int)
    depth = _number(options.get("depth", "2"), int)
    return {"model.net.encoder.dilations": [growth**i for i in range(depth)][::-1]}


def _heads(value: str, options: Mapping[str, str]) -> Overrides:
    heads, width = _number(value, int), _number(options.get("latent_dim", "384"), int)
    if heads < 1 or width % heads:
        raise UnsupportedOption(f"{heads} heads do not divide latent_dim {width}")
    return {"model.net.heads": heads}


def _false(value: str, options: Mapping[str, str]) -> Overrides:
    return _only("False")(value, options)


# the tokenizer (the authors' options/vq_option.py)
VQ_ARCHITECTURE: dict[str, _Rule] = {
    "nb_code": _mapped("model.net.quantizer.codebook_size"),
    "width": _mapped("model.net.encoder.width"),
    "code_dim": _same_as("width"),
    "output_emb_width": _same_as("width"),
    "depth": lambda value, options: {},  # with dilation_growth_rate
    "dilation_growth_rate": _dilations,
    "down_t": _only("2"),
    "stride_t": _only("2"),
    "vq_act": _only("relu"),
    "vq_norm": _only("None"),
    "num_quantizers": _mapped("model.net.quantizer.num_quantizers"),
    "shared_codebook": _false,
    "quantize_dropout_prob": _mapped("model.net.quantizer.dropout_prob", float),
    "mu": _mapped("model.net.quantizer.decay", float),
}
VQ_TRAINING = frozenset(
    "dataset_name motion_rep batch_size window_size window_stride gpu_id cache max_epoch lr "
    "gamma weight_decay commit recons_loss loss_explicit loss_vel loss_bn loss_geo loss_fc name "
    "is_continue checkpoints_dir save_every_e eval_every_e feat_bias do_eval test_batch_size "
    "is_train".split()
)

# the generator (the authors' options/base_option.py and trans_option.py)
GENERATOR_ARCHITECTURE: dict[str, _Rule] = {
    "latent_dim": _mapped("model.net.width"),
    "n_heads": _heads,
    "n_layers": _mapped("model.net.depth"),
    "ff_size": _mapped("model.net.ff"),
    "dropout": _mapped("model.net.dropout", float),
    "cond_drop_prob": _mapped("model.condition_drop", float),
    "force_mask": _false,  # True: the release ignores its text
    "gumbel_sample": _false,  # decoding: the release's default Categorical draw (fidelity 4b)
}
GENERATOR_TRAINING = frozenset(
    "dataset_name motion_rep batch_size max_epoch lr step_unroll interaction_mask_prob gamma "
    "seed is_continue eval_every_e do_eval test_batch_size name vq_name gpu_id checkpoints_dir "
    "cache is_train".split()
)


def _overrides(
    options: Mapping[str, str],
    architecture: Mapping[str, _Rule],
    training: Collection[str],
    *,
    source: str,
    ignore: Collection[str],
) -> Overrides:
    overrides: Overrides = {}
    problems = []
    for key, value in options.items():
        if key in architecture:
            try:
                overrides |= architecture[key](value, options)
            except UnsupportedOption as error:
                problems.append(f"{key}: {value} ({error})")
        elif key not in training and key not in ignore:
            problems.append(f"{key}: {value} (not an option of the authors' code: pass "
                            f"--ignore-option {key} if it does not change the network)")  # fmt: skip
    if problems:
        raise UnsupportedOption(
            f"{source}: option(s) this framework cannot build:\n  " + "\n  ".join(problems)
        )
    return overrides


def vq_overrides(
    options: Mapping[str, str], *, source: str, ignore: Collection[str] = ()
) -> Overrides:
    """Config overrides (dotted keys of a ``train_vq`` config) for a tokenizer's ``opt.txt``."""
    return _overrides(options, VQ_ARCHITECTURE, VQ_TRAINING, source=source, ignore=ignore)


def generator_overrides(
    options: Mapping[str, str], *, source: str, ignore: Collection[str] = ()
) -> Overrides:
    """Config overrides (dotted keys of a ``train_gen`` config) for a generator's ``opt.txt``."""
    return _overrides(
        options, GENERATOR_ARCHITECTURE, GENERATOR_TRAINING, source=source, ignore=ignore
    )
