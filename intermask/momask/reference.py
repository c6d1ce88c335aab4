"""MoMask's released checkpoints (the authors' momask-codes) in this framework's layout.

A release keeps each model as ``<name>/model/<which>.tar`` beside ``<name>/opt.txt``: the residual
VQ-VAE under ``vq_model`` (or ``net``), the masked transformer under ``t2m_transformer`` (or
``trans``), the residual transformer under ``res_transformer``. This module turns their state
dicts into ours and their ``opt.txt`` options into config values; :mod:`intermask.convert_momask`
writes the run folders.

- Residual VQ-VAE: the authors' ``RVQVAE`` is the module tree InterMask's release grew from, so
  :func:`intermask.vq.reference.convert_reference_vq` places it (``layout: 1d``).
- Transformers: the same ``nn.TransformerEncoder`` keys; the token embedding, input and output
  layers renamed. Three values are computed rather than copied, each named in the report:
  the condition Linear folds in CLIP's text projection (the authors condition on CLIP's
  projected sentence embedding, this framework on the end-of-text feature before it:
  ``W' = W P^T``); the residual transformer's layer embedding is the one-hot Linear's column
  plus its bias; without shared weights, its output tables are doubled, because the authors'
  ``output_project`` adds the projection to itself (``output += output + bias``).
- The [PAD] rows of the residual transformer's tables are dropped: a padded step is hidden from
  attention, and this framework never predicts padding (the authors' decoding can draw [PAD] at
  a valid step, which their decoder then reads as an unused code).
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping

import torch

from intermask.release_options import (
    Overrides,
    Rule,
    dilations,
    equal_to,
    flag,
    heads,
    mapped,
    nothing,
    only,
    overrides,
)
from intermask.utils.state_conversion import Conversion, compare_with_target

# ---------------------------------------------------------------------------------------------
# opt.txt -> config overrides

DATASET = "t2m"  # HumanML3D, the dataset this framework builds MoMask for

_DATASET_RULE = only(DATASET)

# the residual VQ-VAE (options/vq_option.py)
RVQ_ARCHITECTURE: dict[str, Rule] = {
    "dataset_name": _DATASET_RULE,  # 263-d HumanML3D features (kit: 251-d, not built here)
    "nb_code": mapped("model.net.quantizer.codebook_size"),
    "width": mapped("model.net.encoder.width"),
    "code_dim": equal_to("width"),  # ours quantizes at the encoder's width
    "output_emb_width": equal_to("width"),
    "depth": nothing,  # read with dilation_growth_rate
    "dilation_growth_rate": dilations(default_depth=3),
    "down_t": only("2"),  # two stride-2 stages: one token per 4 frames
    "stride_t": only("2"),
    "vq_act": only("relu"),
    "vq_norm": only("None"),
    "num_quantizers": mapped("model.net.quantizer.num_quantizers"),
    "shared_codebook": only("False"),  # one codebook per layer
    "quantize_dropout_prob": mapped("model.net.quantizer.dropout_prob", float),
    "mu": mapped("model.net.quantizer.decay", float),
}
RVQ_TRAINING = frozenset(
    "batch_size window_size gpu_id max_epoch warm_up_iter lr milestones gamma weight_decay commit "
    "loss_vel recons_loss ext name is_continue checkpoints_dir log_every save_latest save_every_e "
    "eval_every_e feat_bias which_epoch vq_name seed is_train".split()
)

# both transformers (options/base_option.py, options/train_option.py)
TRANSFORMER_ARCHITECTURE: dict[str, Rule] = {
    "dataset_name": _DATASET_RULE,
    "latent_dim": mapped("model.net.width"),
    "n_heads": heads,
    "n_layers": mapped("model.net.depth"),
    "ff_size": mapped("model.net.ff"),
    "dropout": mapped("model.net.dropout", float),
    "unit_length": only("4"),  # frames per token (the tokenizer's two stride-2 stages)
    "cond_drop_prob": mapped("model.condition_drop", float),
    "force_mask": only("False"),  # True: the release ignores its text
    "gumbel_sample": only("False"),  # the release's decoding draws from Categorical
}
TRANSFORMER_TRAINING = frozenset(
    "name vq_name gpu_id checkpoints_dir max_motion_length batch_size max_epoch lr gamma "
    "milestones warm_up_iter seed is_continue log_every eval_every_e save_latest is_train".split()
)


def rvq_overrides(
    options: Mapping[str, str], *, source: str, ignore: Collection[str] = ()
) -> Overrides:
    """Config overrides (dotted keys of a ``train_vq`` config) for an RVQ's ``opt.txt``."""
    return overrides(options, RVQ_ARCHITECTURE, RVQ_TRAINING, source=source, ignore=ignore)


def transformer_overrides(
    options: Mapping[str, str], *, residual: bool, source: str, ignore: Collection[str] = ()
) -> Overrides:
    """Config overrides (dotted keys of a ``train_gen`` config) for a transformer's ``opt.txt``;
    ``share_weight`` ties the residual transformer's tables and is a training flag of the masked
    one."""
    architecture = dict(TRANSFORMER_ARCHITECTURE)
    training = set(TRANSFORMER_TRAINING)
    if residual:
        architecture["share_weight"] = flag("model.net.share_weights")
    else:
        training.add("share_weight")
    return overrides(options, architecture, training, source=source, ignore=ignore)


# ---------------------------------------------------------------------------------------------
# state dicts

_ENCODER_LAYER = re.compile(r"seqTransEncoder\.layers\.(?P<rest>\d+\..+)")
_SHARED = {  # the parts both transformers have, release key -> ours
    "input_process.poseEmbedding.weight": "backbone.input_projection.weight",
    "input_process.poseEmbedding.bias": "backbone.input_projection.bias",
    "cond_emb.bias": "backbone.condition_projection.bias",
    "output_process.dense.weight": "head.dense.weight",
    "output_process.dense.bias": "head.dense.bias",
    "output_process.LayerNorm.weight": "head.norm.weight",
    "output_process.LayerNorm.bias": "head.norm.bias",
    "output_process.poseFinal.weight": "head.out.weight",
    "output_process.poseFinal.bias": "head.out.bias",
}
WHY_TRANSFORMER = (
    "dropped: clip_model.* is the frozen CLIP tower (this framework's text cache encodes the "
    "captions); the [PAD] rows of the residual tables never reach a valid step",
    "computed: the positions are this model's own sinusoid table (checked against the "
    "release's position_enc.pe); the condition Linear folds in CLIP's text projection",
)


class _Builder:
    """Collects a conversion: our key -> value, with the release key each came from."""

    def __init__(self) -> None:
        self.out: dict[str, torch.Tensor] = {}
        self.sources: dict[str, str] = {}
        self.dropped: list[str] = []
        self.computed: list[str] = []
        self.unmapped: list[str] = []
        self.mismatched: list[str] = []

    def put(self, ours: str, value: torch.Tensor, source: str, computed: bool = False) -> None:
        self.out[ours], self.sources[ours] = value, source
        if computed:
            self.computed.append(ours)

    def finish(self, target: Mapping[str, torch.Tensor] | None, why: tuple[str, ...]) -> Conversion:
        missing, extra, mismatched = compare_with_target(self.out, target, self.sources)
        return Conversion(
            self.out,
            self.dropped,
            self.computed,
            self.unmapped + extra,
            missing,
            self.mismatched + mismatched,
            why,
        )


def _fold_condition(build: _Builder, weight: torch.Tensor, projection: torch.Tensor | None) -> None:
    """``cond_emb.weight`` (D, D_clip) applied to CLIP's sentence embedding ``f P`` equals
    ``W P^T`` applied to the end-of-text feature f (B, D_text) this framework conditions on."""
    if projection is None:
        build.put("backbone.condition_projection.weight", weight, "cond_emb.weight")
        return
    if weight.shape[1] != projection.shape[1]:
        build.mismatched.append(
            f"cond_emb.weight: release {tuple(weight.shape)} takes {weight.shape[1]}-d sentence "
            f"embeddings, the text encoder projects to {projection.shape[1]}"
        )
        return
    folded = (weight.double() @ projection.double().T).to(weight.dtype)
    build.put("backbone.condition_projection.weight", folded, "cond_emb.weight", computed=True)


def _positions(build: _Builder, value: torch.Tensor, target: Mapping[str, torch.Tensor] | None):
    """``position_enc.pe`` (5000, 1, D): ours computes the same table (its first max_steps rows)."""
    ours = "backbone.positions.pe"
    table = value.reshape(value.shape[0], -1)
    if target is None or ours not in target:
        build.put(ours, table, "position_enc.pe", computed=True)
        return
    mine = target[ours]
    rows = mine.shape[0]
    if table.shape[0] < rows or table.shape[1] != mine.shape[1]:
        build.mismatched.append(
            f"position_enc.pe (-> {ours}): release {tuple(value.shape)} vs ours {tuple(mine.shape)}"
        )
    elif not torch.allclose(table[:rows], mine, atol=1e-5, rtol=0):
        build.mismatched.append(
            f"position_enc.pe (-> {ours}): not the sinusoid table this model computes (max "
            f"difference {float((table[:rows] - mine).abs().max()):.3g})"
        )
    else:
        build.put(ours, mine.clone(), "position_enc.pe", computed=True)


def _common(
    build: _Builder,
    key: str,
    value: torch.Tensor,
    target: Mapping[str, torch.Tensor] | None,
    projection: torch.Tensor | None,
) -> bool:
    """Place a key both transformers share; False when it is not one of them."""
    if key.startswith("clip_model."):
        build.dropped.append(key)
    elif key in _SHARED:
        build.put(_SHARED[key], value, key)
    elif key == "cond_emb.weight":
        _fold_condition(build, value, projection)
    elif key == "position_enc.pe":
        _positions(build, value, target)
    elif (layer := _ENCODER_LAYER.fullmatch(key)) is not None:
        build.put(f"backbone.encoder.layers.{layer['rest']}", value, key)
    else:
        return False
    return True


def convert_reference_mask(
    reference: Mapping[str, torch.Tensor],
    target: Mapping[str, torch.Tensor] | None = None,
    *,
    text_projection: torch.Tensor | None = None,
) -> Conversion:
    """The authors' ``MaskTransformer`` state dict -> our :class:`MaskedTransformer`'s.

    ``text_projection``: CLIP's (D_text, D_clip) ``text_projection`` of the text encoder the
    converted network will read (folded into the condition Linear; None copies it unchanged).
    ``target``: our network's state dict, which adds the missing and mis-shaped keys.
    """
    build = _Builder()
    for key, value in reference.items():
        if key == "token_emb.weight":  # codes, [MASK] = K, [PAD] = K + 1: our order too
            build.put("token_embedding.weight", value, key)
        elif not _common(build, key, value, target, text_projection):
            build.unmapped.append(key)
    return build.finish(target, WHY_TRANSFORMER)


_RESIDUAL_TABLES = (
    "token_embed_weight",
    "output_proj_weight",
    "output_proj_bias",
    "embed_proj_shared_weight",
    "token_embed_weight_",
    "output_proj_weight_",
)


def _codes_of(
    build: _Builder, source: str, value: torch.Tensor, codes: int, axis: int = -2
) -> torch.Tensor | None:
    """The K code entries along ``axis`` of a release table (K + 1 there: the codes, then
    [PAD]), or None (and a mismatch) when it was made for another codebook size."""
    if value.shape[axis] != codes + 1:
        build.mismatched.append(
            f"{source}: release {tuple(value.shape)} has {value.shape[axis]} entries per layer, "
            f"the tokenizer's {codes} codes and [PAD] need {codes + 1}"
        )
        return None
    return value.narrow(axis, 0, codes)


def _residual_tables(build: _Builder, reference: Mapping[str, torch.Tensor], codes: int) -> None:
    """The per-layer code tables of the authors' residual transformer onto ours.

    With ``share_weight`` (the release): ``token_embed_weight_`` (1, K+1, E) embeds layer 0,
    ``embed_proj_shared_weight`` (Q-2, K+1, E) embeds layers 1..Q-2 and scores the same layers,
    ``output_proj_weight_`` (1, K+1, E) scores layer Q-1: our ``tables.0..Q-1``. Without it:
    ``token_embed_weight`` (Q-1, K+1, E) embeds layers 0..Q-2, ``output_proj_weight`` (Q-1, K+1, E)
    and ``output_proj_bias`` (Q, K+1) score layers 1..Q-1, the projection counted twice.
    """
    if "embed_proj_shared_weight" in reference:
        shared = reference["embed_proj_shared_weight"]
        tables = [
            ("token_embed_weight_", reference.get("token_embed_weight_")),
            *((f"embed_proj_shared_weight[{i}]", shared[i : i + 1]) for i in range(len(shared))),
            ("output_proj_weight_", reference.get("output_proj_weight_")),
        ]
        for index, (source, value) in enumerate(tables):
            rows = None if value is None else _codes_of(build, source, value, codes)
            if rows is not None:  # an absent table is named by the target comparison
                build.put(f"tables.{index}", rows[0], source)
        build.dropped.append("the [PAD] row of every table (row K)")
        zeros = shared.new_zeros(len(tables) - 1, codes)  # the release has no output bias
        build.put("head_bias", zeros, "(no output bias with shared tables)", computed=True)
        return
    embed, project = reference.get("token_embed_weight"), reference.get("output_proj_weight")
    bias = reference.get("output_proj_bias")
    embed = None if embed is None else _codes_of(build, "token_embed_weight", embed, codes)
    for i in range(0 if embed is None else len(embed)):
        build.put(f"tables.{i}", embed[i], f"token_embed_weight[{i}]")
    project = None if project is None else _codes_of(build, "output_proj_weight", project, codes)
    for i in range(0 if project is None else len(project)):
        # the authors' output_project: output += output + bias, i.e. 2 W h + b
        build.put(f"head_tables.{i}", 2.0 * project[i], f"output_proj_weight[{i}]", computed=True)
    bias = None if bias is None else _codes_of(build, "output_proj_bias", bias, codes, axis=-1)
    if bias is not None:
        build.put("head_bias", bias[:-1], "output_proj_bias")
        build.dropped.append("output_proj_bias[-1] (layer 0 is never predicted)")
    build.dropped.append("the [PAD] row of every table (row K)")


def convert_reference_residual(
    reference: Mapping[str, torch.Tensor],
    target: Mapping[str, torch.Tensor] | None = None,
    *,
    codebook_size: int,
    text_projection: torch.Tensor | None = None,
) -> Conversion:
    """The authors' ``ResidualTransformer`` state dict -> our :class:`ResidualTransformer`'s
    (``codebook_size``: K of the tokenizer; ``target`` and ``text_projection`` as in
    :func:`convert_reference_mask`)."""
    build = _Builder()
    for key, value in reference.items():
        if key in _RESIDUAL_TABLES:
            continue
        if key == "quant_emb.weight":  # (D, Q) on one-hot layer ids; row j-1 of ours is layer j
            bias = reference.get("quant_emb.bias", torch.zeros(value.shape[0]))
            build.put("layer_embedding.weight", (value[:, 1:] + bias[:, None]).T.contiguous(),
                      key, computed=True)  # fmt: skip
        elif key == "quant_emb.bias":
            continue
        elif not _common(build, key, value, target, text_projection):
            build.unmapped.append(key)
    _residual_tables(build, reference, codebook_size)
    return build.finish(target, (*WHY_TRANSFORMER, *_WHY_RESIDUAL))


_WHY_RESIDUAL = (
    "computed: layer_embedding = the release's one-hot quant_emb column of each predicted layer "
    "plus its bias; head_bias = 0 with shared tables (the release has none); without shared "
    "tables the output tables are doubled (the release adds its projection to itself)",
)
