import pytest

from intermask.utils.schedules import warmup_multistep_factor


def test_vq_schedule_warms_up_over_a_quarter_then_steps_down_twice():
    factor = lambda step: warmup_multistep_factor(  # noqa: E731
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
        warmup_multistep_factor(
            s, total_steps=100, warmup_fraction=0.0, milestones=(0.5, 0.7, 0.85), gamma=1 / 3
        )
        for s in (0, 49, 50, 70, 85, 99)
    ]
    assert factors == pytest.approx([1, 1, 1 / 3, 1 / 9, 1 / 27, 1 / 27])


def test_total_steps_must_be_positive():
    with pytest.raises(ValueError, match="total_steps must be positive, got 0"):
        warmup_multistep_factor(0, total_steps=0, warmup_fraction=0.25, milestones=(), gamma=0.1)
