"""`make bench` end to end at the demo's model size on tiny inputs: every row is measured, the
derived columns follow from the measured ones, and the JSON holds what the table printed."""

from __future__ import annotations

import json

import pytest
import torch

from intermask.bench import SCHEMA, main


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    argv = ["--size", "demo", "--frames", "32", "--batches", "1", "2", "--repeats", "1"]
    argv += ["--train-batch", "2", "--vq-batch", "2", "--threads", "1", "--out", str(out)]
    argv += ["--test-split", str(out / "absent.txt")]
    assert main(argv) == 0
    (path,) = out.glob("bench_demo_cpu_1t.json")
    return json.loads(path.read_text())


def test_every_row_is_measured(report):
    assert report["schema"] == SCHEMA and report["size"] == "demo"
    assert report["machine"]["threads"] == 1 and report["machine"]["cpu_capability"]
    assert report["machine"]["cuda_graphs"] is False  # a CPU run decodes eagerly
    assert report["peak_gflops"] > 0
    names = [(row["name"], row["batch"]) for row in report["rows"]]
    assert names == [
        ("interm_forward", 1),
        ("interaction", 1),
        ("interaction", 2),
        ("interm_train_step", 2),
        ("vq_train_step", 2),
        ("vq_roundtrip", 1),
        ("protocol", names[-1][1]),
    ]
    for row in report["rows"]:
        assert row["seconds"] > 0 and row["cpu_seconds"] > 0, row


def test_derived_columns_follow_from_the_measured_ones(report):
    rows = {(row["name"], row["batch"]): row for row in report["rows"]}
    for row in report["rows"]:
        if row["flops"] is not None:
            rate = row["flops"] / row["seconds"] / 1e9
            assert row["gflops_per_s"] == pytest.approx(rate)
            assert row["pct_peak"] == pytest.approx(100 * rate / report["peak_gflops"])
        if row["samples_per_s"] is not None:
            assert row["samples_per_s"] == pytest.approx(row["batch"] / row["seconds"])
    pair = rows[("interaction", 2)]
    assert pair["per_sample_seconds"] == pytest.approx(pair["seconds"] / 2)
    # the counted FLOPs of a batch of 2 are twice those of one interaction
    assert pair["flops"] == pytest.approx(2 * rows[("interaction", 1)]["flops"], rel=1e-6)
    best = [row for row in report["rows"] if row["best"]]
    assert len(best) == 1 and best[0]["per_sample_seconds"] == min(
        row["per_sample_seconds"] for row in report["rows"] if row["name"] == "interaction"
    )


def test_the_protocol_row_extrapolates_the_best_per_sample_time(report):
    best = next(row for row in report["rows"] if row["best"])
    protocol = report["rows"][-1]
    # InterHuman constants: 20 replications of 960 items (1,000 clips in batches of 96) and
    # 5 x 100 x 30 MultiModality generations
    count = 20 * 960 + 5 * 100 * 30
    assert protocol["seconds"] == pytest.approx(count * best["per_sample_seconds"])
    assert "per 1,000 clips: no InterHuman test split here" in protocol["note"]
    assert protocol["note"].startswith(f"{count} generations at 32 frames")


def test_the_rows_run_at_the_trainers_precision_and_say_which(report):
    from intermask.bench import bench_precision
    from intermask.utils.precision import resolve_precision

    # auto is what `trainer.precision: auto` picks here (fp32 on an AVX2-only CPU)
    assert report["machine"]["precision"] == resolve_precision("auto", "cpu").precision
    cpu = torch.device("cpu")
    assert bench_precision("32", cpu).precision == "32-true"
    assert bench_precision("bf16", cpu).precision == "bf16-mixed"
    with pytest.raises(
        ValueError, match=r"bench precision must be one of \['32', 'auto', 'bf16'\], got 'fp16'"
    ):
        bench_precision("fp16", cpu)
