"""The HumanML3D evaluator: T2M's text-motion matcher over the 263-d single-person feature.

This is the evaluator T2M (Guo et al. 2022) released as ``t2m/text_mot_match`` and MoMask
reuses for its HumanML3D table. Motion: de-normalized (B, T, 263) -> z-scored with the
*evaluator's own* statistics (the release's ``t2m/Comp_v6_KLD01/meta/{mean,std}.npy``, not the
generator's) -> the 4 foot-contact dims dropped -> (B, T, 259), padded frames zeroed (the
reference pads the z-scored motion with zeros) -> the shared T2M network
(:class:`~intermask.evaluator.gru_matcher.T2MMatcher`). Text: GloVe ``our_vab`` word vectors +
POS one-hots, at most 20 tokens between sos and eos.

The statistics are buffers (``mean``, ``std``, ``has_statistics``), so our checkpoints carry
them: a released evaluator gets them from the ``meta`` folder (``load_evaluator``), one trained
here from the training split's (``EvaluatorModule`` calls :meth:`HumanML3DMatcher.set_statistics`
with the datamodule's).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from intermask.data.normalization import Normalizer
from intermask.evaluator.gru_matcher import T2MMatcher, WordVectors
from intermask.evaluator.vocabulary import DEFAULT_MAX_WORDS, HUMANML3D_GLOVE_PREFIX
from intermask.motion.humanml3d import FEATURE_DIM, FOOT_CONTACTS
from intermask.motion.masks import length_mask

STATISTICS_BUFFERS = ("mean", "std", "has_statistics")  # not in a released finest.tar
HUMANML3D_MAX_FRAMES = 196  # T2M's and MoMask's max_motion_length


class HumanML3DMatcher(T2MMatcher):
    """T2M text-motion matcher for HumanML3D's (B, T, 263) features.

    Args: those of :class:`~intermask.evaluator.gru_matcher.T2MMatcher` (GloVe prefix
        ``our_vab``) and
        mean, std: (263,) evaluator statistics; None until :meth:`set_statistics` (a checkpoint
            restores them with the weights).
    """

    dataset = "humanml3d"
    architecture_name = "t2m_gru_humanml3d"
    motion_input_size = FOOT_CONTACTS.start  # 259: the contacts are the last 4 dims

    def __init__(
        self,
        *,
        word_vectors: WordVectors = "learned",
        glove_dir: str | None = None,
        glove_prefix: str = HUMANML3D_GLOVE_PREFIX,
        vocabulary: Sequence[str] | None = None,
        max_words: int = DEFAULT_MAX_WORDS,
        unit_length: int = 4,
        max_frames: int = HUMANML3D_MAX_FRAMES,
        word_dim: int = 300,
        movement_hidden: int = 512,
        movement_latent: int = 512,
        motion_hidden: int = 1024,
        text_hidden: int = 512,
        embed_dim: int = 512,
        mean: torch.Tensor | None = None,
        std: torch.Tensor | None = None,
    ) -> None:
        if (mean is None) != (std is None):
            raise ValueError("give both mean and std, or neither")
        super().__init__(
            word_vectors=word_vectors,
            glove_dir=glove_dir,
            glove_prefix=glove_prefix,
            vocabulary=vocabulary,
            max_words=max_words,
            unit_length=unit_length,
            max_frames=max_frames,
            word_dim=word_dim,
            movement_hidden=movement_hidden,
            movement_latent=movement_latent,
            motion_hidden=motion_hidden,
            text_hidden=text_hidden,
            embed_dim=embed_dim,
        )
        self.register_buffer("mean", torch.zeros(FEATURE_DIM))
        self.register_buffer("std", torch.ones(FEATURE_DIM))
        self.register_buffer("has_statistics", torch.tensor(False))
        if mean is not None and std is not None:
            self.set_statistics(mean, std)

    def set_statistics(
        self, mean: torch.Tensor, std: torch.Tensor, *, source: str = "set_statistics"
    ) -> None:
        """Set the (263,) mean and std the motion is z-scored with; ``source`` (e.g. the files)
        is named in the errors."""
        mean = torch.as_tensor(mean, dtype=torch.float32)
        std = torch.as_tensor(std, dtype=torch.float32)
        if tuple(mean.shape) != (FEATURE_DIM,) or tuple(std.shape) != (FEATURE_DIM,):
            raise ValueError(
                f"{source}: HumanML3D evaluator statistics must have shape ({FEATURE_DIM},), "
                f"got mean {tuple(mean.shape)} and std {tuple(std.shape)}"
            )
        Normalizer(mean, std, source=source)  # finite values and std > 0, or a DataError
        self.mean.copy_(mean)
        self.std.copy_(std)
        self.has_statistics.fill_(True)

    def check_motion(self, motion: torch.Tensor) -> int:
        if motion.ndim != 3 or motion.shape[2] != FEATURE_DIM:
            raise ValueError(
                f"the HumanML3D evaluator expects de-normalized motion (B, T, {FEATURE_DIM}), "
                f"got {tuple(motion.shape)}"
            )
        return motion.shape[1]

    def prepare_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """(B, T, 263) de-normalized -> (B, T, 259): z-scored with the evaluator's statistics,
        foot contacts dropped, frames at and after each length zeroed."""
        self.check_motion(motion)
        if not bool(self.has_statistics):
            raise RuntimeError(
                "the HumanML3D evaluator has no statistics yet: load a released one with its "
                "meta/mean.npy and meta/std.npy (load_evaluator), or call set_statistics(mean, "
                "std) with the training split's (EvaluatorModule does it from the datamodule)"
            )
        normalized = (motion.float() - self.mean) / self.std
        valid = length_mask(lengths.to(motion.device), motion.shape[1])[:, :, None]  # (B, T, 1)
        return torch.where(valid, normalized[..., : self.motion_input_size], 0.0)
