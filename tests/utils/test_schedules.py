import math

import pytest

from intermask.utils.schedules import check_lr_decay, warmup_schedule_factor


def test_vq_schedule_warms_up_over_a_quarter_then_steps_down_twice():
    factor = lambda step: warmup_schedule_factor(  # noqa: E731
        step, total_steps=1000, warmup_fraction=0.25, milestones=(0.7, 0.85), gamma=0.1
    )
    assert factor(0) == pytest.approx(1 / 250)
    assert factor(124) == pytest.approx(0.5)
    assert factor(249) == pytest.approx(1.0)
    assert factor(250) == 1.0 and factor(699) == 1.0
    assert factor(700) == pytest.approx(0.1) and factor(849) == pytest.approx(0.1)
    assert factor(850) == pytest.approx(0.01) and factor(999) == pytest.approx(0.01)


def test_generator_schedule_divides_by_three_at_each_milestone():
    factors = [
        warmup_schedule_factor(
            s, total_steps=100, warmup_fraction=0.0, milestones=(0.5, 0.7, 0.85), gamma=1 / 3
        )
        for s in (0, 49, 50, 70, 85, 99)
    ]
    assert factors == pytest.approx([1, 1, 1 / 3, 1 / 9, 1 / 27, 1 / 27])


def test_total_steps_must_be_positive():
    with pytest.raises(ValueError, match="total_steps must be positive, got 0"):
        warmup_schedule_factor(0, total_steps=0, warmup_fraction=0.25, milestones=(), gamma=0.1)


def _smooth(step: int, decay: str, final: float = 0.0) -> float:
    return warmup_schedule_factor(
        step,
        total_steps=110,
        warmup_fraction=10 / 110,
        milestones=(),
        gamma=1.0,
        decay=decay,
        final=final,
    )


def test_cosine_decay_runs_half_a_cosine_from_the_warm_up_to_the_floor():
    assert _smooth(4, "cosine") == pytest.approx(0.5)  # still warming up
    assert _smooth(10, "cosine") == pytest.approx(1.0)
    assert _smooth(35, "cosine") == pytest.approx(0.5 * (1 + math.cos(math.pi / 4)))
    assert _smooth(60, "cosine") == pytest.approx(0.5)
    assert _smooth(110, "cosine") == pytest.approx(0.0)
    assert _smooth(60, "cosine", final=0.1) == pytest.approx(0.55)
    assert _smooth(110, "cosine", final=0.1) == pytest.approx(0.1)


def test_linear_decay_is_a_straight_line_to_the_floor():
    assert [_smooth(s, "linear") for s in (10, 35, 60, 85, 110)] == pytest.approx(
        [1, 0.75, 0.5, 0.25, 0]
    )
    assert _smooth(60, "linear", final=0.2) == pytest.approx(0.6)
    assert _smooth(500, "linear", final=0.2) == pytest.approx(
        0.2
    )  # past the end: stays at the floor


@pytest.mark.parametrize(
    ("decay", "milestones", "final", "message"),
    [
        ("step", (), 0.0, "lr_decay must be one of multistep, cosine, linear, got 'step'"),
        (
            "cosine",
            (0.5,),
            0.0,
            r"lr_decay='cosine' decays smoothly .* \(got \[0.5\]\); set lr_milestones to \[\]",
        ),
        (
            "linear",
            (),
            1.5,
            r"lr_final must lie in \[0, 1\] \(a fraction of the base rate\), got 1.5",
        ),
    ],
)
def test_decay_settings_that_disagree_are_refused(decay, milestones, final, message):
    with pytest.raises(ValueError, match=message):
        check_lr_decay(decay, milestones, final)
    with pytest.raises(ValueError, match=message):
        warmup_schedule_factor(
            0,
            total_steps=10,
            warmup_fraction=0.0,
            milestones=milestones,
            gamma=1.0,
            decay=decay,
            final=final,
        )


def test_multistep_ignores_the_floor():
    factor = warmup_schedule_factor(
        9, total_steps=10, warmup_fraction=0.0, milestones=(0.5,), gamma=0.1, final=0.5
    )
    assert factor == pytest.approx(0.1)
