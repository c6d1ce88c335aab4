"""EvaluatorModule pieces without a Trainer: options, schedule, de-normalization, vocabulary."""

from __future__ import annotations

from functools import partial
from types import SimpleNamespace

import pytest
import torch
from evaluator_builders import CAPTIONS, TOKENS, WORDS, interhuman_batch, tiny_gru, tiny_interclip

from intermask.data.normalization import Normalizer
from intermask.evaluator import EvaluatorModule, GRUMatcher
from intermask.evaluator.checkpoints import VOCABULARY_KEY

ADAM = partial(torch.optim.Adam, lr=0.1)


def test_loss_must_fit_the_network():
    with pytest.raises(
        ValueError,
        match="loss 'clip' needs the learnable latent_scale of InterCLIP, got GRUMatcher",
    ):
        EvaluatorModule(net=tiny_gru(), optimizer=ADAM, loss="clip", trained_on="x")
    with pytest.raises(ValueError, match="loss must be 'clip' or 'margin', got 'hinge'"):
        EvaluatorModule(net=tiny_gru(), optimizer=ADAM, loss="hinge", trained_on="x")


def test_schedule_and_frozen_embeddings_are_not_optimized():
    module = EvaluatorModule(
        net=tiny_interclip(),
        optimizer=ADAM,
        loss="clip",
        trained_on="x",
        warmup_fraction=0.4,
        lr_milestones=[0.8],
        lr_gamma=0.5,
    )
    module._trainer = SimpleNamespace(estimated_stepping_batches=10)
    config = module.configure_optimizers()
    optimizer, schedule = config["optimizer"], config["lr_scheduler"]["scheduler"]
    rates = []
    for _ in range(10):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        schedule.step()
    assert rates == pytest.approx([0.025, 0.05, 0.075, 0.1, 0.1, 0.1, 0.1, 0.1, 0.05, 0.05])
    optimized = {id(p) for group in optimizer.param_groups for p in group["params"]}
    assert id(module.net.token_embedding.weight) not in optimized
    assert id(module.net.latent_scale) in optimized


def test_batches_are_denormalized_before_encoding():
    module = EvaluatorModule(net=tiny_interclip(), optimizer=ADAM, loss="clip", trained_on="x")
    normalizer = Normalizer(torch.randn(262), torch.rand(262) + 0.5)
    module._normalizer = normalizer
    motion, lengths = interhuman_batch()
    batch = {"motion": normalizer.normalize(motion), "length": lengths, "caption": CAPTIONS}
    with torch.no_grad():
        text, embedded = module.embed(batch)
        expected = module.net.encode_motion(motion, lengths)
        loss = module.compute_loss(text, embedded)
    assert torch.allclose(embedded, expected, atol=1e-5) and loss.ndim == 0


def test_learned_vocabulary_comes_from_the_training_split_and_is_checked_on_resume():
    net = GRUMatcher(
        word_dim=8, movement_hidden=8, movement_latent=8, motion_hidden=8, text_hidden=8
    )
    module = EvaluatorModule(net=net, optimizer=ADAM, loss="margin", trained_on="x")
    caption = SimpleNamespace(tokens=" ".join(TOKENS))
    train = SimpleNamespace(captions=[[caption]])
    datamodule = SimpleNamespace(normalizer=None, datasets={"train": train})
    module._trainer = SimpleNamespace(datamodule=datamodule)
    module.setup("fit")
    assert net.vocabulary.words == [
        "sos",
        "eos",
        "unk",
        "hand",
        "hug",
        "jump",
        "left",
        "other",
        "person",
        "the",
        "wave",
    ]
    assert net.encode_text(CAPTIONS, TOKENS).shape == (3, 512)
    checkpoint = {}
    module.on_save_checkpoint(checkpoint)
    assert checkpoint[VOCABULARY_KEY] == net.vocabulary.words
    with pytest.raises(ValueError, match="refusing to replace it with a different one"):
        module.on_load_checkpoint({VOCABULARY_KEY: WORDS})
    interhuman_like = SimpleNamespace(
        datamodule=SimpleNamespace(
            normalizer=None, datasets={"train": SimpleNamespace(captions=[["a caption"]])}
        )
    )
    other = EvaluatorModule(
        net=GRUMatcher(word_dim=8), optimizer=ADAM, loss="margin", trained_on="x"
    )
    other._trainer = interhuman_like
    with pytest.raises(ValueError, match="the GRU matcher reads POS-tagged tokens"):
        other.setup("fit")
