import numpy as np
import pytest
import torch
from mesh_builders import box_mesh, uv_sphere, winding_numbers
from physics_builders import lens_volume

from intermask.body.model import full_rotations, load_body_model
from intermask.body.standin import write_standin_model
from intermask.metrics.penetration import MeshIntersectionFrequency, MeshIntersectionVolume
from intermask.motion.rotations import rotation_about_axis
from intermask.physics.mesh_volume import mesh_intersection_volume, mesh_shared_voxel_counts


@pytest.mark.parametrize("gap", [0.1, 0.15, 0.19])
def test_two_spheres_match_the_lens_volume(gap):
    sphere, faces = uv_sphere(0.1)
    other, _ = uv_sphere(0.1, (gap, 0.003, 0.001))
    volume = mesh_intersection_volume(sphere[None], other[None], faces, pitch=0.0025)
    # the polyhedral sphere is a little smaller than the ball
    assert float(volume) == pytest.approx(lens_volume(0.1, 0.1, gap) * 1e6, rel=0.03, abs=1.0)


def test_boxes_are_exact_and_order_free():
    a, fa = box_mesh((0.0, 0.0, 0.0), (0.2, 0.2, 0.2))
    b, fb = box_mesh((0.1, 0.05, 0.1), (0.3, 0.3, 0.3))
    forward = mesh_intersection_volume(a[None], b[None], fa, fb, pitch=0.01)
    backward = mesh_intersection_volume(b[None], a[None], fb, fa, pitch=0.01)
    assert float(forward) == float(backward) == pytest.approx(0.1 * 0.15 * 0.1 * 1e6)
    apart, _ = box_mesh((0.5, 0.0, 0.0), (0.7, 0.2, 0.2))
    assert float(mesh_intersection_volume(a[None], apart[None], fa, fb)) == 0.0


def test_a_mesh_through_itself_counts_once():
    """Two overlapping spheres in one mesh (a hand inside a torso): their union, not parity."""
    first, faces = uv_sphere(0.1, rings=24, segments=48)
    second, _ = uv_sphere(0.1, (0.05, 0.0, 0.0), rings=24, segments=48)
    union = torch.cat((first, second))
    union_faces = torch.cat((faces, faces + len(first)))
    box, box_faces = box_mesh((-0.2, -0.2, -0.2), (0.3, 0.2, 0.2))  # holds both spheres
    inside_box = mesh_intersection_volume(
        union[None], box[None], union_faces, box_faces, pitch=0.01
    )
    alone = mesh_intersection_volume(first[None], box[None], faces, box_faces, pitch=0.01)
    lens = mesh_intersection_volume(first[None], second[None], faces, faces, pitch=0.01)
    assert float(inside_box) == pytest.approx(2 * float(alone) - float(lens), rel=1e-6)


@pytest.fixture(scope="module")
def standin(tmp_path_factory):
    return load_body_model(
        write_standin_model(tmp_path_factory.mktemp("standin"), "smplx"), dtype=torch.float64
    )


def test_bodies_agree_with_a_voxel_by_voxel_winding_number(standin):
    """Two stand-in bodies reaching into each other: the column count equals testing every
    voxel centre of the box overlap with the generalised winding number."""

    def angle(value: float) -> torch.Tensor:
        return torch.tensor(value, dtype=torch.float64)

    body = torch.eye(3, dtype=torch.float64).expand(22, 3, 3).clone()
    body[16], body[17] = rotation_about_axis(angle(-1.3), "z"), rotation_about_axis(angle(1.3), "z")
    other = body.clone()  # arms down (narrow boxes keep the reference test short), turned round
    other[0] = rotation_about_axis(angle(torch.pi), "y")
    other[17] = rotation_about_axis(angle(-1.2), "x") @ other[17]  # its right arm reaches forward
    betas = torch.zeros(1, 10, dtype=torch.float64)
    a, _ = standin.pose(
        betas, full_rotations(standin, body)[None], torch.zeros(1, 3, dtype=torch.float64)
    )
    b, _ = standin.pose(
        betas,
        full_rotations(standin, other)[None],
        torch.tensor([[0.05, 0.0, 0.1]], dtype=torch.float64),
    )
    pitch = 0.04
    counted = int(mesh_shared_voxel_counts(a, standin.faces, b, standin.faces, pitch=pitch)[0])
    low = torch.maximum(a[0].amin(0), b[0].amin(0)).numpy()
    high = torch.minimum(a[0].amax(0), b[0].amax(0)).numpy()
    axes = [
        (np.arange(np.ceil(lo / pitch - 0.5), np.floor(hi / pitch - 0.5) + 1) + 0.5) * pitch
        for lo, hi in zip(low, high, strict=True)
    ]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    faces = standin.faces.numpy()
    inside = [
        np.concatenate(
            [
                winding_numbers(chunk, mesh[0].numpy(), faces)
                for chunk in np.array_split(centres, 40)
            ]
        )
        > 0.5
        for mesh in (a, b)
    ]
    assert counted > 20
    assert counted == int((inside[0] & inside[1]).sum())


def test_mesh_metrics_accumulate_frames(standin):
    sphere, faces = uv_sphere(0.1, rings=16, segments=32)
    a = torch.stack((sphere, sphere + 1.0))[None]  # (1, 2 frames, V, 3): touching, then apart
    b = torch.stack((sphere + torch.tensor([0.15, 0.0, 0.0], dtype=torch.float64), sphere))[None]
    volumes = mesh_intersection_volume(a, b, faces)
    assert volumes.shape == (1, 2) and volumes[0, 0] > 0 and volumes[0, 1] == 0
    iv, frequency = MeshIntersectionVolume(), MeshIntersectionFrequency()
    for metric in (iv, frequency):
        metric.update(a, b, faces)
    assert float(iv.compute()) == pytest.approx(float(volumes.mean()))
    assert float(frequency.compute()) == 0.5
    masked = mesh_intersection_volume(a, b, faces, frame_mask=torch.tensor([[False, True]]))
    assert masked.tolist() == [[0.0, 0.0]]


def test_mesh_volume_rejects_bad_input():
    sphere, faces = uv_sphere(0.1, rings=8, segments=8)
    with pytest.raises(ValueError, match=r"body a: faces index vertices outside \[0, 58\)"):
        mesh_intersection_volume(sphere[None], sphere[None], faces + 100, faces)
    with pytest.raises(ValueError, match="the two bodies need the same leading shape"):
        mesh_intersection_volume(sphere[None], sphere[None].expand(2, -1, -1), faces)
    with pytest.raises(ValueError, match="pitch must be > 0"):
        mesh_intersection_volume(sphere[None], sphere[None], faces, pitch=0.0)
