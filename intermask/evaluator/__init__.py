"""Contrastive text-motion evaluators: every protocol metric lives in their 512-d space.

* :class:`InterCLIP` - InterHuman (InterGen's evaluator): transformers over motion and CLIP
  token embeddings, L2-normalized embeddings x learnable ``latent_scale``.
* :class:`GRUMatcher` - Inter-X (T2M's matcher): convolutional movement encoder + BiGRU over
  motion, BiGRU over word vectors + POS one-hots; GloVe or a learned vocabulary.
* :class:`HumanML3DMatcher` - HumanML3D (T2M's ``text_mot_match``, MoMask's evaluator): the same
  network over the 263-d feature, z-scored with the evaluator's own statistics.
* :class:`EvaluatorModule` - trains any of them (``make train-evaluator``).
* :func:`load_evaluator` - a :class:`FrozenEvaluator` from a train_evaluator run or a released
  file (``interclip.ckpt``, ``finest.tar`` [+ ``meta/``]), with ``name`` and ``file_hash``.

Protocol API (frozen, eval mode, no gradients)::

    evaluator.encode_motion(motion, lengths)  # -> (B, 512); motion (B, 2, T, 262) InterHuman,
                                              # (B, 2, T, 56, 6) Inter-X, (B, T, 263) HumanML3D
    evaluator.encode_text(captions, tokens)   # B strings (+ T2M "word/POS ..." tokens) -> (B, 512)
"""

from intermask.evaluator.checkpoints import CheckpointMismatchError, KeyReport, file_hash
from intermask.evaluator.frozen import FrozenEvaluator
from intermask.evaluator.gru_matcher import GRUMatcher, T2MMatcher
from intermask.evaluator.humanml3d_matcher import HumanML3DMatcher
from intermask.evaluator.interclip import InterCLIP
from intermask.evaluator.load import load_evaluator
from intermask.evaluator.module import EvaluatorModule

__all__ = [
    "CheckpointMismatchError",
    "EvaluatorModule",
    "FrozenEvaluator",
    "GRUMatcher",
    "HumanML3DMatcher",
    "InterCLIP",
    "KeyReport",
    "T2MMatcher",
    "file_hash",
    "load_evaluator",
]
