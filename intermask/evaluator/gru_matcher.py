"""T2M's text-motion matcher (Guo et al. 2022): the shared network and its Inter-X variant.

Every variant: motion (B, T, C) -> movement encoder (two stride-2 convolutions, T/4) -> BiGRU
over length // 4 steps -> (B, 512); text: word vector + POS one-hot per token -> BiGRU over the
caption's tokens -> (B, 512). No L2 normalization. :class:`T2MMatcher` owns this; a variant
only says how its dataset's de-normalized motion becomes the (B, T, C) input
(``prepare_motion``):

* :class:`GRUMatcher` (Inter-X, InterMask's evaluator): (B, 2, T, 56, 6) -> (B, T, 56, 12) =
  [P1 6 | P2 6] per row with the translation-velocity channels of row 55 zeroed -> (B, T, 672).
* :class:`~intermask.evaluator.humanml3d_matcher.HumanML3DMatcher` (HumanML3D, T2M's and
  MoMask's evaluator): (B, T, 263) z-scored with its own statistics, foot contacts dropped.

Submodule names follow the released ``finest.tar`` (its ``movement_encoder``, ``text_encoder``
and ``motion_encoder`` state dicts load into the same-named children). The word vectors live
in ``word_embedding`` (the reference keeps GloVe outside the network).

Batch order: the reference sorts by length because ``pack_padded_sequence`` wanted sorted
input; with ``enforce_sorted=False`` PyTorch sorts internally and restores the order, so the
outputs here are in input order and equal the sorted computation row by row (tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence

from intermask.evaluator.interclip import check_captions, check_lengths
from intermask.evaluator.vocabulary import (
    DEFAULT_GLOVE_PREFIX,
    INTERX_MAX_WORDS,
    POS_CLASSES,
    Vocabulary,
    load_glove,
)
from intermask.motion.masks import length_mask
from intermask.motion.rotations import rot6d_to_matrix

NUM_ROWS, PERSON_CHANNELS = 56, 6
TRANSLATION_ROW = 55
INTERX_MAX_FRAMES = 150  # InterMask's max_motion_length for Inter-X
WordVectors = Literal["learned", "glove"]
Rot6dInput = Literal["as_is", "pytorch3d"]


def _init(module: nn.Module) -> None:
    # T2M initialisation: Xavier-normal weights, zero biases for convolutions and linear layers
    if isinstance(module, nn.Conv1d | nn.Linear):
        nn.init.xavier_normal_(module.weight)
        if module.bias is not None:
            nn.init.zeros_(module.bias)


class MovementConvEncoder(nn.Module):
    """(B, T, input) -> (B, T/4, output): two Conv1d(k4, s2, p1) + dropout + LeakyReLU, Linear."""

    def __init__(self, *, input_size: int, hidden_size: int, output_size: int) -> None:
        super().__init__()
        self.main = nn.Sequential(
            nn.Conv1d(input_size, hidden_size, 4, 2, 1),
            nn.Dropout(0.2),
            nn.LeakyReLU(0.2),
            nn.Conv1d(hidden_size, output_size, 4, 2, 1),
            nn.Dropout(0.2),
            nn.LeakyReLU(0.2),
        )
        self.out_net = nn.Linear(output_size, output_size)
        self.apply(_init)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.main(rearrange(x, "b t c -> b c t"))
        return self.out_net(rearrange(x, "b c t -> b t c"))


class _BiGRUHead(nn.Module):
    """Linear -> BiGRU (learned initial state) -> last states of both directions -> MLP."""

    def __init__(self, *, input_size: int, hidden_size: int, output_size: int) -> None:
        super().__init__()
        self.input_emb = nn.Linear(input_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = nn.Sequential(
            nn.Linear(hidden_size * 2, hidden_size),
            nn.LayerNorm(hidden_size),
            nn.LeakyReLU(0.2),
            nn.Linear(hidden_size, output_size),
        )
        self.input_emb.apply(_init)
        self.output_net.apply(_init)
        self.hidden = nn.Parameter(torch.randn(2, 1, hidden_size))

    def _run(self, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        packed = pack_padded_sequence(
            self.input_emb(x), lengths.cpu(), batch_first=True, enforce_sorted=False
        )
        _, last = self.gru(packed, self.hidden.expand(-1, x.shape[0], -1).contiguous())
        return self.output_net(torch.cat([last[0], last[1]], dim=-1))  # (B, output)


class MotionEncoderBiGRUCo(_BiGRUHead):
    def forward(self, movements: torch.Tensor, steps: torch.Tensor) -> torch.Tensor:
        """(B, T/4, latent) movements + (B,) valid steps -> (B, output)."""
        return self._run(movements, steps)


class TextEncoderBiGRUCo(_BiGRUHead):
    def __init__(
        self, *, word_size: int, pos_size: int, hidden_size: int, output_size: int
    ) -> None:
        super().__init__(input_size=word_size, hidden_size=hidden_size, output_size=output_size)
        self.pos_emb = nn.Linear(pos_size, word_size)
        self.pos_emb.apply(_init)

    def forward(
        self, word_vectors: torch.Tensor, pos_one_hot: torch.Tensor, lengths: torch.Tensor
    ) -> torch.Tensor:
        """(B, L, word) + (B, L, 15) + (B,) tokens -> (B, output)."""
        return self._run(word_vectors + self.pos_emb(pos_one_hot), lengths)


class T2MMatcher(nn.Module):
    """The T2M matcher without a motion layout; subclasses set the class attributes and define
    ``check_motion`` and ``prepare_motion``.

    Args:
        word_vectors: "glove" (frozen, from ``glove_dir``; comparable to published numbers) or
            "learned" (a trainable embedding over the training split's words, not comparable).
        glove_dir, glove_prefix: the reference GloVe files (see ``vocabulary``).
        vocabulary: the words of the embedding when known at construction (rebuilding a trained
            evaluator); a learned evaluator otherwise gets them from ``set_vocabulary``.
        max_words: tokens kept per caption before sos/eos (max_text_len: 20 in T2M and MoMask,
            35 in InterMask's Inter-X evaluation).
        unit_length: frames per movement step (4; the convolutions halve time twice).
        max_frames: the reference pads every motion with zero frames to its dataset's
            max_motion_length (150 Inter-X, 196 HumanML3D) before the movement encoder;
            shorter inputs are padded to it here (see ``encode_motion``).
        word_dim, movement_hidden, movement_latent, motion_hidden, text_hidden, embed_dim:
            T2M sizes (300, 512, 512, 1024, 512, 512).
    """

    dataset: str  # the motion layout encode_motion takes ("interx", "humanml3d")
    architecture_name: str  # the evaluator name's prefix
    motion_input_size: int  # channels per frame the movement encoder reads (prepare_motion's C)

    def __init__(
        self,
        *,
        word_vectors: WordVectors,
        glove_dir: str | None,
        glove_prefix: str,
        vocabulary: Sequence[str] | None,
        max_words: int,
        unit_length: int,
        max_frames: int,
        word_dim: int,
        movement_hidden: int,
        movement_latent: int,
        motion_hidden: int,
        text_hidden: int,
        embed_dim: int,
    ) -> None:
        super().__init__()
        if word_vectors not in ("learned", "glove"):
            raise ValueError(f"word_vectors must be 'learned' or 'glove', got {word_vectors!r}")
        if word_vectors == "glove" and glove_dir is None and vocabulary is None:
            raise ValueError("word_vectors='glove' needs glove_dir (the folder of the GloVe files)")
        if word_vectors == "learned" and glove_dir is not None:
            raise ValueError(
                "glove_dir is given but word_vectors='learned': set word_vectors='glove'"
            )
        self.word_source, self.word_dim = word_vectors, word_dim
        self.max_words, self.unit_length = max_words, unit_length
        self.max_frames = max_frames
        self.embed_dim = embed_dim
        self.movement_encoder = MovementConvEncoder(
            input_size=self.motion_input_size,
            hidden_size=movement_hidden,
            output_size=movement_latent,
        )
        self.motion_encoder = MotionEncoderBiGRUCo(
            input_size=movement_latent, hidden_size=motion_hidden, output_size=embed_dim
        )
        self.text_encoder = TextEncoderBiGRUCo(
            word_size=word_dim,
            pos_size=len(POS_CLASSES),
            hidden_size=text_hidden,
            output_size=embed_dim,
        )
        self.vocabulary: Vocabulary | None = None
        self.word_embedding: nn.Embedding | None = None
        if glove_dir is not None:
            glove_vocabulary, vectors = load_glove(glove_dir, glove_prefix)
            self._build_embedding(glove_vocabulary, vectors)
        elif vocabulary is not None:
            self._build_embedding(Vocabulary(vocabulary), None)

    @property
    def architecture(self) -> str:
        words = "glove" if self.word_source == "glove" else "learned_words"
        return f"{self.architecture_name}+{words}"

    @property
    def device(self) -> torch.device:
        return self.motion_encoder.hidden.device

    def _build_embedding(self, vocabulary: Vocabulary, vectors: torch.Tensor | None) -> None:
        if vectors is not None and vectors.shape[1] != self.word_dim:
            raise ValueError(
                f"word vectors have {vectors.shape[1]} dims, word_dim is {self.word_dim}"
            )
        embedding = nn.Embedding(len(vocabulary), self.word_dim)
        if vectors is not None:
            with torch.no_grad():
                embedding.weight.copy_(vectors)
        # GloVe stays frozen, as in the reference; learned words train with the rest
        embedding.weight.requires_grad_(self.word_source == "learned")
        self.vocabulary = vocabulary
        self.word_embedding = embedding.to(self.device)

    def set_vocabulary(self, words: Sequence[str]) -> None:
        """Create the learned embedding over ``words`` (once; the same words again are a no-op)."""
        vocabulary = Vocabulary(words)
        if self.vocabulary is not None:
            if vocabulary != self.vocabulary:
                raise ValueError(
                    f"the evaluator already has a vocabulary of {len(self.vocabulary)} words; "
                    f"refusing to replace it with a different one of {len(vocabulary)} words"
                )
            return
        if self.word_source == "glove":
            raise ValueError("a GloVe evaluator takes its vocabulary from the GloVe files")
        self._build_embedding(vocabulary, None)

    def check_motion(self, motion: torch.Tensor) -> int:
        """Raise unless ``motion`` has the variant's de-normalized layout; return its frame count."""
        raise NotImplementedError

    def prepare_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """De-normalized motion + (B,) frame counts -> (B, T, motion_input_size)."""
        raise NotImplementedError

    def encode_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """De-normalized motion in the variant's layout + (B,) frame counts -> (B, embed_dim)."""
        frames = self.check_motion(motion)
        lengths = check_lengths(lengths, batch=motion.shape[0], frames=frames)
        if bool((lengths < self.unit_length).any()):
            raise ValueError(
                f"every length must be >= unit_length {self.unit_length}, got min {int(lengths.min())}"
            )
        motion, lengths = motion.to(self.device), lengths.to(self.device)
        frames = self.prepare_motion(motion, lengths)  # (B, T, C), zero after each length
        if frames.shape[1] < self.max_frames:
            # The reference pads every motion with zero frames to max_motion_length. A motion
            # that ends within 2 frames of the tensor's end has its last movement step read the
            # second convolution's zero padding where the reference reads the first
            # convolution of zero frames (its bias, activated): a different embedding.
            frames = F.pad(frames, (0, 0, 0, self.max_frames - frames.shape[1]))
        movements = self.movement_encoder(frames)  # (B, T/4, latent)
        steps = (lengths // self.unit_length).clamp(max=movements.shape[1])
        return self.motion_encoder(movements, steps)

    def encode_text(
        self, captions: Sequence[str], tokens: Sequence[str] | None = None
    ) -> torch.Tensor:
        """B captions + their ``"word/POS ..."`` token strings -> (B, embed_dim)."""
        check_captions(captions)
        if tokens is None:
            raise ValueError(
                f"the {self.dataset} evaluator reads POS-tagged tokens: pass tokens (the items' "
                "'tokens' strings, 'word/POS word/POS ...'), one per caption"
            )
        if len(tokens) != len(captions):
            raise ValueError(f"got {len(tokens)} token strings for {len(captions)} captions")
        if self.word_embedding is None or self.vocabulary is None:
            raise RuntimeError(
                "the learned word embedding has no vocabulary yet: call set_vocabulary(words) "
                "(EvaluatorModule does it from the training split)"
            )
        encoded = self.vocabulary.encode(tokens, max_words=self.max_words)
        vectors = self.word_embedding(encoded.word_ids.to(self.device))
        return self.text_encoder(vectors, encoded.pos_one_hot.to(self.device), encoded.lengths)


class GRUMatcher(T2MMatcher):
    """T2M text-motion matcher for the Inter-X representation.

    Args: those of :class:`T2MMatcher` and
        rot6d_input: "as_is" feeds our 6D rotations unchanged; "pytorch3d" re-expresses them as
            the first two matrix rows, the layout the released evaluator was trained on.
    """

    dataset = "interx"
    architecture_name = "t2m_gru"
    motion_input_size = NUM_ROWS * 2 * PERSON_CHANNELS  # 672

    def __init__(
        self,
        *,
        word_vectors: WordVectors = "learned",
        glove_dir: str | None = None,
        glove_prefix: str = DEFAULT_GLOVE_PREFIX,
        vocabulary: Sequence[str] | None = None,
        max_words: int = INTERX_MAX_WORDS,
        unit_length: int = 4,
        max_frames: int = INTERX_MAX_FRAMES,
        word_dim: int = 300,
        movement_hidden: int = 512,
        movement_latent: int = 512,
        motion_hidden: int = 1024,
        text_hidden: int = 512,
        embed_dim: int = 512,
        rot6d_input: Rot6dInput = "as_is",
    ) -> None:
        if rot6d_input not in ("as_is", "pytorch3d"):
            raise ValueError(f"rot6d_input must be 'as_is' or 'pytorch3d', got {rot6d_input!r}")
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
        self.rot6d_input = rot6d_input

    def check_motion(self, motion: torch.Tensor) -> int:
        if (
            motion.ndim != 5
            or motion.shape[1] != 2
            or tuple(motion.shape[3:]) != (NUM_ROWS, PERSON_CHANNELS)
        ):
            raise ValueError(
                "the Inter-X evaluator expects de-normalized motion (B, 2, T, 56, 6), "
                f"got {tuple(motion.shape)}"
            )
        return motion.shape[2]

    def prepare_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """(B, 2, T, 56, 6) -> (B, T, 672): persons side by side per row, velocities and padded
        frames zeroed (the reference pads with zeros), 6D layout converted when configured."""
        self.check_motion(motion)
        motion = motion.float().clone()
        motion[:, :, :, TRANSLATION_ROW, 3:] = 0.0  # translation velocity (reference zeros it)
        if self.rot6d_input == "pytorch3d":
            # ours: first two columns, row by row; pytorch3d: the first two rows
            matrix = rot6d_to_matrix(motion[:, :, :, :TRANSLATION_ROW])  # (B, 2, T, 55, 3, 3)
            motion[:, :, :, :TRANSLATION_ROW] = matrix[..., :2, :].flatten(-2)
        valid = length_mask(lengths.to(motion.device), motion.shape[2])
        valid = valid[:, None, :, None, None]  # (B, 1, T, 1, 1)
        motion = torch.where(valid, motion, 0.0)
        return rearrange(motion, "b p t j c -> b t (j p c)")
