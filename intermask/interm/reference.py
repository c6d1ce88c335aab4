"""The reference implementation's Inter-M weights in this framework's layout.

The authors' release stores the generator as a ``MaskTransformer`` state dict (the
``t2m_transformer`` entry of its checkpoint). Its modules map one to one onto
:class:`~intermask.interm.model.InterMTransformer` built with the reference switches
(``text_attends_padding``, ``double_residual_quirk``, ``cross_context_quirk``; docs/fidelity.md),
with three differences of packing:

* attention: ``nn.MultiheadAttention`` packs query, key and value in one ``in_proj``; ours keeps
  the query apart from the packed key/value;
* AdaLN: each reference block regresses the joint stage's 6 vectors and the person stage's 14 in
  two linears; ours gives every sub-layer its own (3 + 3, then 6 + 5 + 3), in the same order;
* the frozen CLIP text tower lives inside the reference model; here its per-token features come
  from the text cache, so those keys are dropped (and reported);
* the reference stores its 2D position encoding's frequencies as a buffer; ours computes them
  (``interm/position.py``), so the buffer is checked against ours and not copied.

:func:`convert_reference_generator` returns the state dict and a report naming every key it
dropped, every reference key it could not place and every key of ours left without a value.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from intermask.interm.position import axis_frequencies
from intermask.utils.state_conversion import Conversion, compare_with_target

# reference prefix -> ours, for modules whose parameters keep their names
_RENAMED = {
    "token_emb.": "token_embedding.",
    "input_process.poseEmbedding.": "token_projection.",
    "cond_emb.": "condition_projection.",
    "clipTrans.": "text_encoder.",
    "clipln.": "text_norm.",
    "output_process.dense.": "head.dense.",
    "output_process.adaLN_mod.model.1.": "head.modulation.linear.",
    "output_process.poseFinal.": "head.logits.",
}
# the frozen CLIP tower kept inside the reference model (features come from the text cache)
_CLIP_PREFIXES = (
    "clip_token_embedding.",
    "clip_transformer.",
    "clip_positional_embedding",
    "clip_ln_final.",
)
# reference attention module -> ours, inside block i
_ATTENTION = {
    "self_attn.attention": "self_attention.attention",
    "spa_temp_attn.spatial_attention": "spatio_temporal.attention.spatial",
    "spa_temp_attn.temporal_attention": "spatio_temporal.attention.temporal",
    "local_inter_attn.interaction_attention": "cross_attention.attention",
}
_FFN = {"ffn_combined": "joint_ffn", "ffn_split": "person_ffn"}
# reference AdaLN linear -> ours, in chunk order (number of width-sized chunks each)
_MODULATION = {
    "adaLN_mod_combined": (("self_attention", 3), ("joint_ffn", 3)),
    "adaLN_mod_split": (("spatio_temporal", 6), ("cross_attention", 5), ("person_ffn", 3)),
}
_FFN_LINEARS = {"model.0.": "net.0.", "model.3.": "net.3."}
_FREQUENCIES = "position_enc.positional_encoding.inv_freq"


def _block_key(rest: str, block: str, value: torch.Tensor, out: dict[str, torch.Tensor]) -> bool:
    """Place one reference key of block ``block`` (``rest`` after ``Transformer.blocks.i.``)."""
    for reference, ours in _ATTENTION.items():
        if rest.startswith(reference + "."):
            name = rest[len(reference) + 1 :]
            target = f"{block}.{ours}"
            if name in ("in_proj_weight", "in_proj_bias"):
                width = value.shape[0] // 3
                kind = "weight" if name.endswith("weight") else "bias"
                out[f"{target}.query.{kind}"] = value[:width]
                out[f"{target}.key_value.{kind}"] = value[width:]
                return True
            if name.startswith("out_proj."):
                out[f"{target}.out.{name[len('out_proj.') :]}"] = value
                return True
            return False
    for reference, ours in _FFN.items():
        for linear, mapped in _FFN_LINEARS.items():
            if rest.startswith(f"{reference}.{linear}"):
                out[f"{block}.{ours}.{mapped}{rest[len(reference) + 1 + len(linear) :]}"] = value
                return True
    for reference, parts in _MODULATION.items():
        prefix = f"{reference}.model.1."
        if rest.startswith(prefix):
            kind = rest[len(prefix) :]
            width = value.shape[0] // sum(chunks for _, chunks in parts)
            start = 0
            for layer, chunks in parts:
                out[f"{block}.{layer}.modulation.linear.{kind}"] = value[
                    start : start + chunks * width
                ]
                start += chunks * width
            return True
    return False


def convert_reference_generator(
    reference: Mapping[str, torch.Tensor], target: Mapping[str, torch.Tensor] | None = None
) -> Conversion:
    """The reference ``MaskTransformer`` state dict -> ours (see the module docstring).

    ``target``: our model's state dict; when given, keys it lacks or holds in another shape are
    reported, and its keys without a converted value too.
    """
    out: dict[str, torch.Tensor] = {}
    sources: dict[str, str] = {}  # ours -> the release key it came from
    dropped, unmapped, computed, mismatched = [], [], [], []
    for key, value in reference.items():
        placed = len(out)
        _place(key, value, out, dropped, computed, mismatched, unmapped)
        sources |= dict.fromkeys(list(out)[placed:], key)
    missing, extra, misshaped = compare_with_target(out, target, sources)
    return Conversion(
        out, dropped, computed, unmapped + extra, missing, mismatched + misshaped, WHY
    )


WHY = (
    "dropped: the frozen CLIP tower the release keeps inside its model (this framework takes "
    "CLIP's per-token features from the text cache, computed by the same tower)",
    "computed: the 2D position encoding's frequencies (checked equal to the release's buffer)",
)


def _place(
    key: str,
    value: torch.Tensor,
    out: dict[str, torch.Tensor],
    dropped: list[str],
    computed: list[str],
    mismatched: list[str],
    unmapped: list[str],
) -> None:
    """Put one release key where it belongs (``out``) or in the list that says why not."""
    if key.startswith(_CLIP_PREFIXES):
        dropped.append(key)
        return
    if key == _FREQUENCIES:
        computed.append(key)
        if not _same_frequencies(value):
            mismatched.append(f"{key}: not the 2D encoding's frequencies for this width")
        return
    renamed = next((p for p in _RENAMED if key.startswith(p)), None)
    if renamed is not None:
        out[_RENAMED[renamed] + key[len(renamed) :]] = value
        return
    if key.startswith("Transformer.blocks."):
        index, _, rest = key[len("Transformer.blocks.") :].partition(".")
        if _block_key(rest, f"blocks.{index}", value, out):
            return
    unmapped.append(key)


def _same_frequencies(value: torch.Tensor) -> bool:
    """The reference's (C/2,) inverse frequencies against ours for a width D = 2C (C = D/2
    channels per axis, interleaved sin/cos: 10000^(-2i / C))."""
    if value.is_meta or value.ndim != 1:
        return value.ndim == 1
    ours = axis_frequencies(2 * value.shape[0])
    return torch.allclose(value.double(), ours, rtol=1e-6, atol=0.0)
