"""Token vocabulary of the Inter-M Transformer and the two-person token sequence.

The generator reads one sequence per interaction (InterMask section 3.2, figure 2b): person A's
``(rows, T')`` token map flattened joint-major (index ``row * T' + t``, the reference layout),
one [SEP] token, then person B's map flattened the same way, ``2N + 1`` tokens with
``N = rows * T'``. The VQ-VAE marks steps beyond a clip's length with ``-1``; here they become
[PAD], which attention never reads.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import NamedTuple

import torch
from einops import rearrange

from intermask.motion.masks import length_mask

CODEBOOK_SIZE = 1024  # |C|, paper appendix C.1

# Whether the sequence builders check their inputs' values. A check reads a tensor back to the
# host, which a CUDA graph cannot capture; the graphed forward checks its inputs eagerly first.
_CHECKED: ContextVar[bool] = ContextVar("intermask_checked_tokens", default=True)


@contextmanager
def unchecked_tokens() -> Iterator[None]:
    """Skip the value checks of :func:`step_padding_mask` and :func:`build_sequence` (their
    shape checks stay): for a CUDA graph capture of inputs already checked eagerly."""
    token = _CHECKED.set(False)
    try:
        yield
    finally:
        _CHECKED.reset(token)


@dataclass(frozen=True)
class Vocabulary:
    """The K codes followed by the three special tokens [MASK], [PAD], [SEP] (section 3.2)."""

    codebook_size: int = CODEBOOK_SIZE

    @property
    def mask_id(self) -> int:
        return self.codebook_size

    @property
    def pad_id(self) -> int:
        return self.codebook_size + 1

    @property
    def sep_id(self) -> int:
        return self.codebook_size + 2

    @property
    def size(self) -> int:
        return self.codebook_size + 3


class PersonPair(NamedTuple):
    a: torch.Tensor  # (B, rows, T', *) person A
    b: torch.Tensor  # (B, rows, T', *) person B


def step_padding_mask(lengths_in_steps: torch.Tensor, steps: int) -> torch.Tensor:
    """(B,) valid token steps -> (B, T') bool, True at padded steps."""
    if lengths_in_steps.ndim != 1:
        raise ValueError(
            f"lengths_in_steps must be (B,), got shape {tuple(lengths_in_steps.shape)}"
        )
    if _CHECKED.get() and bool(((lengths_in_steps < 0) | (lengths_in_steps > steps)).any()):
        raise ValueError(
            f"lengths_in_steps must lie in [0, {steps}], got {lengths_in_steps.tolist()}"
        )
    return ~length_mask(lengths_in_steps, steps)


def build_sequence(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    *,
    codebook_size: int = CODEBOOK_SIZE,
    lengths_in_steps: torch.Tensor | None = None,
) -> torch.Tensor:
    """Two (B, rows, T') token maps -> (B, 2N + 1) sequence ``[A, SEP, B]``, N = rows * T'.

    Entries may be codes ``0..K-1``, [MASK] or [PAD]; ``-1`` (VQ padding) becomes [PAD], and so
    does every step at or beyond ``lengths_in_steps`` (B,) when it is given.
    """
    vocabulary = Vocabulary(codebook_size)
    if tokens_a.shape != tokens_b.shape or tokens_a.ndim != 3:
        raise ValueError(
            "tokens_a and tokens_b must both be (B, rows, T'), got "
            f"{tuple(tokens_a.shape)} and {tuple(tokens_b.shape)}"
        )
    tokens = torch.stack([tokens_a, tokens_b], dim=1).long()  # (B, 2, rows, T')
    if _CHECKED.get() and bool(((tokens < -1) | (tokens > vocabulary.pad_id)).any()):
        raise ValueError(
            f"tokens must be -1, a code in [0, {codebook_size}), [MASK]={vocabulary.mask_id} or "
            f"[PAD]={vocabulary.pad_id}; got values in [{int(tokens.min())}, {int(tokens.max())}]"
        )
    padded = tokens < 0
    if lengths_in_steps is not None:
        padded = padded | step_padding_mask(lengths_in_steps, tokens.shape[-1])[:, None, None, :]
    tokens = tokens.masked_fill(padded, vocabulary.pad_id)
    persons = rearrange(tokens, "b p r t -> b p (r t)")
    sep = persons.new_full((persons.shape[0], 1), vocabulary.sep_id)
    return torch.cat([persons[:, 0], sep, persons[:, 1]], dim=1)


def split_persons(x: torch.Tensor, *, rows: int, steps: int) -> PersonPair:
    """(B, 2N + 1, *) per-token values -> each person's (B, rows, T', *), dropping [SEP]."""
    n = rows * steps
    if x.ndim < 2 or x.shape[1] != 2 * n + 1:
        raise ValueError(
            f"expected (B, {2 * n + 1}, ...) for rows={rows}, steps={steps}, got {tuple(x.shape)}"
        )
    a, _, b = x.split([n, 1, n], dim=1)
    return PersonPair(
        rearrange(a, "b (r t) ... -> b r t ...", r=rows),
        rearrange(b, "b (r t) ... -> b r t ...", r=rows),
    )


def split_sequence(
    sequence: torch.Tensor, *, rows: int = 5, steps: int, codebook_size: int = CODEBOOK_SIZE
) -> PersonPair:
    """(B, 2N + 1) sequence -> (B, rows, T') token maps; [PAD] goes back to -1 (VQ convention).

    Inverse of :func:`build_sequence` for inputs that use -1 for padding.
    """
    vocabulary = Vocabulary(codebook_size)
    if bool((sequence[:, rows * steps] != vocabulary.sep_id).any()):
        raise ValueError(
            f"the middle token (index {rows * steps}) must be [SEP]={vocabulary.sep_id}"
        )
    pair = split_persons(sequence, rows=rows, steps=steps)
    return PersonPair(*(p.masked_fill(p == vocabulary.pad_id, -1) for p in pair))


def sequence_padding_mask(
    sequence: torch.Tensor, *, codebook_size: int = CODEBOOK_SIZE
) -> torch.Tensor:
    """(B, 2N + 1) sequence -> (B, 2N + 1) bool key-padding mask, True at [PAD]."""
    return sequence == Vocabulary(codebook_size).pad_id
