import pytest
import torch

from intermask.interm.tokens import (
    Vocabulary,
    build_sequence,
    sequence_padding_mask,
    split_persons,
    split_sequence,
    step_padding_mask,
)


def test_vocabulary_puts_special_tokens_after_the_codes():
    vocabulary = Vocabulary()
    assert (vocabulary.mask_id, vocabulary.pad_id, vocabulary.sep_id) == (1024, 1025, 1026)
    assert vocabulary.size == 1027


def test_sequence_is_a_sep_b_flattened_joint_major():
    a = torch.arange(2 * 5 * 3).reshape(2, 5, 3) % 16
    b = (a + 7) % 16
    seq = build_sequence(a, b, codebook_size=16)
    assert seq.shape == (2, 31)
    assert (seq[:, 15] == 18).all()  # [SEP] = K + 2
    for r in range(5):
        for t in range(3):
            assert torch.equal(seq[:, r * 3 + t], a[:, r, t])
            assert torch.equal(seq[:, 16 + r * 3 + t], b[:, r, t])


def test_round_trip_keeps_codes_mask_and_vq_padding():
    a = torch.randint(0, 17, (3, 5, 4))  # codes and [MASK]
    b = torch.randint(0, 17, (3, 5, 4))
    a[0, :, 2:] = -1
    b[1, :, 3:] = -1
    seq = build_sequence(a, b, codebook_size=16)
    assert (seq == 17).sum() == (a == -1).sum() + (b == -1).sum()  # -1 -> [PAD] = K + 1
    out = split_sequence(seq, rows=5, steps=4, codebook_size=16)
    assert torch.equal(out.a, a) and torch.equal(out.b, b)


def test_lengths_turn_every_later_step_into_pad():
    a = torch.randint(0, 16, (2, 5, 4))
    seq = build_sequence(a, a.clone(), codebook_size=16, lengths_in_steps=torch.tensor([4, 1]))
    pad = sequence_padding_mask(seq, codebook_size=16)
    expected = step_padding_mask(torch.tensor([4, 1]), 4)[:, None, :].expand(2, 5, 4).reshape(2, 20)
    assert torch.equal(pad, torch.cat([expected, torch.zeros(2, 1, dtype=torch.bool), expected], 1))


def test_split_persons_keeps_trailing_dimensions():
    x = torch.randn(2, 2 * 5 * 3 + 1, 7)
    pair = split_persons(x, rows=5, steps=3)
    assert pair.a.shape == (2, 5, 3, 7)
    assert torch.equal(pair.a[:, 1, 2], x[:, 5]) and torch.equal(pair.b[:, 4, 0], x[:, 16 + 12])


def test_invalid_inputs_raise_with_evidence():
    a = torch.zeros(1, 5, 2, dtype=torch.long)
    with pytest.raises(ValueError, match=r"\(B, rows, T'\)"):
        build_sequence(a, torch.zeros(1, 5, 3, dtype=torch.long))
    with pytest.raises(ValueError, match="got values in"):
        build_sequence(a, torch.full_like(a, 18), codebook_size=16)  # [SEP] is not an input
    with pytest.raises(ValueError, match=r"\[0, 2\]"):
        step_padding_mask(torch.tensor([3]), 2)
    with pytest.raises(ValueError, match="must be \\[SEP\\]"):
        split_sequence(torch.zeros(1, 21, dtype=torch.long), rows=5, steps=2, codebook_size=16)
    with pytest.raises(ValueError, match="expected"):
        split_persons(torch.zeros(1, 20), rows=5, steps=2)
