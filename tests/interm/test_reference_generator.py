"""The reference release's generator keys land on ours (docs/fidelity.md, issue: reference
parity). The key names and shapes below are the reference ``MaskTransformer``'s module tree at
the paper size, written out as data; they are built on the meta device (no memory)."""

from __future__ import annotations

import torch

from intermask.interm.model import InterMTransformer
from intermask.interm.reference import convert_reference_generator

D, FF, K, CODE, TEXT, TEXT_FF, DEPTH = 384, 1024, 1024, 512, 768, 2048, 6


def _attention(prefix: str, width: int) -> dict[str, tuple[int, ...]]:
    return {
        f"{prefix}.in_proj_weight": (3 * width, width),
        f"{prefix}.in_proj_bias": (3 * width,),
        f"{prefix}.out_proj.weight": (width, width),
        f"{prefix}.out_proj.bias": (width,),
    }


def _ffn(prefix: str) -> dict[str, tuple[int, ...]]:
    return {
        f"{prefix}.model.0.weight": (FF, D),
        f"{prefix}.model.0.bias": (FF,),
        f"{prefix}.model.3.weight": (D, FF),
        f"{prefix}.model.3.bias": (D,),
    }


def reference_layout() -> dict[str, tuple[int, ...]]:
    """Key -> shape of the reference's generator state dict (InterHuman, paper size)."""
    keys: dict[str, tuple[int, ...]] = {
        "token_emb.weight": (K + 3, CODE),
        "input_process.poseEmbedding.weight": (D, CODE),
        "input_process.poseEmbedding.bias": (D,),
        "cond_emb.weight": (D, TEXT),
        "cond_emb.bias": (D,),
        "output_process.dense.weight": (D, D),
        "output_process.dense.bias": (D,),
        "output_process.adaLN_mod.model.1.weight": (2 * D, D),
        "output_process.adaLN_mod.model.1.bias": (2 * D,),
        "output_process.poseFinal.weight": (K, D),
        "output_process.poseFinal.bias": (K,),
        "position_enc.positional_encoding.inv_freq": (D // 4,),
        "clipln.weight": (TEXT,),
        "clipln.bias": (TEXT,),
        # the frozen CLIP tower (dropped: its features come from the text cache)
        "clip_token_embedding.weight": (49408, TEXT),
        "clip_positional_embedding": (77, TEXT),
        "clip_transformer.resblocks.0.attn.in_proj_weight": (3 * TEXT, TEXT),
        "clip_ln_final.weight": (TEXT,),
        "clip_ln_final.bias": (TEXT,),
    }
    for layer in range(2):
        prefix = f"clipTrans.layers.{layer}"
        keys |= _attention(f"{prefix}.self_attn", TEXT)
        keys |= {
            f"{prefix}.linear1.weight": (TEXT_FF, TEXT),
            f"{prefix}.linear1.bias": (TEXT_FF,),
            f"{prefix}.linear2.weight": (TEXT, TEXT_FF),
            f"{prefix}.linear2.bias": (TEXT,),
            **{f"{prefix}.norm{n}.{p}": (TEXT,) for n in (1, 2) for p in ("weight", "bias")},
        }
    for block in range(DEPTH):
        prefix = f"Transformer.blocks.{block}"
        keys |= {
            f"{prefix}.adaLN_mod_combined.model.1.weight": (6 * D, D),
            f"{prefix}.adaLN_mod_combined.model.1.bias": (6 * D,),
            f"{prefix}.adaLN_mod_split.model.1.weight": (14 * D, D),
            f"{prefix}.adaLN_mod_split.model.1.bias": (14 * D,),
        }
        keys |= _attention(f"{prefix}.self_attn.attention", D)
        keys |= _attention(f"{prefix}.spa_temp_attn.spatial_attention", D)
        keys |= _attention(f"{prefix}.spa_temp_attn.temporal_attention", D)
        keys |= _attention(f"{prefix}.local_inter_attn.interaction_attention", D)
        keys |= _ffn(f"{prefix}.ffn_combined") | _ffn(f"{prefix}.ffn_split")
    return keys


def _reference_switches() -> dict:
    return {
        "text_attends_padding": True,
        "double_residual_quirk": True,
        "cross_context_quirk": True,
    }


def test_every_reference_key_lands_on_the_paper_model():
    layout = reference_layout()
    with torch.device("meta"):
        reference = {key: torch.empty(shape) for key, shape in layout.items()}
        ours = InterMTransformer(codebook_size=K, **_reference_switches()).state_dict()
    conversion = convert_reference_generator(reference, ours)
    assert conversion.complete, conversion.report()
    assert sorted(conversion.dropped) == sorted(k for k in layout if k.startswith("clip_"))
    assert set(conversion.state) == set(ours)
    report = conversion.report()
    assert (
        "dropped on purpose (5): clip_token_embedding.weight, clip_positional_embedding," in report
    )
    assert "computed here (1): position_enc.positional_encoding.inv_freq" in report
    assert "dropped: the frozen CLIP tower" in report
    assert conversion.computed == ["position_enc.positional_encoding.inv_freq"]


def test_the_reference_position_frequencies_are_checked_against_ours():
    channels = D // 2  # per axis
    frequencies = 1.0 / (10000 ** (torch.arange(0, channels, 2).float() / channels))
    key = "position_enc.positional_encoding.inv_freq"
    assert convert_reference_generator({key: frequencies}).mismatched == []
    wrong = convert_reference_generator({key: frequencies * 2}).mismatched
    assert wrong == [f"{key}: not the 2D encoding's frequencies for this width"]


def test_packed_weights_are_split_in_order():
    generator = torch.Generator().manual_seed(0)
    width = 8
    layout = {
        "Transformer.blocks.0.self_attn.attention.in_proj_weight": (3 * width, width),
        "Transformer.blocks.0.adaLN_mod_split.model.1.bias": (14 * width,),
    }
    reference = {k: torch.randn(s, generator=generator) for k, s in layout.items()}
    state = convert_reference_generator(reference).state
    packed = reference["Transformer.blocks.0.self_attn.attention.in_proj_weight"]
    assert torch.equal(state["blocks.0.self_attention.attention.query.weight"], packed[:width])
    assert torch.equal(state["blocks.0.self_attention.attention.key_value.weight"], packed[width:])
    split = reference["Transformer.blocks.0.adaLN_mod_split.model.1.bias"]
    # spatial/temporal shift, scale, gate (6), then cross (5), then the person FFN (3)
    assert torch.equal(state["blocks.0.spatio_temporal.modulation.linear.bias"], split[: 6 * width])
    assert torch.equal(
        state["blocks.0.cross_attention.modulation.linear.bias"], split[6 * width : 11 * width]
    )
    assert torch.equal(state["blocks.0.person_ffn.modulation.linear.bias"], split[11 * width :])


def test_unknown_missing_and_misshaped_keys_are_reported_by_name():
    with torch.device("meta"):
        ours = InterMTransformer(codebook_size=K, **_reference_switches()).state_dict()
        layout = reference_layout()
        reference = {key: torch.empty(shape) for key, shape in layout.items()}
    reference["Transformer.blocks.0.extra_gate.weight"] = torch.empty(3, device="meta")
    reference["cond_emb.weight"] = torch.empty(D, 512, device="meta")  # a CLIP ViT-B width
    del reference["output_process.poseFinal.bias"]
    conversion = convert_reference_generator(reference, ours)
    assert not conversion.complete
    assert conversion.unmapped == ["Transformer.blocks.0.extra_gate.weight"]
    assert conversion.missing == ["head.logits.bias"]
    assert conversion.mismatched == [
        "cond_emb.weight (-> condition_projection.weight): release (384, 512) vs ours (384, 768)"
    ]
    report = conversion.report()
    assert "release keys with no place here (1): Transformer.blocks.0.extra_gate.weight" in report
    assert "keys of ours without a value (1): head.logits.bias" in report
