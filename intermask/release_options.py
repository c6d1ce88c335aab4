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
The rules (:func:`mapped`, :func:`only`, :func:`heads`, ...) and :func:`overrides` serve the
MoMask release too (:mod:`intermask.momask.reference` holds its tables).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from typing import Any

Overrides = dict[str, Any]
Rule = Callable[[str, Mapping[str, str]], Overrides]  # (value, all options) -> config values


class UnsupportedOption(ValueError):
    """An ``opt.txt`` option this framework cannot build (or does not know)."""


def number(text: str, kind: type) -> Any:
    """An option's value as ``int`` or ``float`` (``"2.0"`` is the int 2, ``"2.5"`` no int)."""
    try:
        value = float(text)
    except ValueError as error:
        raise UnsupportedOption(f"not a {kind.__name__}: {text!r}") from error
    if kind is int and not value.is_integer():
        raise UnsupportedOption(f"not an int: {text!r}")
    return kind(value)


def mapped(key: str, kind: type = int) -> Rule:
    """An option that sets the config value ``key``."""
    return lambda value, options: {key: number(value, kind)}


def only(*supported: str) -> Rule:
    """An option whose only value(s) here are ``supported`` (it sets nothing)."""

    def rule(value: str, options: Mapping[str, str]) -> Overrides:
        if value not in supported:
            raise UnsupportedOption(f"this framework builds only {' or '.join(supported)}")
        return {}

    return rule


def flag(key: str) -> Rule:
    """A True/False option that sets the boolean config value ``key``."""

    def rule(value: str, options: Mapping[str, str]) -> Overrides:
        if value not in ("True", "False"):
            raise UnsupportedOption("not True or False")
        return {key: value == "True"}

    return rule


def equal_to(other: str) -> Rule:
    """An option that must equal another (``code_dim`` = ``width``: ours quantizes at its width)."""

    def rule(value: str, options: Mapping[str, str]) -> Overrides:
        if other in options and number(value, int) != number(options[other], int):
            raise UnsupportedOption(
                f"this framework's tokenizer needs it equal to {other} ({options[other]})"
            )
        return {}

    return rule


def dilations(default_depth: int) -> Rule:
    """``dilation_growth_rate`` with ``depth``: the authors' residual stack has the dilations
    growth**i for i < depth, in reverse order."""

    def rule(value: str, options: Mapping[str, str]) -> Overrides:
        growth = number(value, int)
        depth = number(options.get("depth", str(default_depth)), int)
        if growth < 1 or depth < 1:
            raise UnsupportedOption(f"needs growth >= 1 and depth >= 1, got {growth} and {depth}")
        return {"model.net.encoder.dilations": [growth**i for i in range(depth)][::-1]}

    return rule


def heads(value: str, options: Mapping[str, str]) -> Overrides:
    """``n_heads``, which must divide ``latent_dim``."""
    count, width = number(value, int), number(options.get("latent_dim", "384"), int)
    if count < 1 or width % count:
        raise UnsupportedOption(f"{count} heads do not divide latent_dim {width}")
    return {"model.net.heads": count}


def nothing(value: str, options: Mapping[str, str]) -> Overrides:
    """An option read together with another one (``depth`` with ``dilation_growth_rate``)."""
    return {}


def overrides(
    options: Mapping[str, str],
    architecture: Mapping[str, Rule],
    training: Collection[str],
    *,
    source: str,
    ignore: Collection[str],
) -> Overrides:
    """Every option of ``options``: an architecture option through its rule, a training option
    (or one in ``ignore``) passed over; all problems reported at once, each by name."""
    result: Overrides = {}
    problems = []
    for key, value in options.items():
        if key in architecture:
            try:
                result |= architecture[key](value, options)
            except UnsupportedOption as error:
                problems.append(f"{key}: {value} ({error})")
        elif key not in training and key not in ignore:
            problems.append(
                f"{key}: {value} (not an option of the authors' code: pass --ignore-option "
                f"{key} if it does not change the network)"
            )
    if problems:
        raise UnsupportedOption(
            f"{source}: option(s) this framework cannot build:\n  " + "\n  ".join(problems)
        )
    return result


# the tokenizer (the authors' options/vq_option.py)
VQ_ARCHITECTURE: dict[str, Rule] = {
    "nb_code": mapped("model.net.quantizer.codebook_size"),
    "width": mapped("model.net.encoder.width"),
    "code_dim": equal_to("width"),
    "output_emb_width": equal_to("width"),
    "depth": nothing,  # read with dilation_growth_rate
    "dilation_growth_rate": dilations(default_depth=2),
    "down_t": only("2"),
    "stride_t": only("2"),
    "vq_act": only("relu"),
    "vq_norm": only("None"),
    "num_quantizers": mapped("model.net.quantizer.num_quantizers"),
    "shared_codebook": only("False"),
    "quantize_dropout_prob": mapped("model.net.quantizer.dropout_prob", float),
    "mu": mapped("model.net.quantizer.decay", float),
}
VQ_TRAINING = frozenset(
    "dataset_name motion_rep batch_size window_size window_stride gpu_id cache max_epoch lr "
    "gamma weight_decay commit recons_loss loss_explicit loss_vel loss_bn loss_geo loss_fc name "
    "is_continue checkpoints_dir save_every_e eval_every_e feat_bias do_eval test_batch_size "
    "is_train".split()
)

# the generator (the authors' options/base_option.py and trans_option.py)
GENERATOR_ARCHITECTURE: dict[str, Rule] = {
    "latent_dim": mapped("model.net.width"),
    "n_heads": heads,
    "n_layers": mapped("model.net.depth"),
    "ff_size": mapped("model.net.ff"),
    "dropout": mapped("model.net.dropout", float),
    "cond_drop_prob": mapped("model.condition_drop", float),
    "force_mask": only("False"),  # True: the release ignores its text
    # decoding: the release's default Categorical draw (fidelity 4b)
    "gumbel_sample": only("False"),
}
GENERATOR_TRAINING = frozenset(
    "dataset_name motion_rep batch_size max_epoch lr step_unroll interaction_mask_prob gamma "
    "seed is_continue eval_every_e do_eval test_batch_size name vq_name gpu_id checkpoints_dir "
    "cache is_train".split()
)


def vq_overrides(
    options: Mapping[str, str], *, source: str, ignore: Collection[str] = ()
) -> Overrides:
    """Config overrides (dotted keys of a ``train_vq`` config) for a tokenizer's ``opt.txt``."""
    return overrides(options, VQ_ARCHITECTURE, VQ_TRAINING, source=source, ignore=ignore)


def generator_overrides(
    options: Mapping[str, str], *, source: str, ignore: Collection[str] = ()
) -> Overrides:
    """Config overrides (dotted keys of a ``train_gen`` config) for a generator's ``opt.txt``."""
    return overrides(
        options, GENERATOR_ARCHITECTURE, GENERATOR_TRAINING, source=source, ignore=ignore
    )
