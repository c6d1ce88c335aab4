"""Every gen_* experiment composes, lands its switches and builds its network (Table 3)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf

from intermask.interm.model import InterMTransformer
from intermask.train import CONFIG_DIR

PAPER = {
    "modeling": "collaborative",
    "use_self_attention": True,
    "use_spatio_temporal_attention": True,
    "use_cross_attention": True,
    "p_random": 0.8,
    "p_solo": 0.0,
    "p_partner": 0.0,
    "step_unroll": True,
}
EXPERIMENTS = {
    "gen_interhuman": {},
    "gen_interx": {},
    "gen_ablation_alternative": {"modeling": "alternative"},
    "gen_ablation_no_self_attention": {"use_self_attention": False},
    "gen_ablation_no_spatio_temporal": {"use_spatio_temporal_attention": False},
    "gen_ablation_no_cross_attention": {"use_cross_attention": False},
    "gen_ablation_no_step_unroll": {"step_unroll": False},
    "gen_ablation_no_interaction_masking": {"p_random": 1.0},
    "gen_ablation_no_step_unroll_no_interaction_masking": {"p_random": 1.0, "step_unroll": False},
}
CPU_SETTINGS = {"gen_demo"}  # CPU-sized: paper switches, not paper sizes (tested below)
SYNTHETIC_SETTINGS = {"gen_synthetic_long", "gen_synthetic_long_cpu"}  # long runs (tested below)
REFERENCE_SETTINGS = {
    "gen_interhuman_reference"
}  # the reference code's switches (test_fidelity.py)
TINY_NET = {
    "width": 32,
    "heads": 2,
    "depth": 1,
    "ff": 32,
    "token_embed_dim": 16,
    "text_dim": 32,
    "text_layers": 1,
    "text_heads": 2,
    "text_ff": 32,
}


def _compose(experiment: str, *extra: str):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(
            "train_gen",
            overrides=[
                f"experiment={experiment}",
                "vq_ckpt=unused",
                "paths.output_dir=/tmp/x",
                *extra,
            ],
        )


def test_every_gen_experiment_file_is_covered():
    files = {path.stem for path in Path(CONFIG_DIR, "experiment").glob("gen_*.yaml")}
    assert files == set(EXPERIMENTS) | CPU_SETTINGS | SYNTHETIC_SETTINGS | REFERENCE_SETTINGS


def test_long_synthetic_run_is_the_paper_network_scored_by_the_protocol():
    cfg = _compose("gen_synthetic_long", "callbacks.protocol.evaluator=unused.ckpt")
    landed = {key: cfg.model[key] if key in cfg.model else cfg.model.net[key] for key in PAPER}
    assert landed == PAPER
    net = cfg.model.net
    assert (net.width, net.heads, net.depth, net.ff, net.dropout) == (384, 6, 6, 1024, 0.2)
    assert cfg.data.max_length == 96  # the demo's crops; the codebook size comes from the VQ
    assert cfg.trainer.max_epochs == 500 and cfg.trainer.accelerator == "gpu"
    assert cfg.callbacks.protocol.every_n_epochs == 10
    assert cfg.callbacks.model_checkpoint.monitor == "protocol/fid"


def test_long_cpu_run_is_the_demo_network_trained_longer_and_scored_every_1000_steps():
    cfg = _compose("gen_synthetic_long_cpu", "callbacks.protocol.evaluator=unused.ckpt")
    demo = _compose("gen_demo")
    # at the width its curve was measured with (docs/decisions.md: model.net.width), the demo's
    # otherwise
    widths = {"width": 128, "ff": 256, "token_embed_dim": 128}
    assert {key: cfg.model.net[key] for key in widths} == widths
    assert demo.model.net.width == 64
    assert {**cfg.model.net, **{key: demo.model.net[key] for key in widths}} == demo.model.net
    assert cfg.data.batch_size == demo.data.batch_size
    assert cfg.trainer.accelerator == "cpu" and cfg.trainer.max_epochs == 100
    # 100 steps an epoch: a validation every 1,000 steps, each followed by the protocol
    assert cfg.trainer.check_val_every_n_epoch == 10 and cfg.callbacks.protocol.every_n_epochs == 1
    assert cfg.callbacks.model_checkpoint.monitor == "protocol/fid"
    # scored with the demo protocol's decoding: persons in turn, 5 iterations each
    protocol = cfg.callbacks.protocol
    assert (protocol.persons, protocol.iterations) == ("in_turn", 5)


def test_demo_setting_keeps_the_paper_switches_on_a_cpu_sized_network():
    cfg = _compose("gen_demo")
    landed = {key: cfg.model[key] if key in cfg.model else cfg.model.net[key] for key in PAPER}
    # the demo trains without the step-unroll pass: at its CPU budget the measured run without it
    # had the better top-3 and success (docs/decisions.md: model.step_unroll); every other paper
    # switch stays on
    # and it trains for the persons-in-turn decoding of eval_demo: a quarter of the samples
    # masked solo, a quarter by interaction masking (docs/decisions.md: model.p_solo)
    assert landed == {**PAPER, "step_unroll": False, "p_random": 0.5, "p_solo": 0.5}
    assert cfg.trainer.accelerator == "cpu" and cfg.text.encoder.pretrained is None
    assert cfg.model.net.text_dim == 64  # the tiny text tower


def test_no_generator_config_repeats_the_codebook_size_its_vq_owns():
    # the network is a factory InterMModule calls with the loaded VQ's codebook size
    for experiment in sorted(set(EXPERIMENTS) | CPU_SETTINGS | SYNTHETIC_SETTINGS):
        extra = ["callbacks.protocol.evaluator=unused.ckpt"] * (experiment in SYNTHETIC_SETTINGS)
        net = _compose(experiment, *extra).model.net
        assert net._partial_ is True and "codebook_size" not in net, experiment


@pytest.mark.parametrize("experiment", sorted(EXPERIMENTS))
def test_gen_experiment_lands_its_switches_on_the_paper_setting(experiment):
    cfg = _compose(experiment)
    expected = {**PAPER, **EXPERIMENTS[experiment]}
    net, model = cfg.model.net, cfg.model
    landed = {key: (model[key] if key in model else net[key]) for key in expected}
    assert landed == expected
    interx = experiment == "gen_interx"
    assert cfg.data.dataset == ("interx" if interx else "interhuman")
    assert cfg.data.max_length == (150 if interx else 300)
    # appendix C: batch 52, 500 epochs, warm-up a quarter of the first epoch, bf16 GPU
    assert cfg.data.batch_size == 52 and cfg.trainer.max_epochs == 500
    assert cfg.trainer.accelerator == "gpu" and cfg.trainer.precision == "bf16-mixed"
    assert model.warmup_fraction == pytest.approx(0.25 / 500) and model.condition_drop == 0.1
    assert (net.width, net.depth, net.heads, net.double_residual_quirk) == (384, 6, 6, False)
    OmegaConf.resolve(cfg)
    tiny = instantiate(OmegaConf.merge(net, TINY_NET))(codebook_size=16)  # as InterMModule does
    assert isinstance(tiny, InterMTransformer) and tiny.modeling == expected["modeling"]
    assert all(
        (block.cross_attention is not None) == net.use_cross_attention for block in tiny.blocks
    )
    assert all(
        (block.self_attention is not None) == net.use_self_attention for block in tiny.blocks
    )
    assert all(
        (block.spatio_temporal is not None) == net.use_spatio_temporal_attention
        for block in tiny.blocks
    )
