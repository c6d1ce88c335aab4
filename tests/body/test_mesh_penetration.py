import pytest
import torch
from body_builders import known_params
from test_fit import interhuman_features

from intermask.body.export import body_vertices
from intermask.body.penetration import MeshPenetration, pad_with_last_frame
from intermask.physics.mesh_volume import mesh_intersection_volume


def test_padding_repeats_each_sample_last_valid_frame():
    x = torch.arange(2 * 1 * 4, dtype=torch.float64).reshape(2, 1, 4, 1)
    padded = pad_with_last_frame(x, torch.tensor([2, 4]))
    assert padded[:, 0, :, 0].tolist() == [[0.0, 1.0, 1.0, 1.0], [4.0, 5.0, 6.0, 7.0]]


def test_batches_of_interactions_give_the_mesh_volume_of_their_valid_frames(smplx_model):
    """Two interactions of different lengths, fitted in one batch: the accumulated IV is the mesh
    IV of the known bodies over the valid frames (the fit is exact to a fraction of a mm)."""
    truth = known_params(12)
    # the mean shape: some stand-in shape directions move no joint, and a fit leaves those at 0
    truth = truth._replace(
        betas=torch.zeros_like(truth.betas),
        transl=truth.transl * torch.tensor([0.3, 1.0, 0.3], dtype=torch.float64),  # closer
    )
    joints = smplx_model.body_joints(truth.betas, truth.rotations, truth.transl)  # (2, 12, 22, 3)
    features = interhuman_features(joints, truth.rotations)
    batch_joints = torch.stack((joints, joints))  # (B=2, 2, 12, 22, 3)
    batch_features = torch.stack((features, features))
    lengths = torch.tensor([12, 7])
    measure = MeshPenetration(smplx_model, pitch=0.02, fit_samples=2)
    measure.update(batch_joints, batch_features, lengths)
    known = body_vertices(smplx_model, truth._replace(hands=None))
    volume = mesh_intersection_volume(known[0], known[1], smplx_model.faces, pitch=0.02)
    expected = torch.cat((volume, volume[:7]))
    values = measure.compute()
    assert values["mesh_iv_cm3"] == pytest.approx(float(expected.mean()), rel=0.05, abs=8.0)
    assert values["mesh_if"] == pytest.approx(float((expected > 0).double().mean()), abs=0.1)
    assert values["mesh_fit_error_mm"] < 1.0
    measure.reset()
    with pytest.raises(ValueError, match="before any valid frame"):
        measure.compute()
