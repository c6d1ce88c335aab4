"""The frozen protocol wrapper: eval mode for good, no gradients, deterministic outputs."""

from __future__ import annotations

import pytest
import torch
from evaluator_builders import CAPTIONS, interhuman_batch, tiny_interclip

from intermask.evaluator import FrozenEvaluator


def test_frozen_evaluator_never_trains():
    evaluator = FrozenEvaluator(
        tiny_interclip(dropout=0.5), name="interclip[test]", file_hash="0" * 16
    )
    evaluator.train()
    assert not evaluator.training and not any(m.training for m in evaluator.modules())
    assert not any(p.requires_grad for p in evaluator.parameters())
    with pytest.raises(RuntimeError, match=r"interclip\[test\] is a frozen evaluator"):
        evaluator.requires_grad_(True)
    motion, lengths = interhuman_batch()
    motion.requires_grad_(True)
    first = evaluator.encode_motion(motion, lengths)
    assert not first.requires_grad and torch.equal(first, evaluator.encode_motion(motion, lengths))
    text = evaluator.encode_text(CAPTIONS)
    assert text.shape == (3, 512) and text.dtype == torch.float32 and not text.requires_grad
    assert evaluator.dataset == "interhuman" and evaluator.embed_dim == 512
