"""Released layouts (constructed in their on-disk form), key reports, file identity."""

from __future__ import annotations

import hashlib
import logging
import pickle

import numpy as np
import pytest
import torch
from evaluator_builders import (
    CAPTIONS,
    TINY_GRU,
    TOKENS,
    WORDS,
    interhuman_batch,
    interx_batch,
    tiny_gru,
    tiny_interclip,
)

from intermask.evaluator import CheckpointMismatchError, file_hash, load_evaluator


def _interclip_file(path, state):
    """InterGen's interclip.ckpt layout: a Lightning checkpoint, keys prefixed with 'model.'."""
    torch.save(
        {"epoch": 7, "global_step": 900, "state_dict": {f"model.{k}": v for k, v in state.items()}},
        path,
    )


def test_released_interclip_loads_and_is_named(tmp_path):
    source = tiny_interclip(seed=1)
    path = tmp_path / "interclip.ckpt"
    _interclip_file(path, source.state_dict())
    evaluator = load_evaluator(path, net=tiny_interclip(seed=2))
    assert evaluator.name == "interclip[released]"
    assert evaluator.file_hash == hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    motion, lengths = interhuman_batch()
    with torch.no_grad():
        assert torch.allclose(
            evaluator.encode_motion(motion, lengths), source.encode_motion(motion, lengths)
        )
        assert torch.allclose(evaluator.encode_text(CAPTIONS), source.encode_text(CAPTIONS))


def test_released_interclip_mismatches_are_listed(tmp_path, caplog):
    state = tiny_interclip(seed=1).state_dict()
    state["motion_encoder.query_tokens"] = state.pop("motion_encoder.query_token")  # wrong name
    state["out.weight"] = torch.zeros(512, 7)  # wrong shape
    del state["text_ln.bias"]
    path = tmp_path / "interclip.ckpt"
    _interclip_file(path, state)
    with pytest.raises(CheckpointMismatchError) as error:
        load_evaluator(path, net=tiny_interclip())
    message = str(error.value)
    assert "missing (2): motion_encoder.query_token, text_ln.bias" in message
    assert "unexpected (1): motion_encoder.query_tokens" in message
    assert "shape mismatch (1): out.weight file [512, 7] vs model [512, 64]" in message
    net = tiny_interclip(seed=3)
    kept = net.motion_encoder.query_token.detach().clone()
    with caplog.at_level(logging.WARNING, logger="intermask.evaluator.checkpoints"):
        evaluator = load_evaluator(path, net=net, strict=False)
    assert "strict=False: loading the" in caplog.text and "unexpected (1)" in caplog.text
    assert torch.equal(evaluator.net.motion_encoder.query_token, kept)  # not in the file: untouched
    assert torch.equal(
        evaluator.net.motion_encoder.embed_motion.weight,
        state["motion_encoder.embed_motion.weight"],
    )


def _glove(folder, dim):
    vectors = np.random.default_rng(0).normal(size=(len(WORDS), dim)).astype(np.float32)
    np.save(folder / "hhi_vab_data.npy", vectors)
    (folder / "hhi_vab_words.pkl").write_bytes(pickle.dumps(WORDS))
    (folder / "hhi_vab_idx.pkl").write_bytes(pickle.dumps({w: i for i, w in enumerate(WORDS)}))
    return vectors


def _finest_tar(path, net, *, text_state=None):
    """T2M's finest.tar layout: one state dict per part, plus optimizer state and epoch."""
    parts = {
        name: getattr(net, name).state_dict()
        for name in ("movement_encoder", "text_encoder", "motion_encoder")
    }
    if text_state is not None:
        parts["text_encoder"] = text_state
    torch.save(
        {**parts, "opt_encoder": {"state": {}, "param_groups": []}, "epoch": 120, "iter": 5}, path
    )


def test_released_t2m_loads_with_glove(tmp_path):
    vectors = _glove(tmp_path, dim=12)
    source = tiny_gru(seed=1)
    path = tmp_path / "finest.tar"
    _finest_tar(path, source)
    from intermask.evaluator import GRUMatcher

    net = GRUMatcher(
        word_vectors="glove", glove_dir=str(tmp_path), rot6d_input="pytorch3d", **TINY_GRU
    )
    evaluator = load_evaluator(path, net=net)
    assert evaluator.name == "t2m_gru+glove[released]" and evaluator.dataset == "interx"
    assert torch.equal(evaluator.net.word_embedding.weight, torch.from_numpy(vectors))
    assert not evaluator.net.word_embedding.weight.requires_grad
    source.word_embedding.weight.data.copy_(torch.from_numpy(vectors))
    source.rot6d_input = "pytorch3d"
    motion, lengths = interx_batch()
    with torch.no_grad():
        assert torch.allclose(
            evaluator.encode_text(CAPTIONS, TOKENS), source.encode_text(CAPTIONS, TOKENS), atol=1e-6
        )
        assert torch.allclose(
            evaluator.encode_motion(motion, lengths),
            source.encode_motion(motion, lengths),
            atol=1e-6,
        )


def test_released_t2m_reports_a_wrong_key_and_needs_glove(tmp_path):
    source = tiny_gru(seed=1)
    text_state = source.text_encoder.state_dict()
    text_state["pos_embed.weight"] = text_state.pop("pos_emb.weight")
    path = tmp_path / "finest.tar"
    _finest_tar(path, source, text_state=text_state)
    with pytest.raises(
        CheckpointMismatchError,
        match=r"missing \(1\): text_encoder.pos_emb.weight; unexpected \(1\): text_encoder.pos_embed.weight",
    ):
        load_evaluator(path, net=tiny_gru())
    with pytest.raises(ValueError, match="pass glove_dir=<folder with hhi_vab_data.npy"):
        load_evaluator(path)


def test_unknown_files_and_pickled_objects_are_refused(tmp_path):
    path = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(2)}, path)
    with pytest.raises(
        ValueError, match=r"not an evaluator checkpoint.*top-level keys \['weights'\]"
    ):
        load_evaluator(path)
    with pytest.raises(FileNotFoundError, match="nowhere.ckpt: evaluator checkpoint not found"):
        load_evaluator(tmp_path / "nowhere.ckpt")
    pickled = tmp_path / "pickled.ckpt"
    state = {f"model.{k}": v for k, v in tiny_interclip().state_dict().items()}
    torch.save({"state_dict": state, "hyper_parameters": {"cfg": _Config()}}, pickled)
    with pytest.raises(ValueError, match="does not load with weights_only=True.*trusted=True"):
        load_evaluator(pickled, net=tiny_interclip())
    assert load_evaluator(pickled, net=tiny_interclip(), trusted=True).name == "interclip[released]"


class _Config:
    """Stands for the config objects old Lightning checkpoints pickle into hyper_parameters."""


def test_file_hash_is_the_sha256_prefix(tmp_path):
    path = tmp_path / "blob.bin"
    path.write_bytes(b"x" * (3 << 20))
    assert file_hash(path) == hashlib.sha256(b"x" * (3 << 20)).hexdigest()[:16]
