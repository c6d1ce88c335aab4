import math

import pytest
import torch

from intermask.motion import humanml3d as hml


def test_slices_tile_the_263_dims():
    slices = hml.PARTS
    assert [s.stop - s.start for s in slices] == [1, 2, 1, 63, 126, 66, 4]
    assert [s.start for s in slices[1:]] == [s.stop for s in slices[:-1]]
    assert slices[0].start == 0 and slices[-1].stop == hml.FEATURE_DIM == 263
    assert hml.FPS == 20


def test_split_parts_unflattens_joints():
    features = torch.arange(2 * 3 * 263, dtype=torch.float64).reshape(2, 3, 263)
    parts = hml.split_parts(features)
    assert parts.ric.shape == (2, 3, 21, 3) and parts.local_velocity.shape == (2, 3, 22, 3)
    assert parts.ric[1, 2, 0].tolist() == features[1, 2, 4:7].tolist()
    assert parts.rotations[0, 0, 20].tolist() == features[0, 0, 187:193].tolist()
    assert parts.foot_contacts[0, 1].tolist() == features[0, 1, 259:263].tolist()


def constant_turn(frames: int, half_turn: float, speed: float, height: float) -> torch.Tensor:
    features = torch.zeros(frames, 263, dtype=torch.float64)
    features[:, 0] = half_turn
    features[:, 2] = speed  # forward (+Z) in the heading frame
    features[:, 3] = height
    return features


def test_root_integrates_a_constant_turn_in_closed_form():
    """Angular channel c per frame: heading turned by -2 c t; the step of frame s - 1 is taken
    with the heading of frame s, so root(t) = sum_{s=1..t} speed * (-sin 2cs, 0, cos 2cs)."""
    c, speed, height = 0.05, 0.1, 0.9
    features = constant_turn(30, c, speed, height)
    root = hml.recover_root(features)
    for t in (0, 1, 2, 17, 29):
        expected_x = sum(-speed * math.sin(2 * c * s) for s in range(1, t + 1))
        expected_z = sum(speed * math.cos(2 * c * s) for s in range(1, t + 1))
        assert root.position[t].tolist() == pytest.approx([expected_x, height, expected_z])
        assert root.heading[t].tolist() == pytest.approx(
            [math.cos(c * t), 0.0, math.sin(c * t), 0.0]
        )


def test_ric_is_turned_back_and_shifted_by_the_root():
    c = 0.25
    features = constant_turn(3, c, 0.0, 1.0)
    features[:, 4:7] = torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64)  # joint 1: ahead (+Z)
    positions = hml.recover_from_ric(features)
    # Frame 2: heading maps world -> facing +Z with angle 2 * (2c) about +Y; its inverse turns
    # the forward offset (0, 0, 1) to (-sin 4c, 0, cos 4c).
    assert positions[2, 1].tolist() == pytest.approx([-math.sin(4 * c), 0.5, math.cos(4 * c)])
    assert positions[0, 1].tolist() == pytest.approx([0.0, 0.5, 1.0])
    torch.testing.assert_close(
        positions[:, 0], torch.tensor([[0.0, 1.0, 0.0]] * 3, dtype=torch.float64)
    )


def test_batched_and_dtypes_agree():
    generator = torch.Generator().manual_seed(3)
    features = torch.randn(2, 3, 40, 263, generator=generator, dtype=torch.float64) * 0.1
    batched = hml.recover_from_ric(features)
    assert batched.shape == (2, 3, 40, 22, 3) and batched.dtype == torch.float64
    torch.testing.assert_close(batched[1, 2], hml.recover_from_ric(features[1, 2]))
    single = hml.recover_from_ric(features.float())
    assert single.dtype == torch.float32
    torch.testing.assert_close(single.double(), batched, atol=1e-5, rtol=0)


@pytest.mark.parametrize("shape", [(263,), (10, 262)])
def test_rejects_wrong_shapes(shape):
    with pytest.raises(ValueError, match=r"recover_from_ric: expected shape \(\.\.\., T, 263\)"):
        hml.recover_from_ric(torch.zeros(shape))


def test_rejects_integer_features():
    with pytest.raises(ValueError, match="expected a float tensor"):
        hml.recover_from_ric(torch.zeros(4, 263, dtype=torch.int64))
