"""Rebuilding MoMask's transformers from train_gen run folders, and the sampler over them."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from intermask.momask.load import load_momask, load_momask_sampler
from intermask.utils.fingerprint import weights_digest
from tests.momask.momask_tiny import (
    CAPTIONS,
    CODES,
    FEATURES,
    LAYERS,
    TEXT,
    TINY,
    VQ_NET,
    make_mask_net,
    make_residual_net,
    make_vq,
    save_run,
)


def _vq_run(folder: Path):
    vq = make_vq()
    return vq, save_run(folder, {"model": {"net": VQ_NET}}, vq.state_dict())


def _transformer_run(folder: Path, net, target: str, vq, vq_folder: Path, **hyper) -> Path:
    config = {
        "model": {"net": {"_target_": target, "_partial_": True, **TINY}},
        "text": TEXT,
        "vq_ckpt": str(vq_folder / "checkpoints" / "last.ckpt"),
    }
    hyper_parameters = {
        "codebook_size": CODES,
        "text_dim": 64,
        "vq_digest": weights_digest(vq),
        **hyper,
    }
    return save_run(folder, config, net.state_dict(), **hyper_parameters)


@pytest.fixture
def runs(tmp_path):
    vq, vq_folder = _vq_run(tmp_path / "vq")
    mask_net, residual_net = make_mask_net(), make_residual_net()
    mask = _transformer_run(
        tmp_path / "mask", mask_net, "intermask.momask.model.MaskedTransformer", vq, vq_folder
    )
    residual = _transformer_run(
        tmp_path / "residual",
        residual_net,
        "intermask.momask.model.ResidualTransformer",
        vq,
        vq_folder,
        num_quantizers=LAYERS,
    )
    return {"vq": vq, "mask": mask, "residual": residual, "nets": (mask_net, residual_net)}


def test_runs_rebuild_the_trained_networks_and_their_tokenizer(runs):
    mask = load_momask(runs["mask"])
    for name, tensor in runs["nets"][0].state_dict().items():
        torch.testing.assert_close(mask.net.state_dict()[name], tensor, rtol=0, atol=0)
    assert weights_digest(mask.vq) == weights_digest(runs["vq"])
    residual = load_momask(runs["residual"], vq=mask.vq)
    assert residual.vq is mask.vq and residual.net.num_quantizers == LAYERS


def test_the_sampler_chains_both_and_is_reproducible(runs):
    sampler, paths = load_momask_sampler(runs["mask"], runs["residual"])
    assert set(paths) == {"mask", "residual", "vq"}
    lengths = torch.tensor([64, 40])
    first = sampler(CAPTIONS[:2], lengths, generator=torch.Generator().manual_seed(5))
    again = sampler(CAPTIONS[:2], lengths, generator=torch.Generator().manual_seed(5))
    assert torch.equal(first.tokens, again.tokens) and first.features.shape == (2, 64, FEATURES)
    assert bool((first.tokens[1, :, 0, 10:] == -1).all())  # 40 frames = 10 steps
    assert bool((first.tokens[:, :, 0, :10] >= 0).all())  # every layer decoded
    base, _ = load_momask_sampler(runs["mask"])
    alone = base(CAPTIONS[:2], lengths, generator=torch.Generator().manual_seed(5))
    assert torch.equal(alone.tokens[:, 0], first.tokens[:, 0])  # the same base layer
    assert bool((alone.tokens[:, 1:] == -1).all())


def test_wrong_runs_and_tokenizers_are_refused(runs, tmp_path):
    with pytest.raises(ValueError, match="holds a ResidualTransformer, not the masked transformer"):
        load_momask_sampler(runs["residual"])
    with pytest.raises(ValueError, match="holds a MaskedTransformer, not the residual transformer"):
        load_momask_sampler(runs["mask"], runs["mask"])
    other, other_folder = _vq_run(tmp_path / "other")
    for parameter in other.parameters():
        parameter.data.add_(0.5)
    torch.save(
        {
            "state_dict": {f"net.{k}": v for k, v in other.state_dict().items()},
            "hyper_parameters": {},
        },
        other_folder / "checkpoints" / "last.ckpt",
    )
    with pytest.raises(ValueError, match="not the VQ-VAE .* was trained on"):
        load_momask(runs["mask"], vq_checkpoint=other_folder / "checkpoints" / "last.ckpt")


def test_per_sample_generators_make_a_sample_independent_of_its_batch(runs):
    sampler, _ = load_momask_sampler(runs["mask"], runs["residual"])

    def generators(*seeds):
        return [torch.Generator().manual_seed(seed) for seed in seeds]

    pair = sampler(CAPTIONS[:2], torch.tensor([64, 40]), generator=generators(11, 12))
    alone = sampler(CAPTIONS[1:2], torch.tensor([40]), generator=generators(12))
    torch.testing.assert_close(pair.tokens[1:, :, :, :10], alone.tokens)
    with pytest.raises(ValueError, match="got 1 generators for 2 samples"):
        sampler(CAPTIONS[:2], torch.tensor([64, 40]), generator=generators(11))
