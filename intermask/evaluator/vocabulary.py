"""Word vectors and part-of-speech classes for the T2M-style text encoder (Inter-X, HumanML3D).

Inter-X and HumanML3D captions come with lemmatized, POS-tagged tokens (``"word/POS word/POS
..."``; Inter-X's ``texts_processed`` files, HumanML3D's ``texts``; items carry them as
``"tokens"``). The T2M text encoder reads, per token, a 300-d word vector plus a 15-class POS
one-hot; words of five small "VIP" lists override the tagger's class (a direction word is
``Loc_VIP`` whatever its tag). Every caption becomes ``sos``, at most ``max_words`` tokens,
``eos``, padded with ``unk`` to ``max_words + 2``.

Word vectors come from one of two places:

* **GloVe** (comparable to published numbers): the files the reference evaluator reads,
  ``<glove_dir>/<prefix>_data.npy`` (V, 300) float, ``<prefix>_words.pkl`` (list of V words) and
  ``<prefix>_idx.pkl`` (dict word -> row). InterMask's Inter-X evaluator uses prefix ``hhi_vab``
  (HumanML3D's T2M uses ``our_vab``). Frozen.
* **learned**: a trainable embedding over the training split's words (plus ``sos``, ``eos``,
  ``unk``). Not comparable to published numbers; evaluators built this way say so in their name.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from intermask.utils.plain_pickle import UnsafePickle, load_plain_pickle

# T2M's POS classes, in one-hot order (text-to-motion word_vectorizer.py)
POS_CLASSES = (
    "VERB",
    "NOUN",
    "DET",
    "ADP",
    "NUM",
    "AUX",
    "PRON",
    "ADJ",
    "ADV",
    "Loc_VIP",
    "Body_VIP",
    "Obj_VIP",
    "Act_VIP",
    "Desc_VIP",
    "OTHER",
)
POS_INDEX = {name: i for i, name in enumerate(POS_CLASSES)}
# Words whose class overrides the tagger's (same source).
VIP_WORDS = {
    "Loc_VIP": (
        "left right clockwise counterclockwise anticlockwise forward back backward up down "
        "straight curve"
    ).split(),
    "Body_VIP": "arm chin foot feet face hand mouth leg waist eye knee shoulder thigh".split(),
    "Obj_VIP": "stair dumbbell chair window floor car ball handrail baseball basketball".split(),
    "Act_VIP": (
        "walk run swing pick bring kick put squat throw hop dance jump turn stumble stop sit lift "
        "lower raise wash stand kneel stroll rub bend balance flap jog shuffle lean rotate spin "
        "spread climb"
    ).split(),
    "Desc_VIP": (
        "slowly carefully fast careful slow quickly happy angry sad happily angrily sadly"
    ).split(),
}
VIP_CLASS = {word: cls for cls, words in VIP_WORDS.items() for word in words}
START, END, UNKNOWN = "sos", "eos", "unk"
SPECIAL_WORDS = (START, END, UNKNOWN)
DEFAULT_MAX_WORDS = 20  # max_text_len of T2M and MoMask (HumanML3D)
INTERX_MAX_WORDS = 35  # max_text_len InterMask's eval.py sets for Inter-X
DEFAULT_GLOVE_PREFIX = "hhi_vab"  # InterMask's Inter-X vocabulary
HUMANML3D_GLOVE_PREFIX = "our_vab"  # T2M's HumanML3D vocabulary


class EncodedTokens(NamedTuple):
    word_ids: torch.Tensor  # (B, max_words + 2) int64 rows of the word-vector table
    pos_one_hot: torch.Tensor  # (B, max_words + 2, 15) float
    lengths: torch.Tensor  # (B,) int64 tokens incl. sos/eos (the GRU's sequence lengths)


def split_token(token: str) -> tuple[str, str]:
    """``"word/POS"`` -> (word, POS); the word may itself contain a slash."""
    word, sep, pos = token.rpartition("/")
    if not sep or not word:
        raise ValueError(f"malformed token {token!r}: expected 'word/POS'")
    return word, pos


def pos_class(word: str, pos: str) -> int:
    """Index of the POS one-hot: a VIP class when the word is listed, else the tag or OTHER."""
    return POS_INDEX[VIP_CLASS.get(word, pos if pos in POS_INDEX else "OTHER")]


class Vocabulary:
    """Words -> rows of a word-vector table; unknown words map to ``unk``."""

    def __init__(self, words: Sequence[str]) -> None:
        words = list(words)
        missing = [w for w in SPECIAL_WORDS if w not in words]
        if missing:
            raise ValueError(f"a vocabulary must contain {SPECIAL_WORDS}; missing {missing}")
        if len(set(words)) != len(words):
            duplicates = sorted(w for w, n in Counter(words).items() if n > 1)
            raise ValueError(f"duplicate words in the vocabulary: {duplicates[:10]}")
        self.words = words
        self.index = {w: i for i, w in enumerate(words)}

    def __len__(self) -> int:
        return len(self.words)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Vocabulary) and self.words == other.words

    @classmethod
    def from_token_strings(cls, token_strings: Iterable[str], *, min_count: int = 1) -> Vocabulary:
        """Sorted words seen at least ``min_count`` times in ``"word/POS ..."`` strings, plus
        the special words first (deterministic: the same split gives the same vocabulary)."""
        counts: Counter[str] = Counter()
        for text in token_strings:
            counts.update(split_token(t)[0] for t in text.split())
        seen = sorted(w for w, n in counts.items() if n >= min_count and w not in SPECIAL_WORDS)
        if not seen:
            raise ValueError("no words found in the token strings: cannot build a vocabulary")
        return cls([*SPECIAL_WORDS, *seen])

    def encode(self, token_strings: Sequence[str], *, max_words: int) -> EncodedTokens:
        """B ``"word/POS ..."`` strings -> EncodedTokens (``sos`` + <= max_words + ``eos``,
        ``unk`` padding; longer captions keep their first ``max_words`` tokens)."""
        if isinstance(token_strings, str):
            raise TypeError("tokens must be a sequence of 'word/POS ...' strings, one per caption")
        length = max_words + 2
        ids = torch.full((len(token_strings), length), self.index[UNKNOWN], dtype=torch.int64)
        pos = torch.zeros(len(token_strings), length, len(POS_CLASSES))
        pos[:, :, POS_INDEX["OTHER"]] = 1.0  # sos/eos/unk padding are OTHER
        lengths = torch.zeros(len(token_strings), dtype=torch.int64)
        for row, text in enumerate(token_strings):
            parsed = [split_token(t) for t in text.split()][:max_words]
            if not parsed:
                raise ValueError(f"tokens[{row}] is empty: expected 'word/POS ...'")
            ids[row, 0] = self.index[START]
            for col, (word, tag) in enumerate(parsed, start=1):
                # the reference maps a word missing from GloVe to unk/OTHER, whatever its tag
                if word in self.index:
                    ids[row, col] = self.index[word]
                    pos[row, col].zero_()
                    pos[row, col, pos_class(word, tag)] = 1.0
            ids[row, len(parsed) + 1] = self.index[END]
            lengths[row] = len(parsed) + 2
        return EncodedTokens(ids, pos, lengths)


def _load_pickle(path: Path):
    if not path.is_file():
        raise FileNotFoundError(f"{path}: GloVe file not found")
    try:
        return load_plain_pickle(path)
    except (UnsafePickle, ValueError) as error:  # the message names the file
        raise ValueError(f"not a plain pickled list/dict: {error}") from error


def load_glove(
    glove_dir: str | Path, prefix: str = DEFAULT_GLOVE_PREFIX
) -> tuple[Vocabulary, torch.Tensor]:
    """The reference word-vector files -> (Vocabulary, (V, 300) float32 vectors in its order)."""
    glove_dir = Path(glove_dir)
    data_path = glove_dir / f"{prefix}_data.npy"
    if not data_path.is_file():
        raise FileNotFoundError(
            f"{data_path}: GloVe vectors not found (expected {prefix}_data.npy, "
            f"{prefix}_words.pkl and {prefix}_idx.pkl in {glove_dir})"
        )
    vectors = np.load(data_path, allow_pickle=False)
    words = _load_pickle(glove_dir / f"{prefix}_words.pkl")
    index = _load_pickle(glove_dir / f"{prefix}_idx.pkl")
    if vectors.ndim != 2:
        raise ValueError(f"{data_path}: expected a (V, D) array, got shape {vectors.shape}")
    if not isinstance(words, list) or not isinstance(index, dict):
        raise ValueError(
            f"{glove_dir}: {prefix}_words.pkl must hold a list, {prefix}_idx.pkl a dict"
        )
    missing = [w for w in words if w not in index]
    if missing:
        raise ValueError(f"{glove_dir}/{prefix}_idx.pkl: no row for words {missing[:5]}")
    rows = [int(index[w]) for w in words]
    if max(rows) >= len(vectors):
        raise ValueError(
            f"{data_path}: {len(vectors)} rows, but {prefix}_idx.pkl points to row {max(rows)}"
        )
    vocabulary = Vocabulary([str(w) for w in words])
    return vocabulary, torch.from_numpy(np.asarray(vectors[rows], dtype=np.float32))
