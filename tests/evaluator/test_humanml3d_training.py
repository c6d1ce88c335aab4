"""Training the HumanML3D matcher with EvaluatorModule: the composed config, statistics and words
from the datamodule, a short fit, and the checkpoint loaded back frozen."""

from __future__ import annotations

from functools import partial
from types import SimpleNamespace

import lightning as L
import pytest
import torch
from evaluator_builders import CAPTIONS, TOKENS, humanml3d_batch, humanml3d_statistics
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf
from torch.utils.data import DataLoader

from intermask.data.normalization import Normalizer
from intermask.evaluator import EvaluatorModule, HumanML3DMatcher, load_evaluator
from intermask.evaluator.checkpoints import VOCABULARY_KEY
from intermask.train import CONFIG_DIR
from intermask.utils import run_config

TINY = [
    "model.net.word_dim=8",
    "model.net.movement_hidden=8",
    "model.net.movement_latent=8",
    "model.net.motion_hidden=8",
    "model.net.text_hidden=8",
    "model.trained_on=synthetic_humanml3d",
]
HUMANML3D_TARGET = "intermask.evaluator.humanml3d_matcher.HumanML3DMatcher"


def _compose(*overrides: str):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        return compose("train_evaluator", overrides=["data=humanml3d", *overrides])


def _training_split():
    """HumanML3DDataset's caption layout: items whose captions hold token tuples."""
    captions = [
        SimpleNamespace(text=c, tokens=tuple(t.split()))
        for c, t in zip(CAPTIONS, TOKENS, strict=True)
    ]
    return SimpleNamespace(items=[SimpleNamespace(captions=(c,)) for c in captions])


class _Batches(L.LightningDataModule):
    """z-scored (B, T, 263) batches as the HumanML3D datamodule gives them."""

    def __init__(self, normalizer: Normalizer) -> None:
        super().__init__()
        self.normalizer = normalizer
        self.datasets = {"train": _training_split()}
        motion, lengths = humanml3d_batch(batch=3, frames=24)
        self.batch = {
            "motion": normalizer.normalize(motion).float(),
            "length": lengths,
            "caption": CAPTIONS,
            "tokens": TOKENS,
        }

    def train_dataloader(self) -> DataLoader:
        return DataLoader([self.batch] * 2, batch_size=None)

    def val_dataloader(self) -> DataLoader:
        return DataLoader([self.batch], batch_size=None)


def test_the_config_is_t2m_humanml3d():
    cfg = _compose()
    net = cfg.model.net
    assert net._target_ == HUMANML3D_TARGET and cfg.model.loss == "margin"
    assert (net.word_dim, net.movement_hidden, net.movement_latent) == (300, 512, 512)
    assert (net.motion_hidden, net.text_hidden, net.embed_dim) == (1024, 512, 512)
    assert (net.max_words, net.unit_length, net.glove_prefix) == (20, 4, "our_vab")
    assert (cfg.model.margin, cfg.model.optimizer.lr, cfg.model.retrieval_group_size) == (
        10.0,
        1e-4,
        32,
    )


def test_setup_takes_the_datamodule_statistics_and_words():
    mean, std = humanml3d_statistics(seed=3)
    normalizer = Normalizer(mean, std)
    module = instantiate(_compose(*TINY).model)
    module._trainer = SimpleNamespace(datamodule=_Batches(normalizer))
    module.setup("fit")
    net = module.net
    assert isinstance(net, HumanML3DMatcher) and bool(net.has_statistics)
    assert torch.allclose(net.mean, mean) and torch.allclose(net.std, std)
    assert net.vocabulary.words[:3] == ["sos", "eos", "unk"] and "wave" in net.vocabulary.words
    batch = module.trainer.datamodule.batch
    motion, lengths = humanml3d_batch(batch=3, frames=24)
    module.eval()  # no dropout
    with torch.no_grad():
        text, embedded = module.embed(batch)
        expected = net.encode_motion(motion, lengths)
    assert text.shape == (3, 512) and torch.allclose(embedded, expected, atol=1e-5)
    bare = EvaluatorModule(
        net=HumanML3DMatcher(word_dim=8),
        optimizer=partial(torch.optim.Adam),
        loss="margin",
        trained_on="x",
    )
    bare._trainer = SimpleNamespace(datamodule=SimpleNamespace(normalizer=None, datasets={}))
    with pytest.raises(ValueError, match="z-scores motion with the training split's statistics"):
        bare.setup("fit")


def test_fit_then_load_the_checkpoint_frozen(tmp_path):
    cfg = _compose(*TINY)
    torch.manual_seed(0)
    module = instantiate(cfg.model)
    datamodule = _Batches(Normalizer(*humanml3d_statistics(seed=3)))
    before = module.net.motion_encoder.hidden.detach().clone()
    trainer = L.Trainer(
        accelerator="cpu",
        max_epochs=1,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
    )
    trainer.fit(module, datamodule=datamodule)
    assert not torch.equal(module.net.motion_encoder.hidden, before)  # it trained
    assert torch.isfinite(trainer.callback_metrics["train/loss"])
    assert 0.0 <= float(trainer.callback_metrics["val/top3"]) <= 1.0

    run = tmp_path / "run"
    last = run / "checkpoints" / "last.ckpt"
    trainer.save_checkpoint(last)
    OmegaConf.save(OmegaConf.create({"model": cfg.model}), run / "config.yaml")
    checkpoint = torch.load(last, map_location="cpu", weights_only=True)
    assert checkpoint["state_dict"]["net.std"].shape == (263,)
    assert checkpoint[VOCABULARY_KEY] == module.net.vocabulary.words
    assert HUMANML3D_TARGET in run_config.LOADABLE_TARGETS
    evaluator = load_evaluator(last)
    assert evaluator.name == "t2m_gru_humanml3d+learned_words[trained:synthetic_humanml3d]"
    assert torch.equal(evaluator.net.std, module.net.std) and evaluator.dataset == "humanml3d"
    motion, lengths = humanml3d_batch()
    module.eval()
    with torch.no_grad():
        assert torch.allclose(
            evaluator.encode_motion(motion, lengths),
            module.net.encode_motion(motion, lengths),
            atol=1e-6,
        )
        assert torch.allclose(
            evaluator.encode_text(CAPTIONS, TOKENS),
            module.net.encode_text(CAPTIONS, TOKENS),
            atol=1e-6,
        )
