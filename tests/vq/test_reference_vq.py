"""The reference release's VQ-VAE keys land on ours (Inter-X, whose release uses convolutions
throughout); the InterHuman release's graph layers are reported by name. The key names and
shapes are the reference ``RVQVAE``'s module tree, written out as data."""

from __future__ import annotations

import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

from intermask.train import CONFIG_DIR
from intermask.vq.reference import convert_reference_vq

W = 512


def _resnet(prefix: str) -> dict[str, tuple[int, ...]]:
    keys = {}
    for block in range(2):
        keys[f"{prefix}.model.{block}.conv1.weight"] = (W, W, 3, 3)
        keys[f"{prefix}.model.{block}.conv1.bias"] = (W,)
        keys[f"{prefix}.model.{block}.conv2.weight"] = (W, W, 1, 1)
        keys[f"{prefix}.model.{block}.conv2.bias"] = (W,)
    return keys


def reference_interx_layout() -> dict[str, tuple[int, ...]]:
    keys = {
        "encoder.model.0.weight": (W, 6, 3, 3),
        "encoder.model.0.bias": (W,),
        "encoder.model.4.weight": (W, W, 3, 3),
        "encoder.model.4.bias": (W,),
        "decoder.model.0.weight": (W, W, 3, 3),
        "decoder.model.0.bias": (W,),
        "decoder.model.4.weight": (W, W, 3, 3),
        "decoder.model.4.bias": (W,),
        "decoder.model.6.weight": (6, W, 3, 3),
        "decoder.model.6.bias": (6,),
        "quantizer.layers.0.codebook": (1024, W),
    }
    for stage in (2, 3):
        keys[f"encoder.model.{stage}.0.weight"] = (W, W, 6, 4)
        keys[f"encoder.model.{stage}.0.bias"] = (W,)
        keys |= _resnet(f"encoder.model.{stage}.1")
        keys |= _resnet(f"decoder.model.{stage}.0")
        keys[f"decoder.model.{stage}.2.weight"] = (W, W, 3, 3)
        keys[f"decoder.model.{stage}.2.bias"] = (W,)
    return keys


def _ours(dataset: str):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose("train_vq", overrides=[f"data={dataset}"])
    with torch.device("meta"):
        return instantiate(cfg.model.net)


def test_every_reference_interx_key_lands_and_the_ema_statistics_are_derived():
    reference = {k: torch.randn(s) if "codebook" in k else torch.empty(s, device="meta")
                 for k, s in reference_interx_layout().items()}  # fmt: skip
    conversion = convert_reference_vq(reference, _ours("interx").state_dict())
    assert conversion.complete, conversion.report()
    codebook = reference["quantizer.layers.0.codebook"]
    assert torch.equal(conversion.state["quantizer.layers.0.ema_sum"], codebook)
    assert torch.equal(conversion.state["quantizer.layers.0.ema_count"], torch.ones(1024))
    assert bool(conversion.state["quantizer.layers.0.initialized"])
    assert conversion.computed == [
        "quantizer.layers.0.ema_sum",
        "quantizer.layers.0.ema_count",
        "quantizer.layers.0.initialized",
    ]


def test_the_interhuman_graph_layers_are_reported_by_name():
    reference = {
        "encoder.gcn_layer1.lin.weight": torch.empty(W, 12, device="meta"),
        "decoder.gcn_layer2.lin_l.weight": torch.empty(12, W, device="meta"),
        "decoder.model.0.weight": torch.empty(W, W, 3, 3, device="meta"),
    }
    conversion = convert_reference_vq(reference)
    assert conversion.unmapped == [
        "encoder.gcn_layer1.lin.weight",
        "decoder.gcn_layer2.lin_l.weight",
    ]
    assert "reference keys with no place (2)" in conversion.report()


def test_the_decoder_keeps_the_encoders_dilation_order_as_the_reference_does():
    decoder = _ours("interhuman").decoder
    dilations = [block.body[1].dilation[0] for block in decoder.net[2]]
    assert dilations == [3, 1]  # the encoder's order; reverse_dilations=True gives [1, 3]
    from intermask.vq.convolutions import MotionDecoder

    # a decoder built without the key (a run saved before the switch) keeps its old order
    old = MotionDecoder(num_joints=22, out_channels=12, width=16)
    assert [block.body[1].dilation[0] for block in old.net[2]] == [1, 3]
