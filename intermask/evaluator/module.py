"""EvaluatorModule: trains a contrastive text-motion evaluator (loss, optimizer, logging)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any, Literal

import torch
from torch.optim import Optimizer

from intermask.data.normalization import Normalizer
from intermask.evaluator.checkpoints import VOCABULARY_KEY
from intermask.evaluator.gru_matcher import T2MMatcher
from intermask.evaluator.humanml3d_matcher import HumanML3DMatcher
from intermask.evaluator.interclip import InterCLIP
from intermask.evaluator.losses import RetrievalAccuracy, clip_loss, margin_loss
from intermask.evaluator.vocabulary import Vocabulary
from intermask.utils.lightning import ScheduledModule

log = logging.getLogger(__name__)
LossKind = Literal["clip", "margin"]


class EvaluatorModule(ScheduledModule):
    """Trains :class:`InterCLIP` or a T2M matcher (:class:`GRUMatcher` for Inter-X,
    :class:`HumanML3DMatcher`) on text-motion batches.

    Batch: ``motion`` as the datamodule gives it (normalized or not): (B, 2, T, *F) for the
    interaction datasets, (B, T, 263) for HumanML3D; ``length`` (B,), ``caption`` (B strings) and,
    for the T2M matchers, ``tokens`` (B ``"word/POS ..."`` strings). The motion is de-normalized
    with the datamodule's statistics first: evaluators always see feature units, exactly as the
    protocol feeds them. A HumanML3D matcher without statistics takes the datamodule's (the
    training split's) as its own.

    Args:
        net: the evaluator network.
        optimizer: partial optimizer taking the trainable parameters.
        loss: "clip" (InterGen: symmetric cross-entropy, logit scale latent_scale^2; InterCLIP
            only) or "margin" (T2M: matching distance^2 + hinge^2 on shifted negatives).
        margin: T2M's negative margin (10).
        trained_on: the data config's name; becomes part of the evaluator's name.
        retrieval_group_size: R-precision groups for validation (protocol eval batch).
        min_word_count: words seen fewer times in the training split map to ``unk`` (learned
            GRU vocabulary only).
        warmup_fraction, lr_milestones, lr_gamma: the project's warm-up multistep schedule
            (fractions of all optimizer steps); the defaults keep the learning rate constant,
            as T2M trains its matcher.
    """

    def __init__(
        self,
        *,
        net: InterCLIP | T2MMatcher,
        optimizer: Callable[..., Optimizer],
        loss: LossKind,
        trained_on: str,
        margin: float = 10.0,
        retrieval_group_size: int = 96,
        min_word_count: int = 1,
        warmup_fraction: float = 0.0,
        lr_milestones: Sequence[float] = (),
        lr_gamma: float = 1.0,
    ) -> None:
        super().__init__()
        if loss not in ("clip", "margin"):
            raise ValueError(f"loss must be 'clip' or 'margin', got {loss!r}")
        if loss == "clip" and not isinstance(net, InterCLIP):
            raise ValueError(
                f"loss 'clip' needs the learnable latent_scale of InterCLIP, got {type(net).__name__}"
            )
        self.net = net
        self.optimizer_factory = optimizer
        self.save_hyperparameters(
            {
                "loss": str(loss),
                "margin": float(margin),
                "trained_on": str(trained_on),
                "retrieval_group_size": int(retrieval_group_size),
                "min_word_count": int(min_word_count),
                "warmup_fraction": float(warmup_fraction),
                "lr_milestones": [float(m) for m in lr_milestones],
                "lr_gamma": float(lr_gamma),
            },
            logger=False,
        )
        self.val_retrieval = RetrievalAccuracy(group_size=retrieval_group_size)
        self._normalizer: Normalizer | None = None

    # ------------------------------------------------------------------ data

    def setup(self, stage: str) -> None:
        """Take the datamodule's statistics and, for a learned GRU vocabulary, its words."""
        datamodule = getattr(self.trainer, "datamodule", None) if self._trainer else None
        if datamodule is None:
            raise RuntimeError("EvaluatorModule needs a datamodule (fit with datamodule=)")
        self._normalizer = datamodule.normalizer
        if isinstance(self.net, HumanML3DMatcher) and not bool(self.net.has_statistics):
            # a resumed run restores the checkpoint's statistics after this
            if self._normalizer is None:
                raise ValueError(
                    "the HumanML3D matcher z-scores motion with the training split's statistics, "
                    "but the datamodule has none (normalizer is None)"
                )
            self.net.set_statistics(
                self._normalizer.mean, self._normalizer.std, source=self._normalizer.source
            )
        if isinstance(self.net, T2MMatcher) and self.net.vocabulary is None:
            if "train" not in datamodule.datasets:
                datamodule.setup("fit")
            self.net.set_vocabulary(self._training_words(datamodule.datasets["train"]).words)
            log.info("learned word embedding over %d training words", len(self.net.vocabulary))

    def _training_words(self, dataset: Any) -> Vocabulary:
        strings = _token_strings(dataset)
        if not strings:
            raise ValueError(
                f"the GRU matcher reads POS-tagged tokens, but {type(dataset).__name__} has none "
                "(use it with Inter-X or HumanML3D data)"
            )
        return Vocabulary.from_token_strings(strings, min_count=self.hparams.min_word_count)

    def denormalize(self, motion: torch.Tensor) -> torch.Tensor:
        """(B, 2, T, *F) or (B, T, F) datamodule motion -> feature units."""
        return motion if self._normalizer is None else self._normalizer.denormalize(motion)

    # ------------------------------------------------------------------ steps

    def embed(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        """Batch -> (text (B, 512), motion (B, 512)) embeddings, rows in batch order."""
        motion = self.denormalize(batch["motion"])
        text = self.net.encode_text(batch["caption"], batch.get("tokens"))
        return text, self.net.encode_motion(motion, batch["length"])

    def compute_loss(self, text: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        text, motion = text.float(), motion.float()
        if self.hparams.loss == "clip":
            return clip_loss(text, motion, self.net.logit_scale())
        if len(text) < 2:
            raise ValueError("the margin loss needs batches of at least 2 pairs")
        shift = int(torch.randint(1, len(text), ()))
        return margin_loss(text, motion, margin=self.hparams.margin, shift=shift)

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor | None:
        text, motion = self.embed(batch)
        loss = self.compute_loss(text, motion)
        if self.skip_non_finite({"loss": loss}, batch):
            return None
        batch_size = len(text)
        self.log("train/loss", loss, batch_size=batch_size, prog_bar=True)
        if isinstance(self.net, InterCLIP):
            self.log(
                "train/latent_scale",
                self.net.latent_scale.detach().squeeze(0),
                batch_size=batch_size,
            )
        return loss

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> None:
        text, motion = self.embed(batch)
        if len(text) >= 2:
            loss = self.compute_loss(text, motion)
            self.log("val/loss", loss, batch_size=len(text), sync_dist=True, prog_bar=True)
        self.val_retrieval.update(text, motion)

    def on_validation_epoch_end(self) -> None:
        result = self.val_retrieval.compute()
        self.val_retrieval.reset()
        for name, value in result.items():
            self.log(f"val/{name}", value, prog_bar=name == "top3")

    def optimized_parameters(self) -> list[torch.nn.Parameter]:
        # the frozen CLIP embeddings never reach the optimizer (nor its weight decay)
        return [p for p in self.parameters() if p.requires_grad]

    # ------------------------------------------------------------------ checkpoints

    def on_save_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        # plain strings: the checkpoint still loads with weights_only=True
        if isinstance(self.net, T2MMatcher) and self.net.vocabulary is not None:
            checkpoint[VOCABULARY_KEY] = list(self.net.vocabulary.words)

    def on_load_checkpoint(self, checkpoint: dict[str, Any]) -> None:
        words = checkpoint.get(VOCABULARY_KEY)
        if isinstance(self.net, T2MMatcher) and words is not None:
            # setup() built the vocabulary from today's data: it must be the checkpoint's
            self.net.set_vocabulary(words)


def _token_strings(dataset: Any) -> list[str]:
    """Every ``"word/POS ..."`` caption of a training split: Inter-X keeps ``captions`` per clip
    (tokens one string), HumanML3D ``items`` with their captions (tokens a tuple)."""
    if getattr(dataset, "captions", None):
        clips = dataset.captions
    else:
        clips = [item.captions for item in getattr(dataset, "items", None) or []]
    strings = []
    for clip in clips:
        for caption in clip:
            tokens = getattr(caption, "tokens", None)
            if tokens is None:
                return []
            strings.append(tokens if isinstance(tokens, str) else " ".join(tokens))
    return strings
