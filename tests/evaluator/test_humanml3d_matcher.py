"""HumanML3DMatcher: its own z-scoring, dropped foot contacts, order invariance, statistics, errors."""

from __future__ import annotations

import pytest
import torch
from evaluator_builders import (
    CAPTIONS,
    TOKENS,
    humanml3d_batch,
    humanml3d_statistics,
    interx_batch,
    tiny_humanml3d,
)
from torch.nn.utils.rnn import pack_padded_sequence

from intermask.data.errors import DataError
from intermask.evaluator import GRUMatcher, HumanML3DMatcher, T2MMatcher


def test_prepare_motion_z_scores_with_its_own_statistics_and_drops_the_contacts():
    net = tiny_humanml3d()
    mean, std = humanml3d_statistics()
    motion, lengths = humanml3d_batch()
    frames = net.prepare_motion(motion, lengths)
    assert frames.shape == (3, 24, 259)
    first = lengths[0]
    expected = ((motion[0, :first] - mean) / std)[:, :259]
    assert torch.allclose(frames[0, :first], expected, atol=1e-6)
    assert (frames[0, first:] == 0).all()  # padding is zero in the z-scored space
    assert net.movement_encoder.main[0].in_channels == 259


def test_outputs_stay_in_input_order_and_match_the_sorted_reference():
    net = tiny_humanml3d()
    mean, std = humanml3d_statistics()
    motion, lengths = humanml3d_batch(batch=5)
    with torch.no_grad():
        ours = net.encode_motion(motion, lengths)
        # the reference: z-score with meta mean/std, pad with zeros to max_motion_length, drop
        # the last 4 dims, sort
        order = torch.argsort(lengths, descending=True)
        normalized = (motion[order] - mean) / std
        for row, length in enumerate(lengths[order]):
            normalized[row, length:] = 0.0
        padding = net.max_frames - normalized.shape[1]
        normalized = torch.nn.functional.pad(normalized, (0, 0, 0, padding))
        movements = net.movement_encoder(normalized[..., :-4])
        head = net.motion_encoder
        packed = pack_padded_sequence(
            head.input_emb(movements), (lengths[order] // 4).tolist(), batch_first=True
        )
        _, last = head.gru(packed, head.hidden.repeat(1, 5, 1))
        reference = head.output_net(torch.cat([last[0], last[1]], dim=-1))
    assert ours.shape == (5, 512)
    assert torch.allclose(ours[order], reference, atol=1e-5)


def test_contacts_and_padding_content_do_not_matter():
    net = tiny_humanml3d()
    motion, lengths = humanml3d_batch()
    changed = motion.clone()
    changed[..., 259:] = torch.randint(0, 2, changed[..., 259:].shape).float()
    changed[0, lengths[0] :] = 7.0
    with torch.no_grad():
        assert torch.allclose(
            net.encode_motion(changed, lengths), net.encode_motion(motion, lengths), atol=1e-6
        )


def test_statistics_are_buffers_that_travel_with_the_state_dict():
    source = tiny_humanml3d(seed=1)
    state = source.state_dict()
    assert state["mean"].shape == (263,) and bool(state["has_statistics"])
    assert not any(name in dict(source.named_parameters()) for name in ("mean", "std"))
    copy = tiny_humanml3d(seed=2, statistics=False)
    assert not bool(copy.has_statistics)
    copy.load_state_dict(state)
    motion, lengths = humanml3d_batch()
    with torch.no_grad():
        assert torch.equal(
            copy.encode_motion(motion, lengths), source.encode_motion(motion, lengths)
        )


def test_statistics_errors():
    net = tiny_humanml3d(statistics=False)
    motion, lengths = humanml3d_batch()
    with pytest.raises(RuntimeError, match="has no statistics yet.*set_statistics"):
        net.encode_motion(motion, lengths)
    mean, std = humanml3d_statistics()
    with pytest.raises(
        ValueError,
        match=r"stats.npy: HumanML3D evaluator statistics must have shape \(263,\), "
        r"got mean \(262,\) and std \(263,\)",
    ):
        net.set_statistics(mean[:262], std, source="stats.npy")
    std[5] = 0.0
    with pytest.raises(DataError, match=r"std must be > 0 everywhere.*flat indices \[5\]"):
        net.set_statistics(mean, std)
    assert not bool(net.has_statistics)
    with pytest.raises(ValueError, match="give both mean and std, or neither"):
        HumanML3DMatcher(mean=mean)


def test_text_path_names_and_layout_errors():
    net = tiny_humanml3d()
    assert isinstance(net, T2MMatcher) and not isinstance(net, GRUMatcher)
    assert (net.dataset, net.architecture, net.embed_dim) == (
        "humanml3d",
        "t2m_gru_humanml3d+learned_words",
        512,
    )
    with torch.no_grad():
        batch = net.encode_text(CAPTIONS, TOKENS)
        single = torch.cat(
            [net.encode_text(CAPTIONS[i : i + 1], TOKENS[i : i + 1]) for i in range(3)]
        )
    assert batch.shape == (3, 512) and torch.allclose(batch, single, atol=1e-5)
    with pytest.raises(ValueError, match="the humanml3d evaluator reads POS-tagged tokens"):
        net.encode_text(CAPTIONS)
    pair, pair_lengths = interx_batch()
    with pytest.raises(
        ValueError,
        match=r"expects de-normalized motion \(B, T, 263\), got \(3, 2, 24, 56, 6\)",
    ):
        net.encode_motion(pair, pair_lengths)
    motion, _ = humanml3d_batch()
    with pytest.raises(ValueError, match="every length must be >= unit_length 4, got min 2"):
        net.encode_motion(motion, torch.tensor([2, 8, 8]))
    with pytest.raises(ValueError, match=r"lengths must lie in \[1, 24\]"):
        net.encode_motion(motion, torch.tensor([25, 8, 8]))
