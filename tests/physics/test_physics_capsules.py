"""The capsule proxy: layout, radii table, height scaling, distances against numpy references."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from physics_builders import facing_pair, point_segment_distance

from intermask.motion.interhuman import yup_to_zup
from intermask.motion.skeleton import BONES, JOINT_NAMES, rest_pose_positions
from intermask.physics import (
    CAPSULE_NAMES,
    DEFAULT_RADII,
    PARTS,
    TEMPLATE_HEIGHT,
    BodyProxy,
    Capsules,
    body_capsules,
    capsule_distances,
    segment_distances,
    signed_distance,
    skeleton_height,
)


def _close(actual: torch.Tensor, expected: torch.Tensor) -> None:
    # numpy: torch.testing imports for seconds on first use; 2e-6 m covers the 1e-6 m norm floor
    np.testing.assert_allclose(
        actual.detach().numpy(), expected.detach().numpy(), rtol=1e-6, atol=2e-6
    )


CONFIG = Path(__file__).parents[2] / "configs" / "physics" / "capsules.yaml"


def test_layout_covers_every_bone_plus_torso_hands_and_head():
    joints = rest_pose_positions().double()
    caps = body_capsules(joints)
    assert caps.a.shape == caps.b.shape == (28, 3) and caps.radius.shape == (28,)
    ends = {(tuple(a.tolist()), tuple(b.tolist())) for a, b in zip(caps.a, caps.b, strict=True)}
    for parent, child in BONES:
        assert (tuple(joints[parent].tolist()), tuple(joints[child].tolist())) in ends
    named = dict(zip(CAPSULE_NAMES, zip(caps.a, caps.b, caps.radius, strict=True), strict=True))
    head_a, head_b, head_r = named["head"]
    neck, head = joints[JOINT_NAMES.index("neck")], joints[JOINT_NAMES.index("head")]
    _close(head_a, head_b)  # a sphere: a capsule of zero length
    _close(head_a, head + 0.5 * (head - neck))
    assert head_r.item() == pytest.approx(0.10)
    elbow, wrist = joints[JOINT_NAMES.index("l_elbow")], joints[JOINT_NAMES.index("l_wrist")]
    _close(named["hand_l"][1], wrist + 0.5 * (wrist - elbow))
    assert named["thigh_r"][2].item() == pytest.approx(DEFAULT_RADII["thigh"])


def test_batched_capsules_and_gradients_reach_the_joints():
    joints = rest_pose_positions().expand(4, 5, 22, 3).clone().requires_grad_(True)
    caps = body_capsules(joints)
    assert caps.a.shape == (4, 5, 28, 3) and caps.radius.shape == (28,)
    caps.b.sum().backward()
    assert joints.grad is not None and joints.grad.abs().sum() > 0


def test_height_scaling_multiplies_radii_per_frame():
    rest = rest_pose_positions().double()
    assert skeleton_height(rest).item() == pytest.approx(TEMPLATE_HEIGHT)
    joints = torch.stack((rest, 1.2 * rest, 0.8 * yup_to_zup(rest)))  # any up axis, any size
    assert skeleton_height(joints).tolist() == pytest.approx(
        [TEMPLATE_HEIGHT, 1.2 * TEMPLATE_HEIGHT, 0.8 * TEMPLATE_HEIGHT], rel=1e-6
    )
    caps = body_capsules(joints, BodyProxy(scale_with_height=True))
    base = body_capsules(rest).radius
    assert caps.radius.shape == (3, 28)
    _close(caps.radius, torch.stack((base, 1.2 * base, 0.8 * base)))


def test_config_table_is_the_code_default_and_instantiates():
    cfg = OmegaConf.load(CONFIG)
    assert dict(cfg.proxy.radii) == DEFAULT_RADII and set(cfg.proxy.radii) == set(PARTS)
    proxy = instantiate(cfg.proxy)
    assert isinstance(proxy, BodyProxy) and proxy.radii == DEFAULT_RADII
    assert cfg.loss.zeta == 0.5 and cfg.pitch == 0.01 and cfg.tolerance == 0.0


def test_sphere_distance_is_closed_form():
    centre = torch.tensor([[0.3, -0.2, 1.0]])
    sphere = Capsules(centre, centre.clone(), torch.tensor([0.1]))
    points = torch.tensor([[0.3, -0.2, 1.0], [0.3, 0.3, 1.0], [1.3, -0.2, 1.0]])
    _close(capsule_distances(points, sphere)[:, 0], torch.tensor([-0.1, 0.4, 0.9]))


def test_signed_distance_matches_dense_segment_sampling():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    b[2] = a[2]  # one sphere
    radius = rng.uniform(0.05, 0.3, size=6)
    points = rng.normal(size=(40, 3)) * 1.5
    expected = point_segment_distance(points, a, b) - radius  # (N, K)
    caps = Capsules(torch.tensor(a), torch.tensor(b), torch.tensor(radius))
    got = capsule_distances(torch.tensor(points), caps)
    np.testing.assert_allclose(got.numpy(), expected, atol=2e-4)
    np.testing.assert_allclose(
        signed_distance(torch.tensor(points), caps).numpy(), expected.min(-1), atol=2e-4
    )


def _exact_point_segment(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    t = np.clip((points - a) @ (b - a) / max(float((b - a) @ (b - a)), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - a - t[:, None] * (b - a), axis=-1)


def test_segment_distances_match_brute_force_including_parallel_and_points():
    rng = np.random.default_rng(1)
    a1, b1, a2, b2 = (rng.normal(size=(8, 3)) for _ in range(4))
    b1[1] = a1[1]  # point vs segment
    b1[2], b2[2] = a1[2], a2[2]  # point vs point
    b2[3] = a2[3] + 2 * (b1[3] - a1[3])  # parallel segments
    a1[4], b1[4] = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]  # parallel and overlapping, 0.3 apart
    a2[4], b2[4] = [0.5, 0.3, 0.0], [1.5, 0.3, 0.0]
    s = np.linspace(0.0, 1.0, 20001)
    expected = [
        _exact_point_segment(a1[k] + s[:, None] * (b1[k] - a1[k]), a2[k], b2[k]).min()
        for k in range(8)
    ]
    got = segment_distances(*(torch.tensor(x) for x in (a1, b1, a2, b2)))
    np.testing.assert_allclose(got.numpy(), expected, atol=2e-4)
    assert got[4].item() == pytest.approx(0.3, abs=1e-9)


def test_distances_do_not_depend_on_the_up_axis():
    a, b = facing_pair(0.3)
    points = b[0]
    yup = signed_distance(points, body_capsules(a[0]))
    zup = signed_distance(yup_to_zup(points), body_capsules(yup_to_zup(a[0])))
    _close(yup, zup)


def test_gradient_is_finite_on_a_capsule_axis():
    caps = body_capsules(rest_pose_positions())
    point = caps.a[5:6].clone().requires_grad_(True)  # exactly on an axis
    signed_distance(point, caps).sum().backward()
    assert torch.isfinite(point.grad).all()


def test_errors_name_the_problem():
    with pytest.raises(
        ValueError,
        match=r"body_capsules: expected joints of shape \(\.\.\., 22, 3\), got \(4, 21, 3\)",
    ):
        body_capsules(torch.zeros(4, 21, 3))
    with pytest.raises(ValueError, match="must be a floating-point tensor"):
        body_capsules(torch.zeros(22, 3, dtype=torch.long))
    radii = dict(DEFAULT_RADII)
    del radii["head"]
    radii["tail"] = 0.1
    with pytest.raises(ValueError, match=r"missing \['head'\], unknown \['tail'\]"):
        BodyProxy(radii=radii)
    with pytest.raises(ValueError, match=r"radii must be >= 0 metres, got \{'hand': -0.01\}"):
        BodyProxy(radii={**DEFAULT_RADII, "hand": -0.01})
    with pytest.raises(ValueError, match="radii must be >= 0 metres"):
        BodyProxy(radii={**DEFAULT_RADII, "hand": math.nan})
    with pytest.raises(ValueError, match="hand_extension and head_offset must be >= 0"):
        BodyProxy(hand_extension=-1.0)
    with pytest.raises(ValueError, match=r"points must be \(\.\.\., N, 3\), got \(5, 2\)"):
        capsule_distances(torch.zeros(5, 2), body_capsules(rest_pose_positions()))


def test_signed_distance_has_the_value_and_gradient_of_a_min_over_capsules():
    a, b = facing_pair(0.2, frames=3)
    caps = body_capsules(a.requires_grad_(True), BodyProxy(scale_with_height=True))
    points = b.clone().requires_grad_(True)
    fast = signed_distance(points, caps)
    dense = capsule_distances(points, caps).amin(-1)
    assert torch.equal(fast, dense)
    grads = [torch.autograd.grad(d.sum(), (points, a), retain_graph=True) for d in (fast, dense)]
    for got, expected in zip(*grads, strict=True):
        _close(got, expected)
