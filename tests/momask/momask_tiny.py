"""Tiny MoMask pieces for the tests: a 1D-token residual VQ-VAE over 263-d features, networks,
batches."""

from __future__ import annotations

from pathlib import Path

import torch
import yaml

from intermask.momask.model import MaskedTransformer, ResidualTransformer
from intermask.vq.convolutions import MotionDecoder, MotionEncoder
from intermask.vq.model import MotionVQVAE
from intermask.vq.quantizers import ResidualQuantizer
from intermask.vq.views import HumanML3DView

FEATURES = 263  # HumanML3D's feature vector
CODES = 16
LAYERS = 3
TINY = {
    "code_dim": 16,
    "width": 32,
    "depth": 1,
    "heads": 2,
    "ff": 64,
    "dropout": 0.0,
    "max_steps": 64,
}
CAPTIONS = ["a person walks forward", "someone jumps twice", "a man waves", "she sits down"]


def make_vq(layers: int = LAYERS, codes: int = CODES, seed: int = 0) -> MotionVQVAE:
    torch.manual_seed(seed)
    vq = MotionVQVAE(
        view=HumanML3DView(mean=torch.zeros(FEATURES), std=torch.ones(FEATURES)),
        encoder=MotionEncoder(num_joints=1, in_channels=FEATURES, width=16, layout="1d"),
        quantizer=ResidualQuantizer(num_quantizers=layers, codebook_size=codes, dim=16),
        decoder=MotionDecoder(num_joints=1, out_channels=FEATURES, width=16, layout="1d"),
    )
    vq.train()(torch.randn(4, 64, FEATURES))  # initialise the codebooks from data
    return vq.eval()


def make_mask_net(seed: int = 1, **overrides: object) -> MaskedTransformer:
    torch.manual_seed(seed)
    return MaskedTransformer(**{"codebook_size": CODES, "text_dim": 64, **TINY, **overrides})


def make_residual_net(seed: int = 2, **overrides: object) -> ResidualTransformer:
    torch.manual_seed(seed)
    config = {"codebook_size": CODES, "num_quantizers": LAYERS, "text_dim": 64, **TINY}
    return ResidualTransformer(**{**config, **overrides})


def make_batch(lengths=(64, 40, 30, 16), seed: int = 3) -> dict:
    generator = torch.Generator().manual_seed(seed)
    return {
        "motion": torch.randn(len(lengths), 64, FEATURES, generator=generator),
        "length": torch.tensor(lengths),
        "caption": CAPTIONS[: len(lengths)],
    }


TEXT = {  # configs/text/tiny_random.yaml without the disk cache
    "_target_": "intermask.text.cache.TextFeatureCache",
    "encoder": {
        "_target_": "intermask.text.clip_encoder.FrozenCLIPTextEncoder",
        "model_name": "intermask-tiny-text",
        "pretrained": None,
        "context_length": 77,
        "quick_gelu": None,
        "seed": 0,
    },
    "cache_dir": None,
}
VQ_NET = {  # configs/model/vq/humanml3d.yaml at test size
    "_target_": "intermask.vq.model.MotionVQVAE",
    "view": {"_target_": "intermask.vq.views.HumanML3DView"},
    "encoder": {
        "_target_": "intermask.vq.convolutions.MotionEncoder",
        "num_joints": 1,
        "in_channels": FEATURES,
        "width": 16,
        "layout": "1d",
    },
    "quantizer": {
        "_target_": "intermask.vq.quantizers.ResidualQuantizer",
        "num_quantizers": LAYERS,
        "codebook_size": CODES,
        "dim": 16,
    },
    "decoder": {
        "_target_": "intermask.vq.convolutions.MotionDecoder",
        "num_joints": 1,
        "out_channels": FEATURES,
        "width": 16,
        "layout": "1d",
    },
}


def save_run(run: Path, config: dict, state: dict[str, torch.Tensor], **hyper: object) -> Path:
    """A run folder as training leaves it: config.yaml and checkpoints/last.ckpt."""
    (run / "checkpoints").mkdir(parents=True)
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    payload = {"state_dict": {f"net.{k}": v for k, v in state.items()}, "hyper_parameters": hyper}
    torch.save(payload, run / "checkpoints" / "last.ckpt")
    return run
