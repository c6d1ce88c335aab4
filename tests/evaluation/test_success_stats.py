"""success-stats on the 48-clip synthetic fixture: the GT passes its own predicates, the report
names every check, and the suggested thresholds follow the documented percentile rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from intermask.cli import main as cli
from intermask.evaluation.success_stats import TOLERANCE, UNMEASURED, success_statistics
from intermask.metrics.interaction import CHECKS, SuccessThresholds


@pytest.fixture(scope="module")
def statistics(synthetic_interhuman_root):
    return success_statistics(synthetic_interhuman_root, max_length=300)


def test_ground_truth_passes_and_suggestions_follow_the_rule(statistics):
    assert statistics.overall >= 0.95
    assert sum(map(len, statistics.passed.values())) == 48  # every clip once, no mirrored copies
    suggestions = statistics.suggested_thresholds()
    assert not set(suggestions) & set(UNMEASURED)
    values = np.array([s["hand_gap"] for s in statistics.signals["handshake"]])
    quantile = np.quantile(values, 0.99) * (1 + TOLERANCE)
    assert suggestions["hand_gap"] >= math.ceil(quantile * 100) / 100 - 1e-9
    assert set(suggestions) | set(UNMEASURED) <= {f for f in vars(SuccessThresholds())}


def test_report_and_command(statistics, synthetic_interhuman_root, capsys):
    report = statistics.report()
    for check in CHECKS["handshake"]:
        assert f"  {check.signal} " in report
    assert report.startswith("GT success ") and "suggested thresholds: " in report
    assert cli(["data", "success-stats", str(synthetic_interhuman_root), "--split", "test"]) == 0
    assert capsys.readouterr().out.startswith("GT success ")


def test_the_config_builds_the_default_thresholds():
    from pathlib import Path

    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    from intermask.train import CONFIG_DIR

    config = OmegaConf.load(Path(CONFIG_DIR) / "success" / "synthetic.yaml")
    assert instantiate(config) == SuccessThresholds()
    assert instantiate(config, hand_gap=0.2).hand_gap == 0.2
