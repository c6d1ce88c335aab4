"""GRUMatcher: the reference motion layout, 6D conversion, order invariance, text path, errors."""

from __future__ import annotations

import pytest
import torch
from evaluator_builders import CAPTIONS, TOKENS, WORDS, interx_batch, tiny_gru
from torch.nn.utils.rnn import pack_padded_sequence

from intermask.evaluator import GRUMatcher
from intermask.motion.rotations import axis_angle_to_matrix, matrix_to_rot6d


def test_prepare_motion_puts_persons_side_by_side_and_zeros_velocity_and_padding(gru):
    motion, lengths = interx_batch()
    frames = gru.prepare_motion(motion, lengths)  # (B, T, 672)
    assert frames.shape == (3, 24, 672)
    rows = frames.reshape(3, 24, 56, 12)
    valid = rows[0, : lengths[0]]
    assert torch.equal(valid[:, :55, :6], motion[0, 0, : lengths[0], :55])
    assert torch.equal(valid[:, :55, 6:], motion[0, 1, : lengths[0], :55])
    assert torch.equal(valid[:, 55, 0:3], motion[0, 0, : lengths[0], 55, :3])  # P1 translation
    assert torch.equal(valid[:, 55, 6:9], motion[0, 1, : lengths[0], 55, :3])  # P2 translation
    assert (valid[:, 55, 3:6] == 0).all() and (valid[:, 55, 9:12] == 0).all()  # velocities
    assert (rows[0, lengths[0] :] == 0).all()  # padding


def test_pytorch3d_layout_is_the_first_two_matrix_rows():
    net = tiny_gru(rot6d_input="pytorch3d")
    matrix = axis_angle_to_matrix(torch.randn(1, 2, 8, 55, 3))
    motion = torch.zeros(1, 2, 8, 56, 6)
    motion[:, :, :, :55] = matrix_to_rot6d(matrix)  # our layout: first two columns, row by row
    rows = net.prepare_motion(motion, torch.tensor([8])).reshape(1, 8, 56, 12)
    expected = matrix[0, 0, :, :, :2, :].reshape(8, 55, 6)  # [R00 R01 R02 R10 R11 R12]
    assert torch.allclose(rows[0, :, :55, :6], expected, atol=1e-5)
    assert not torch.allclose(matrix_to_rot6d(matrix)[0, 0], expected, atol=1e-3)


def test_outputs_stay_in_input_order_and_match_the_sorted_reference(gru):
    motion, lengths = interx_batch(batch=5)
    with torch.no_grad():
        ours = gru.encode_motion(motion, lengths)
        # the reference: zero frames up to max_motion_length, sort by length, pack sorted,
        # movement steps = length // 4
        order = torch.argsort(lengths, descending=True)
        frames = gru.prepare_motion(motion[order], lengths[order])
        frames = torch.nn.functional.pad(frames, (0, 0, 0, gru.max_frames - frames.shape[1]))
        movements = gru.movement_encoder(frames)
        head = gru.motion_encoder
        packed = pack_padded_sequence(
            head.input_emb(movements), (lengths[order] // 4).tolist(), batch_first=True
        )
        _, last = head.gru(packed, head.hidden.repeat(1, 5, 1))
        reference = head.output_net(torch.cat([last[0], last[1]], dim=-1))
    assert torch.allclose(ours[order], reference, atol=1e-5)
    assert ours.shape == (5, 512)


def test_padding_content_does_not_matter(gru):
    motion, lengths = interx_batch()
    noisy = motion.clone()
    noisy[0, :, lengths[0] :] = 7.0
    with torch.no_grad():
        assert torch.allclose(
            gru.encode_motion(noisy, lengths), gru.encode_motion(motion, lengths), atol=1e-6
        )


def test_text_reads_words_and_pos_and_ignores_padding_rows(gru):
    with torch.no_grad():
        batch = gru.encode_text(CAPTIONS, TOKENS)
        single = torch.cat(
            [gru.encode_text(CAPTIONS[i : i + 1], TOKENS[i : i + 1]) for i in range(3)]
        )
        retagged = gru.encode_text(
            CAPTIONS[:1], ["the/DET person/NOUN wave/NOUN left/ADJ hand/NOUN"]
        )
    assert batch.shape == (3, 512) and torch.allclose(batch, single, atol=1e-5)
    assert not torch.allclose(retagged, batch[:1], atol=1e-4)  # the POS tag is an input


def test_vocabulary_and_word_vector_modes(gru):
    assert gru.architecture == "t2m_gru+learned_words"
    assert gru.word_embedding.weight.requires_grad and len(gru.vocabulary) == len(WORDS)
    pending = GRUMatcher(
        word_dim=8, movement_hidden=8, movement_latent=8, motion_hidden=8, text_hidden=8
    )
    with pytest.raises(RuntimeError, match="call set_vocabulary"):
        pending.encode_text(CAPTIONS, TOKENS)
    pending.set_vocabulary(WORDS)
    pending.set_vocabulary(WORDS)  # the same words again: no-op
    with pytest.raises(ValueError, match="refusing to replace it with a different one of 4 words"):
        pending.set_vocabulary(["sos", "eos", "unk", "extra"])


def test_errors_name_the_problem(gru):
    motion, lengths = interx_batch()
    with pytest.raises(
        ValueError, match=r"expects de-normalized motion \(B, 2, T, 56, 6\), got \(3, 24, 56, 12\)"
    ):
        gru.encode_motion(motion.permute(0, 2, 3, 1, 4).reshape(3, 24, 56, 12), lengths)
    with pytest.raises(ValueError, match="every length must be >= unit_length 4, got min 3"):
        gru.encode_motion(motion, torch.tensor([3, 8, 8]))
    with pytest.raises(ValueError, match="pass tokens"):
        gru.encode_text(CAPTIONS)
    with pytest.raises(ValueError, match="got 2 token strings for 3 captions"):
        gru.encode_text(CAPTIONS, TOKENS[:2])
    with pytest.raises(ValueError, match="needs glove_dir"):
        GRUMatcher(word_vectors="glove")
    with pytest.raises(ValueError, match="set word_vectors='glove'"):
        GRUMatcher(glove_dir="/somewhere")
    with pytest.raises(ValueError, match="rot6d_input must be"):
        GRUMatcher(rot6d_input="columns")
