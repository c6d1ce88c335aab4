"""``trainer.precision: auto`` follows the hardware; explicit values stay as given."""

from __future__ import annotations

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import open_dict

from intermask.train import CONFIG_DIR, decide_precision, set_threads
from intermask.utils.precision import resolve_precision

AVX2_FLAGS = {"architecture": "x86_64", "avx2": True, "avx512_bf16": False, "amx_bf16": False}
SAPPHIRE_RAPIDS_FLAGS = {**AVX2_FLAGS, "avx512_f": True, "avx512_bf16": True, "amx_bf16": True}
AVX512_NO_BF16_FLAGS = {**AVX2_FLAGS, "avx512_f": True}  # Skylake-X: wide vectors, no bf16


@pytest.fixture
def cpu_only(monkeypatch):
    """No CUDA; returns a setter for the CPU's (capability string, feature flags)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)

    def set_cpu(capability: str, flags: dict) -> None:
        monkeypatch.setattr(torch.backends.cpu, "get_cpu_capability", lambda: capability)
        monkeypatch.setattr(torch.cpu, "get_capabilities", lambda: flags)

    return set_cpu


@pytest.mark.parametrize("accelerator", ["auto", "cpu"])
def test_avx2_cpu_trains_in_fp32(cpu_only, accelerator):
    cpu_only("AVX2", AVX2_FLAGS)
    choice = resolve_precision("auto", accelerator)
    assert choice.precision == "32-true"
    assert choice.reason == "CPU capability AVX2, no native bf16"


def test_avx512_without_bf16_trains_in_fp32(cpu_only):
    cpu_only("AVX512", AVX512_NO_BF16_FLAGS)
    assert resolve_precision("auto", "cpu").precision == "32-true"


def test_native_bf16_cpu_trains_in_bf16(cpu_only):
    cpu_only("AVX512", SAPPHIRE_RAPIDS_FLAGS)
    choice = resolve_precision("auto", "cpu")
    assert choice.precision == "bf16-mixed"
    assert "avx512_bf16" in choice.reason and "amx_bf16" in choice.reason


def test_arm_bf16_cpu_trains_in_bf16(cpu_only):
    cpu_only("SVE256", {"architecture": "arm64", "sve": True, "bf16": True})
    assert resolve_precision("auto", "cpu").precision == "bf16-mixed"


@pytest.mark.parametrize(("bf16", "expected"), [(True, "bf16-mixed"), (False, "32-true")])
@pytest.mark.parametrize("accelerator", ["auto", "gpu", "cuda"])
def test_cuda_uses_bf16_where_supported(monkeypatch, cpu_only, accelerator, bf16, expected):
    cpu_only("AVX2", AVX2_FLAGS)  # the host CPU does not matter on CUDA
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda: bf16)
    monkeypatch.setattr(torch.cuda, "get_device_name", lambda: "Fake GPU")
    choice = resolve_precision("auto", accelerator)
    assert choice.precision == expected and choice.reason.startswith("CUDA Fake GPU")


def test_cuda_present_but_cpu_requested_follows_the_cpu(monkeypatch, cpu_only):
    cpu_only("AVX2", AVX2_FLAGS)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolve_precision("auto", "cpu").precision == "32-true"


@pytest.mark.parametrize("explicit", ["bf16-mixed", "32-true", "16-mixed", 32])
def test_explicit_precision_is_kept(cpu_only, explicit):
    cpu_only("AVX2", AVX2_FLAGS)
    choice = resolve_precision(explicit, "cpu")
    assert choice.precision == str(explicit) and choice.reason == "set explicitly"


def _train_config(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train_vq", overrides=["trainer=cpu", *overrides])
    with open_dict(cfg):
        cfg.paths.output_dir = "/tmp/unused"
    return cfg


@pytest.mark.parametrize(
    ("job", "experiment", "precision"),
    [
        ("train_vq", "vq_demo", "auto"),
        # on a CPU with native bf16 the demo's two small transformers are slower in bf16 than in
        # fp32, and the tokenizer's convolutions faster (docs/decisions.md: trainer.precision)
        ("train_evaluator", "evaluator_demo", "32-true"),
        ("train_gen", "gen_demo", "32-true"),
        ("train_arflow", "arflow_demo", "auto"),
    ],
)
def test_demo_experiments_precision(job, experiment, precision):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(job, overrides=[f"experiment={experiment}"])
    assert cfg.trainer.precision == precision


def test_train_job_resolves_auto_once_and_logs_it(cpu_only, caplog):
    cpu_only("AVX2", AVX2_FLAGS)
    cfg = _train_config([])
    with caplog.at_level("INFO", logger="intermask.train"):
        choice = decide_precision(cfg)
    assert cfg.trainer.precision == "32-true" and choice.requested == "auto"
    assert "precision: 32-true (CPU capability AVX2, no native bf16)" in caplog.text


def test_train_job_keeps_an_explicit_value(cpu_only, caplog):
    cpu_only("AVX2", AVX2_FLAGS)
    cfg = _train_config(["trainer.precision=bf16-mixed"])
    with caplog.at_level("INFO", logger="intermask.train"):
        decide_precision(cfg)
    assert cfg.trainer.precision == "bf16-mixed"
    assert "precision: bf16-mixed (set explicitly)" in caplog.text


@pytest.fixture
def keep_threads():
    previous = torch.get_num_threads()
    yield
    torch.set_num_threads(previous)


def test_train_job_sets_its_threads_and_logs_them(keep_threads, caplog):
    cfg = _train_config(["threads=1"])
    with caplog.at_level("INFO", logger="intermask.train"):
        assert set_threads(cfg) == 1
    assert torch.get_num_threads() == 1
    assert "CPU threads: 1" in caplog.text


def test_train_job_without_threads_keeps_torchs_count(keep_threads):
    torch.set_num_threads(2)
    assert set_threads(_train_config([])) == 2
    assert torch.get_num_threads() == 2


@pytest.mark.parametrize("value", ["0", "-2", "true", "1.5", "two"])
def test_train_job_refuses_a_thread_count_that_is_not_a_positive_integer(keep_threads, value):
    cfg = _train_config([f"threads={value}"])
    with pytest.raises(ValueError, match="threads must be a positive integer or null, got"):
        set_threads(cfg)


@pytest.mark.parametrize(
    ("job", "experiment", "threads"),
    [
        ("train_vq", "vq_demo", None),
        ("train_evaluator", "evaluator_demo", 1),  # faster on 1 of 2 cores (docs/performance.md)
        ("train_gen", "gen_demo", None),
        ("train_arflow", "arflow_demo", None),
    ],
)
def test_demo_experiments_thread_counts(job, experiment, threads):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(job, overrides=[f"experiment={experiment}"])
    assert cfg.threads == threads


def test_generate_precision_choices_are_the_precision_options():
    """`intermask generate --precision` spells its choices without importing torch; they must
    stay the keys of intermask.utils.precision.OPTIONS, which the job maps them through."""
    from intermask.cli import build_parser
    from intermask.utils.precision import OPTIONS

    parser = build_parser()
    generate = next(action.choices["generate"] for action in parser._actions if action.choices)
    option = next(a for a in generate._actions if "--precision" in a.option_strings)
    assert sorted(option.choices) == sorted(OPTIONS) == ["32", "auto", "bf16"]
