"""FrozenCLIPTextEncoder on the tiny random tower: shapes, end-of-text, padding, freezing, errors."""

from __future__ import annotations

import os
import subprocess
import sys

import open_clip
import pytest
import torch

from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder

CAPTIONS = [
    "a person waves",
    "two people hug each other warmly and then step back",
    "",
]
EOT_TOKEN = 49407  # the largest id of CLIP's BPE vocabulary


def test_shapes_and_dtypes(tiny_encoder):
    features = tiny_encoder.encode(CAPTIONS)
    assert features.features.shape == (3, 77, 64) and features.features.dtype == torch.float32
    assert features.eot_index.shape == (3,) and features.eot_index.dtype == torch.int64
    assert features.padding_mask.shape == (3, 77) and features.padding_mask.dtype == torch.bool
    assert tiny_encoder.width == 64 and torch.isfinite(features.features).all()


def test_eot_index_and_padding_mask(tiny_encoder):
    long_caption = "walk " * 200  # truncated to 77 tokens; the last one becomes end-of-text
    captions = [*CAPTIONS, long_caption]
    ids = tiny_encoder.tokenize(captions)
    features = tiny_encoder.encode(captions)
    rows = torch.arange(len(captions))
    assert torch.equal(features.eot_index, ids.argmax(dim=-1))
    assert (ids[rows, features.eot_index] == EOT_TOKEN).all()
    assert features.eot_index.tolist()[2:] == [1, 76]  # empty caption: start, end
    for row, eot in enumerate(features.eot_index.tolist()):
        assert not features.padding_mask[row, : eot + 1].any()
        assert features.padding_mask[row, eot + 1 :].all()
        assert (ids[row, eot + 1 :] == 0).all()


def test_features_do_not_depend_on_the_batch(tiny_encoder):
    batch = tiny_encoder.encode(CAPTIONS)
    for row, caption in enumerate(CAPTIONS):
        alone = tiny_encoder.encode([caption])
        assert torch.equal(alone.features[0], batch.features[row])  # bitwise
        assert alone.eot_index.item() == batch.eot_index[row].item()


_BATCH_CHECK = """
import torch
from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder
encoder = FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=None, seed=0)
captions = [f"person {i} waves {i % 7} times and the other bows" for i in range(300)]
batch = encoder.encode(captions).features
alone = torch.cat([encoder.encode([c]).features for c in captions[::37]])
print(sum(not torch.equal(a, b) for a, b in zip(alone, batch[::37])), len(alone))
"""


def test_features_do_not_depend_on_the_batch_on_avx2_kernels():
    """On AVX2 kernels a batched matmul rounds a row by the batch's size: before each caption
    went through the tower alone, all 9 of these rows differed from the same captions encoded
    alone (in their last bits), so a shared cache served whatever an earlier job's batches gave."""
    env = os.environ | {
        "ATEN_CPU_CAPABILITY": "avx2",
        "MKL_ENABLE_INSTRUCTIONS": "AVX2",
        "ONEDNN_MAX_CPU_ISA": "AVX2",
    }
    done = subprocess.run(
        [sys.executable, "-c", _BATCH_CHECK], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-2:] == ["0", "9"]  # rows differing, rows compared


def test_tokens_are_open_clip_text_features_before_pooling(tiny_encoder):
    """tokens[eot] @ text_projection is exactly open_clip's pooled text embedding."""
    torch.manual_seed(0)  # the encoder builds its random tower under seed 0 as well
    clip = open_clip.create_model(TINY_MODEL_NAME).eval()
    features = tiny_encoder.encode(CAPTIONS)
    pooled = features.features[torch.arange(3), features.eot_index] @ clip.text_projection
    with torch.no_grad():
        expected = clip.encode_text(tiny_encoder.tokenize(CAPTIONS))
    torch.testing.assert_close(pooled, expected, rtol=1e-5, atol=1e-5)


def test_frozen_and_always_in_eval_mode(tiny_encoder):
    assert all(not p.requires_grad for p in tiny_encoder.parameters())
    assert tiny_encoder.train() is tiny_encoder
    assert not any(module.training for module in tiny_encoder.modules())
    with torch.enable_grad():
        features = tiny_encoder(CAPTIONS[:1])
    assert not features.features.requires_grad and features.features.grad_fn is None


def test_random_towers_are_seeded(tiny_encoder):
    same = FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, seed=0)
    other = FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, seed=1)
    assert same.identity == tiny_encoder.identity != other.identity
    assert "random(seed=0)" in tiny_encoder.identity and TINY_MODEL_NAME in tiny_encoder.identity
    torch.testing.assert_close(
        same.encode(CAPTIONS).features, tiny_encoder.encode(CAPTIONS).features
    )
    assert not torch.allclose(
        other.encode(CAPTIONS).features, tiny_encoder.encode(CAPTIONS).features
    )


def test_random_tower_is_announced(caplog):
    with caplog.at_level("WARNING", logger="intermask.text.clip_encoder"):
        FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME)
    assert "RANDOMLY INITIALISED" in caplog.text and "not CLIP features" in caplog.text


def test_loads_a_local_checkpoint(tmp_path, tiny_encoder):
    torch.manual_seed(5)
    clip = open_clip.create_model(TINY_MODEL_NAME)
    checkpoint = tmp_path / "tiny.pt"
    torch.save(clip.state_dict(), checkpoint)
    encoder = FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=str(checkpoint))
    assert (
        str(checkpoint.resolve()) in encoder.identity and encoder.identity != tiny_encoder.identity
    )
    torch.testing.assert_close(encoder.token_embedding.weight, clip.token_embedding.weight)
    assert not hasattr(encoder, "visual")


def test_missing_checkpoint_names_the_path(tmp_path):
    missing = tmp_path / "no_such_clip.pt"
    with pytest.raises(FileNotFoundError, match=str(missing)):
        FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=str(missing))


def test_corrupt_checkpoint_names_the_path(tmp_path):
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(b"not a checkpoint")
    with pytest.raises(RuntimeError, match=f"could not load the CLIP checkpoint {corrupt}"):
        FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=str(corrupt))


def test_failed_download_explains_the_offline_route(monkeypatch):
    def offline(*args, **kwargs):
        raise OSError("network is unreachable")

    # open_clip resolves the "openai" tag through this function before it builds the model, so
    # the test neither downloads nor allocates ViT-L
    monkeypatch.setattr(open_clip.factory, "download_pretrained", offline)
    with pytest.raises(RuntimeError, match="Offline.*text.encoder.pretrained=/path/to/"):
        FrozenCLIPTextEncoder(model_name="ViT-L-14-336", pretrained="openai")


def test_invalid_arguments():
    with pytest.raises(ValueError, match="unknown open_clip model_name 'no-such-model'"):
        FrozenCLIPTextEncoder(model_name="no-such-model")
    with pytest.raises(ValueError, match=r"context_length must be >= 2 .*got 1"):
        FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, context_length=1)


def test_invalid_captions(tiny_encoder):
    with pytest.raises(TypeError, match="single string"):
        tiny_encoder.encode("a person waves")
    with pytest.raises(ValueError, match="captions is empty"):
        tiny_encoder.encode([])
