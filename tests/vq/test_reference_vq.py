"""The reference release's VQ-VAE keys land on ours (Inter-X, whose release uses convolutions
throughout); the InterHuman release's graph layers are reported by name. The key names and
shapes are the reference ``RVQVAE``'s module tree, written out as data."""

from __future__ import annotations

import pytest
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


def reference_interhuman_layout() -> dict[str, tuple[int, ...]]:
    """The InterHuman release: graph layers at both ends, the encoder's stages from index 0."""
    keys = {
        "encoder.model.2.weight": (W, W, 3, 3),
        "encoder.model.2.bias": (W,),
        "decoder.model.0.weight": (W, W, 3, 3),
        "decoder.model.0.bias": (W,),
        "decoder.model.4.weight": (W, W, 3, 3),
        "decoder.model.4.bias": (W,),
        "quantizer.layers.0.codebook": (1024, W),
    }
    for end, (first, last) in {"encoder": (12, W), "decoder": (W, 12)}.items():
        for layer, (n_in, n_out) in {1: (first, W), 2: (W, last)}.items():
            prefix = f"{end}.gcn_layer{layer}"
            keys |= {
                f"{prefix}.lin.weight": (n_in, n_in),
                f"{prefix}.lin.bias": (n_in,),
                f"{prefix}.lin_l.weight": (n_out, n_in),
                f"{prefix}.lin_l.bias": (n_out,),
                f"{prefix}.lin_r.weight": (n_out, n_in),
            }
    for stage in (0, 1):
        keys[f"encoder.model.{stage}.0.weight"] = (W, W, 4, 4)
        keys[f"encoder.model.{stage}.0.bias"] = (W,)
        keys |= _resnet(f"encoder.model.{stage}.1")
    for stage in (2, 3):
        keys |= _resnet(f"decoder.model.{stage}.0")
        keys[f"decoder.model.{stage}.2.weight"] = (W, W, 3, 3)
        keys[f"decoder.model.{stage}.2.bias"] = (W,)
    return keys


def test_the_interhuman_graph_release_lands_on_graph_ends():
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "train_vq", overrides=["data=interhuman", "model.net.encoder.ends=graph_first_frame"]
        )
    with torch.device("meta"):
        ours = instantiate(cfg.model.net).state_dict()
        reference = {k: torch.empty(s) for k, s in reference_interhuman_layout().items()}
    conversion = convert_reference_vq(reference, ours)
    assert conversion.unmapped == [] and conversion.mismatched == []
    # the statistics are the dataset's (the release's global_mean/std.npy), not weights
    assert conversion.missing == ["view.has_statistics", "view.mean", "view.std"]


def test_the_graph_layer_is_graphsage_and_the_reference_aggregates_one_frame():
    from intermask.vq.convolutions import SkeletonGraphLayer

    torch.manual_seed(0)
    every = SkeletonGraphLayer(3, 4, frames="all")
    first = SkeletonGraphLayer(3, 4, frames="batch_first")
    first.load_state_dict(every.state_dict())
    x = torch.randn(2, 3, 22, 5)  # (B, C, J, T)
    nodes = x.permute(0, 3, 2, 1)
    # joint 4 (left knee) neighbours the left hip 1 and the left ankle 7
    projected = torch.relu(every.lin(nodes))
    mean = (projected[..., 1, :] + projected[..., 7, :]) / 2
    expected = every.lin_l(mean) + every.lin_r(nodes[..., 4, :])  # (B, T, 4)
    torch.testing.assert_close(every(x)[:, :, 4, :].permute(0, 2, 1), expected)
    out = first(x).permute(0, 3, 2, 1)  # (B, T, J, 4)
    torch.testing.assert_close(out[0, 0, 4], expected[0, 0])  # sample 0, frame 0 aggregates
    alone = every.lin_l.bias + every.lin_r(nodes)  # every other node: no neighbours
    torch.testing.assert_close(out[1], alone[1])
    torch.testing.assert_close(out[0, 1:], alone[0, 1:])
    # "first": frame 0 of every sequence, what the reference gives each sequence passed alone
    each = SkeletonGraphLayer(3, 4, frames="first")
    each.load_state_dict(every.state_dict())
    out = each(x).permute(0, 3, 2, 1)
    for sample in (0, 1):
        alone_call = first(x[sample : sample + 1]).permute(0, 3, 2, 1)[0]
        torch.testing.assert_close(out[sample], alone_call, rtol=0, atol=1e-6)
        torch.testing.assert_close(out[sample, 0, 4], expected[sample, 0])
        torch.testing.assert_close(out[sample, 1:], alone[sample, 1:])
    with pytest.raises(ValueError, match="frames must be 'all', 'first' or 'batch_first', got 'x'"):
        SkeletonGraphLayer(3, 4, frames="x")


def test_the_decoder_keeps_the_encoders_dilation_order_as_the_reference_does():
    decoder = _ours("interhuman").decoder
    dilations = [block.body[1].dilation[0] for block in decoder.net[2]]
    assert dilations == [3, 1]  # the encoder's order; reverse_dilations=True gives [1, 3]
    from intermask.vq.convolutions import MotionDecoder

    # a decoder built without the key (a run saved before the switch) keeps its old order
    old = MotionDecoder(num_joints=22, out_channels=12, width=16)
    assert [block.body[1].dilation[0] for block in old.net[2]] == [1, 3]
