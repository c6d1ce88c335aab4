import math
from dataclasses import fields

import pytest
import torch

from intermask.motion import interhuman as ih
from intermask.motion.rotations import matrix_to_rot6d, rot6d_to_matrix, rotation_about_axis
from intermask.motion.skeleton import JOINT_NAMES, REST_OFFSETS
from intermask.vq.convolutions import MotionDecoder, MotionEncoder
from intermask.vq.losses import PELVIS_RELATIVE_TERMS, LossTerms, LossWeights, vq_losses
from intermask.vq.model import MotionVQVAE
from intermask.vq.quantizers import ResidualQuantizer
from intermask.vq.views import InterHumanView, InterXView


def _interhuman_vq(layers=2, width=16):
    view = InterHumanView(mean=torch.zeros(262), std=torch.ones(262))
    return MotionVQVAE(
        view=view,
        encoder=MotionEncoder(num_joints=22, in_channels=12, width=width),
        quantizer=ResidualQuantizer(num_quantizers=layers, codebook_size=32, dim=width),
        decoder=MotionDecoder(num_joints=22, out_channels=12, width=width),
    )


def test_encode_decode_shapes_and_consistency_with_forward():
    torch.manual_seed(0)
    model = _interhuman_vq()
    features = torch.randn(3, 64, 262)
    model.train()(features)  # initialise the codebooks
    model.eval()
    out = model(features)
    tokens = model.encode(features)
    assert tokens.shape == (3, 2, 5, 16) and tokens.dtype == torch.long
    assert torch.equal(tokens, out.indices)
    decoded = model.decode(tokens)
    assert decoded.shape == (3, 64, 262)
    torch.testing.assert_close(decoded, out.reconstruction)
    assert torch.all(decoded[..., ih.CONTACTS] == 0)


def test_encode_marks_token_steps_beyond_the_length_as_padding():
    model = _interhuman_vq().eval()
    tokens = model.encode(torch.randn(2, 64, 262), lengths=torch.tensor([64, 30]))
    assert (tokens[0] >= 0).all()
    assert (tokens[1, ..., :7] >= 0).all() and (tokens[1, ..., 7:] == -1).all()  # 30 // 4 = 7 steps


def test_decode_valid_decodes_each_sample_as_it_would_alone():
    torch.manual_seed(0)
    model = _interhuman_vq(layers=1)
    model.train()(torch.randn(4, 64, 262))  # initialise the codebook
    model.eval()
    tokens = model.encode(torch.randn(3, 64, 262), lengths=torch.tensor([64, 30, 44]))
    decoded = model.decode_valid(tokens)
    assert decoded.shape == (3, 64, 262)
    for sample, steps in enumerate((16, 7, 11)):
        alone = model.decode(tokens[sample : sample + 1, ..., :steps])[0]
        torch.testing.assert_close(decoded[sample, : 4 * steps], alone, rtol=0, atol=1e-6)
        assert torch.all(decoded[sample, 4 * steps :] == 0)
    # the old way, the padding decoded as code 0, moves the last valid frames of a short sample
    padded = model.decode(tokens.clamp_min(0))
    assert (padded[1, 24:28] - decoded[1, 24:28]).abs().max() > 1e-3
    # a batch without padding is decoded as one
    full = tokens[:1].expand(2, -1, -1, -1)
    torch.testing.assert_close(model.decode_valid(full), model.decode(full), rtol=0, atol=0)


def test_decode_valid_refuses_padding_that_is_not_at_the_end():
    model = _interhuman_vq(layers=1).eval()
    tokens = model.encode(torch.randn(2, 32, 262))
    gap = tokens.clone()
    gap[1, 0, :, 3] = -1
    with pytest.raises(ValueError, match="must fill the last steps of every row"):
        model.decode_valid(gap)
    ragged = tokens.clone()
    ragged[1, 0, 2, 6:] = -1  # one row of the sample shorter than the others
    with pytest.raises(ValueError, match="must fill the last steps of every row"):
        model.decode_valid(ragged)
    empty = torch.full_like(tokens, -1)
    with pytest.raises(ValueError, match="every sample of the batch is padding"):
        model.decode_valid(empty)
    one_empty = tokens.clone()
    one_empty[1] = -1  # a sample of padding only decodes to 0 beside a real one
    decoded = model.decode_valid(one_empty)
    torch.testing.assert_close(decoded[0], model.decode(tokens[:1])[0], rtol=0, atol=1e-6)
    assert torch.all(decoded[1] == 0)


def test_encode_never_updates_the_codebook_even_in_train_mode():
    model = _interhuman_vq()
    features = torch.randn(2, 16, 262)
    model.train()(features)
    before = model.quantizer.layers[0].codebook.clone()
    model.encode(features)
    assert torch.equal(model.quantizer.layers[0].codebook, before)


def test_frames_must_be_a_multiple_of_four():
    with pytest.raises(ValueError, match="multiple of 4 frames, got 30"):
        _interhuman_vq()(torch.randn(1, 30, 262))


def _geometry_pair():
    torch.manual_seed(1)
    view = InterHumanView(mean=torch.zeros(262), std=torch.ones(262))
    target = torch.randn(2, 8, 262)
    target[..., ih.CONTACTS] = 0.0  # random positions slide: no foot is planted
    return view, target


def _losses(
    view,
    prediction,
    target,
    *,
    frame_mask=None,
    commit=0.0,
    kind="smooth_l1",
    weights=None,
    measure_unweighted=True,
):
    if frame_mask is None:
        frame_mask = torch.ones(target.shape[:2], dtype=torch.bool)
    return vq_losses(
        prediction=prediction,
        target=target,
        predicted_geometry=view.geometry(prediction),
        target_geometry=view.geometry(target),
        reconstruction_mask=view.reconstruction_mask(target.device),
        frame_mask=frame_mask,
        commit_loss=torch.tensor(commit),
        weights=weights or LossWeights(),
        kind=kind,
        measure_unweighted=measure_unweighted,
    )


def test_losses_vanish_on_a_perfect_reconstruction():
    view, target = _geometry_pair()
    terms = _losses(view, target, target, commit=0.5)
    assert (
        terms.reconstruction == 0
        and terms.positions == 0
        and terms.velocity == 0
        and terms.bone_length == 0
    )
    assert terms.geodesic.abs() < 1e-3
    assert terms.total == pytest.approx(0.02 * 0.5 + 0.01 * terms.geodesic.item())


def test_geometric_terms_measure_what_they_claim():
    view, target = _geometry_pair()
    prediction = target.clone()
    # shift every position by 1 cm on x: positions error 0.01, velocity 0, bones 0
    prediction[..., ih.POSITIONS] += torch.tensor([0.01, 0.0, 0.0]).repeat(22)
    # turn every joint rotation by 0.1 rad about y: geodesic 0.1
    turn = rotation_about_axis(torch.tensor(0.1), "y")
    base = rot6d_to_matrix(ih.split_features(target).rot6d)
    prediction[..., ih.ROTATIONS] = matrix_to_rot6d(turn @ base).flatten(-2)
    terms = _losses(view, prediction, target, kind="l1")
    assert terms.positions.item() == pytest.approx(
        0.01 / 3, rel=1e-4
    )  # one of three axes off by 1 cm
    assert terms.velocity.item() == pytest.approx(0.0, abs=1e-6)
    assert terms.bone_length.item() == pytest.approx(0.0, abs=1e-6)
    assert terms.geodesic.item() == pytest.approx(0.1, abs=1e-4)


def test_a_geodesic_term_of_weight_zero_is_measured_without_a_graph_or_skipped():
    view, target = _geometry_pair()
    turn = rotation_about_axis(torch.tensor(0.1), "y")
    turned = target.clone()
    turned[..., ih.ROTATIONS] = matrix_to_rot6d(
        turn @ rot6d_to_matrix(ih.split_features(target).rot6d)
    ).flatten(-2)
    prediction = turned.clone().requires_grad_(True)
    no_geodesic = LossWeights(geodesic=0.0)
    measured = _losses(view, prediction, target, weights=no_geodesic)
    assert measured.geodesic.item() == pytest.approx(0.1, abs=1e-4)
    assert not measured.geodesic.requires_grad  # only the weighted terms build a graph
    assert measured.total.requires_grad
    weighted = _losses(view, prediction, target)
    assert weighted.geodesic.requires_grad
    assert weighted.total.item() == pytest.approx(measured.total.item() + 0.01 * 0.1, abs=1e-5)
    skipped = _losses(view, prediction, target, weights=no_geodesic, measure_unweighted=False)
    assert skipped.geodesic.item() == 0.0
    assert skipped.total.item() == pytest.approx(measured.total.item())


def test_arms_term_measures_elbows_and_wrists_relative_to_the_pelvis():
    view, target = _geometry_pair()
    prediction = target.clone()
    positions = prediction[..., ih.POSITIONS].reshape(2, 8, 22, 3)
    positions[..., :, 0] += 0.5  # the whole body moved: nothing changes relative to the pelvis
    positions[..., 21, 1] += 0.02  # the right wrist 2 cm higher
    prediction[..., ih.POSITIONS] = positions.flatten(-2)
    off = _losses(view, prediction, target, kind="l1")
    # one joint of the four arm joints, one axis of three
    assert off.arms.item() == pytest.approx(0.02 / 12, rel=1e-4)
    weighted = _losses(view, prediction, target, kind="l1", weights=LossWeights(arms=10.0))
    assert weighted.total.item() == pytest.approx(
        off.total.item() + 10.0 * off.arms.item(), rel=1e-5
    )
    assert _losses(view, target, target).arms.item() == 0.0


def test_torso_term_measures_the_upper_spine_neck_and_head_relative_to_the_pelvis():
    view, target = _geometry_pair()
    prediction = target.clone()
    positions = prediction[..., ih.POSITIONS].reshape(2, 8, 22, 3)
    positions[..., :, 2] -= 0.3  # the whole body moved: nothing changes relative to the pelvis
    positions[..., JOINT_NAMES.index("head"), 2] += 0.06  # the head 6 cm forward: a bow
    positions[..., JOINT_NAMES.index("r_wrist"), 1] += 0.02  # an arm joint: not the torso's
    prediction[..., ih.POSITIONS] = positions.flatten(-2)
    off = _losses(view, prediction, target, kind="l1")
    # one joint of the three torso joints, one axis of three
    assert off.torso.item() == pytest.approx(0.06 / 9, rel=1e-4)
    assert off.arms.item() == pytest.approx(0.02 / 12, rel=1e-4)
    assert not off.torso.requires_grad  # weight 0: measured without a graph
    weighted = _losses(view, prediction, target, kind="l1", weights=LossWeights(torso=20.0))
    assert weighted.total.item() == pytest.approx(
        off.total.item() + 20.0 * off.torso.item(), rel=1e-5
    )
    skipped = _losses(view, prediction, target, kind="l1", measure_unweighted=False)
    assert (skipped.torso.item(), skipped.arms.item()) == (0.0, 0.0)
    assert _losses(view, target, target).torso.item() == 0.0


def test_every_pelvis_relative_term_is_a_weight_and_a_logged_term_of_its_own_joints():
    weights = {field.name for field in fields(LossWeights)}
    for name, joints in PELVIS_RELATIVE_TERMS.items():
        assert name in weights and name in LossTerms._fields, name
        assert 0 not in joints, name  # never the pelvis itself: the terms are relative to it
    # the joint sets are disjoint: a joint weighed twice would be a term's share counted twice
    every = [joint for joints in PELVIS_RELATIVE_TERMS.values() for joint in joints]
    assert len(every) == len(set(every)) == 11
    assert list(PELVIS_RELATIVE_TERMS) == ["arms", "torso", "legs"]  # the order of the sum


def test_legs_term_measures_the_knees_and_ankles_relative_to_the_pelvis():
    view, target = _geometry_pair()
    prediction = target.clone()
    positions = prediction[..., ih.POSITIONS].reshape(2, 8, 22, 3)
    positions[..., :, 1] += 0.4  # the whole body lifted: nothing changes relative to the pelvis
    positions[..., JOINT_NAMES.index("r_ankle"), 1] += 0.12  # the right ankle 12 cm up: a kick
    positions[..., JOINT_NAMES.index("head"), 2] += 0.03  # a torso joint: not the legs'
    prediction[..., ih.POSITIONS] = positions.flatten(-2)
    off = _losses(view, prediction, target, kind="l1")
    # one joint of the four leg joints, one axis of three
    assert off.legs.item() == pytest.approx(0.12 / 12, rel=1e-4)
    assert off.torso.item() == pytest.approx(0.03 / 9, rel=1e-4)
    assert off.arms.item() == pytest.approx(0.0, abs=1e-7)  # float32 rounding of the lift
    assert not off.legs.requires_grad  # weight 0: measured without a graph
    weighted = _losses(view, prediction, target, kind="l1", weights=LossWeights(legs=20.0))
    assert weighted.total.item() == pytest.approx(
        off.total.item() + 20.0 * off.legs.item(), rel=1e-5
    )
    skipped = _losses(view, prediction, target, kind="l1", measure_unweighted=False)
    assert skipped.legs.item() == 0.0
    assert _losses(view, target, target).legs.item() == 0.0


def test_foot_contact_penalises_sliding_planted_feet_only():
    view, target = _geometry_pair()
    target[..., ih.POSITIONS] = 0.0
    target[..., ih.CONTACTS] = torch.tensor([1.0, 0.0, 0.0, 0.0])  # only the left ankle is planted
    prediction = target.clone()
    frames = torch.arange(8.0)[None, :, None]
    positions = prediction[..., ih.POSITIONS].reshape(2, 8, 22, 3)
    positions[..., 7, 0] = 0.01 * frames[..., 0]  # left ankle slides 1 cm per frame
    positions[..., 8, 0] = 0.01 * frames[..., 0]  # right ankle too, but it is not planted
    prediction[..., ih.POSITIONS] = positions.flatten(-2)
    mask = torch.ones(2, 8, dtype=torch.bool)
    terms = _losses(view, prediction, target, frame_mask=mask, kind="l1")
    # one planted joint of 4, one axis of 3, 1 cm per step
    assert terms.foot_contact.item() == pytest.approx(0.01 / 12, rel=1e-4)


def test_padding_frames_do_not_count():
    view, target = _geometry_pair()
    prediction = target.clone()
    prediction[:, 4:] += 10.0
    mask = torch.zeros(2, 8, dtype=torch.bool)
    mask[:, :4] = True
    terms = _losses(view, prediction, target, frame_mask=mask)
    assert terms.reconstruction == 0 and terms.positions == 0 and terms.velocity == 0


def test_interx_view_without_body_model_has_no_positions():
    view = InterXView()
    features = torch.randn(2, 8, 56, 6)
    geometry = view.geometry(features)
    assert (
        geometry.positions is None
        and geometry.contacts is None
        and geometry.rot6d.shape == (2, 8, 55, 6)
    )
    with_body = InterXView(body_offsets=REST_OFFSETS).geometry(features)
    assert with_body.positions.shape == (2, 8, 22, 3) and with_body.contacts.shape == (2, 8, 4)
    assert not math.isnan(with_body.positions.sum().item())


def test_interaction_level_vq_shares_one_token_grid_between_persons():
    view = InterHumanView(mean=torch.zeros(262), std=torch.ones(262))
    model = MotionVQVAE(
        view=view,
        encoder=MotionEncoder(num_joints=22, in_channels=24, width=16),
        quantizer=ResidualQuantizer(num_quantizers=1, codebook_size=32, dim=16),
        decoder=MotionDecoder(num_joints=22, out_channels=24, width=16),
        persons=2,
    )
    pair = torch.randn(2, 16, 2, 262)
    pair[..., ih.CONTACTS] = 0.0
    joints = model.view.to_joints(pair)
    assert joints.shape == (2, 16, 22, 24)
    torch.testing.assert_close(joints[..., :12], ih.features_to_joint_view(pair[:, :, 0]))
    back = model.view.from_joints(joints)
    kept = torch.ones(262, dtype=torch.bool)
    kept[ih.CONTACTS] = False
    torch.testing.assert_close(back[..., kept], pair[..., kept])
    out = model.train()(pair)
    assert out.reconstruction.shape == pair.shape and out.indices.shape == (2, 1, 5, 4)
    assert model.view.split_persons(pair).shape == (4, 16, 262)


def test_encoder_channels_must_match_the_view():
    with pytest.raises(
        ValueError, match=r"encoder takes 22 joints x 12 channels, the 2-person view gives 22 x 24"
    ):
        MotionVQVAE(
            view=InterHumanView(),
            encoder=MotionEncoder(num_joints=22, in_channels=12, width=8),
            quantizer=ResidualQuantizer(codebook_size=4, dim=8),
            decoder=MotionDecoder(num_joints=22, out_channels=12, width=8),
            persons=2,
        )
