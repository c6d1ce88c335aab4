import pytest
import torch

from intermask.vq.convolutions import MotionDecoder, MotionEncoder

INTERHUMAN = dict(
    num_joints=22, channels=12, joint_kernel=4, joint_stride=2, joint_scales=(2.2, 2.0)
)
INTERX = dict(num_joints=56, channels=6, joint_kernel=6, joint_stride=3, joint_scales=(3.5, 3.3))


def _build(spec, width=32, layout="2d"):
    encoder = MotionEncoder(
        num_joints=spec["num_joints"],
        in_channels=spec["channels"],
        width=width,
        joint_kernel=spec["joint_kernel"],
        joint_stride=spec["joint_stride"],
        layout=layout,
    )
    decoder = MotionDecoder(
        num_joints=spec["num_joints"],
        out_channels=spec["channels"],
        width=width,
        joint_scales=spec["joint_scales"],
        layout=layout,
    )
    return encoder, decoder


@pytest.mark.parametrize("spec", [INTERHUMAN, INTERX], ids=["interhuman", "interx"])
@pytest.mark.parametrize("frames", [16, 64, 300])
def test_token_grid_is_five_rows_by_a_quarter_of_the_frames(spec, frames):
    encoder, decoder = _build(spec)
    x = torch.randn(2, frames, spec["num_joints"], spec["channels"])
    latent = encoder(x)
    assert latent.shape == (2, 32, 5, frames // 4)
    assert decoder(latent).shape == x.shape


def test_one_dimensional_ablation_has_one_row():
    encoder, decoder = _build(INTERHUMAN, layout="1d")
    latent = encoder(torch.randn(3, 64, 22, 12))
    assert latent.shape == (3, 32, 1, 16)
    assert decoder(latent).shape == (3, 64, 22, 12)


@pytest.mark.parametrize(("spec", "expected_millions"), [(INTERHUMAN, 41.28), (INTERX, 45.42)])
def test_paper_configuration_parameter_count(spec, expected_millions):
    encoder, decoder = _build(spec, width=512)
    total = sum(p.numel() for module in (encoder, decoder) for p in module.parameters())
    assert total / 1e6 == pytest.approx(expected_millions, abs=0.01)  # paper: ~41.3M / ~45.4M


def test_encoder_is_local_in_time():
    """A change at the last frames must not reach the first tokens (receptive field is finite)."""
    encoder, _ = _build(INTERHUMAN)
    encoder.eval()
    x = torch.randn(1, 64, 22, 12)
    y = x.clone()
    y[:, -8:] += 5.0
    torch.testing.assert_close(encoder(x)[..., :4], encoder(y)[..., :4])


def test_inconsistent_joint_scales_are_rejected():
    with pytest.raises(
        ValueError, match=r"joint_scales \(2.0, 2.0\) take 5 latent rows to 20 joints, expected 22"
    ):
        MotionDecoder(num_joints=22, out_channels=12, width=8, joint_scales=(2.0, 2.0))
