"""Tokens -> word ids + POS one-hots (T2M conventions); GloVe files; the safe word-list loader."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch
from evaluator_builders import WORDS

from intermask.evaluator.vocabulary import POS_CLASSES, POS_INDEX, Vocabulary, load_glove


def test_encode_adds_sos_eos_and_unk_padding():
    vocabulary = Vocabulary(WORDS)
    encoded = vocabulary.encode(["the/DET person/NOUN wave/VERB left/ADJ", "hug/VERB"], max_words=5)
    index = vocabulary.index
    assert encoded.word_ids.shape == (2, 7) and encoded.pos_one_hot.shape == (2, 7, 15)
    assert encoded.word_ids[0].tolist() == [
        index[w] for w in ["sos", "the", "person", "wave", "left", "eos", "unk"]
    ]
    assert encoded.lengths.tolist() == [6, 3]
    classes = encoded.pos_one_hot.argmax(-1)
    # wave is tagged VERB but not an Act_VIP word; left overrides its tag with Loc_VIP
    assert [POS_CLASSES[i] for i in classes[0].tolist()] == [
        "OTHER",
        "DET",
        "NOUN",
        "VERB",
        "Loc_VIP",
        "OTHER",
        "OTHER",
    ]
    assert torch.equal(encoded.pos_one_hot.sum(-1), torch.ones(2, 7))


def test_unknown_words_become_unk_other_and_long_captions_are_cropped():
    vocabulary = Vocabulary(WORDS)
    encoded = vocabulary.encode(["zebra/NOUN the/DET " * 10], max_words=3)
    assert encoded.word_ids[0].tolist() == [0, 2, 7, 2, 1]  # sos unk the unk eos
    assert encoded.pos_one_hot[0, 1].argmax() == POS_INDEX["OTHER"]
    assert encoded.lengths.tolist() == [5]


def test_vocabulary_from_token_strings_is_sorted_and_counts():
    vocabulary = Vocabulary.from_token_strings(["b/NOUN a/DET", "a/DET c/VERB"], min_count=2)
    assert vocabulary.words == ["sos", "eos", "unk", "a"]
    assert Vocabulary.from_token_strings(["b/X a/Y"]).words == ["sos", "eos", "unk", "a", "b"]
    with pytest.raises(ValueError, match="malformed token 'walk': expected 'word/POS'"):
        Vocabulary.from_token_strings(["walk"])
    with pytest.raises(ValueError, match=r"missing \['unk'\]"):
        Vocabulary(["sos", "eos"])
    with pytest.raises(ValueError, match=r"tokens\[0\] is empty"):
        Vocabulary(WORDS).encode([""], max_words=4)


def _write_glove(folder, words, vectors, prefix="hhi_vab"):
    np.save(folder / f"{prefix}_data.npy", vectors)
    (folder / f"{prefix}_words.pkl").write_bytes(pickle.dumps(words))
    rows = {w: len(words) - 1 - i for i, w in enumerate(words)}  # rows in reverse order
    (folder / f"{prefix}_idx.pkl").write_bytes(pickle.dumps(rows))


def test_load_glove_orders_vectors_like_the_words(tmp_path):
    vectors = np.arange(5 * 3, dtype=np.float32).reshape(5, 3)
    _write_glove(tmp_path, ["sos", "eos", "unk", "walk", "run"], vectors)
    vocabulary, table = load_glove(tmp_path)
    assert vocabulary.words == ["sos", "eos", "unk", "walk", "run"]
    assert torch.equal(table[3], torch.from_numpy(vectors[1]))  # walk -> row 5 - 1 - 3


def test_load_glove_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"hhi_vab_data.npy: GloVe vectors not found"):
        load_glove(tmp_path)
    _write_glove(tmp_path, ["sos", "eos", "unk"], np.zeros((3, 2), dtype=np.float32))

    class Evil:
        def __reduce__(self):
            return (print, ("owned",))

    (tmp_path / "hhi_vab_words.pkl").write_bytes(pickle.dumps(Evil()))
    with pytest.raises(ValueError, match="refusing to load builtins.print"):
        load_glove(tmp_path)
