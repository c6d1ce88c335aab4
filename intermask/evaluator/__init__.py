"""Contrastive text-motion evaluators: every protocol metric lives in their 512-d space.

* :class:`InterCLIP` - InterHuman (InterGen's evaluator): transformers over motion and CLIP
  token embeddings, L2-normalized embeddings x learnable ``latent_scale``.
* :class:`GRUMatcher` - Inter-X (T2M's matcher): convolutional movement encoder + BiGRU over
  motion, BiGRU over word vectors + POS one-hots; GloVe or a learned vocabulary.
* :class:`EvaluatorModule` - trains either (``make train-evaluator``).
* :func:`load_evaluator` - a :class:`FrozenEvaluator` from a train_evaluator run or a released
  file (``interclip.ckpt``, ``finest.tar``), with ``name`` and ``file_hash``.

Protocol API (frozen, eval mode, no gradients)::

    evaluator.encode_motion(motion, lengths)  # (B, 2, T, 262) or (B, 2, T, 56, 6) -> (B, 512)
    evaluator.encode_text(captions, tokens)   # B strings (+ Inter-X "word/POS ..." tokens) -> (B, 512)
"""

from intermask.evaluator.checkpoints import CheckpointMismatchError, KeyReport, file_hash
from intermask.evaluator.frozen import FrozenEvaluator
from intermask.evaluator.gru_matcher import GRUMatcher
from intermask.evaluator.interclip import InterCLIP
from intermask.evaluator.load import load_evaluator
from intermask.evaluator.module import EvaluatorModule

__all__ = [
    "CheckpointMismatchError",
    "EvaluatorModule",
    "FrozenEvaluator",
    "GRUMatcher",
    "InterCLIP",
    "KeyReport",
    "file_hash",
    "load_evaluator",
]
