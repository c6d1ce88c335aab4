"""The Hydra tree composes for every job and dataset, and its values are the paper's."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf

from intermask.data.datamodule import InteractionDataModule
from intermask.train import CONFIG_DIR

DATASETS = ["synthetic", "synthetic_interx", "interhuman", "interx"]


def _compose(job: str, overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(job, overrides=overrides, return_hydra_config=False)


@pytest.mark.parametrize("data", DATASETS)
def test_train_vq_composes_for_every_dataset(data):
    cfg = _compose("train_vq", [f"data={data}", "paths.output_dir=/tmp/unused"])
    interx = "interx" in data
    assert cfg.data.dataset == ("interx" if interx else "interhuman")
    assert cfg.data.mode == "window" and cfg.data.window == 64 and cfg.data.stride == 10
    assert cfg.model.net.encoder.num_joints == (56 if interx else 22)
    assert cfg.model.loss_weights.foot_contact == (100.0 if interx else 500.0)
    assert cfg.model.loss_weights.velocity == 100.0 and cfg.model.loss_weights.bone_length == 5.0
    assert cfg.model.optimizer.lr == 2e-4 and list(cfg.model.optimizer.betas) == [0.9, 0.99]
    assert cfg.trainer.max_epochs == 50 and cfg.trainer.gradient_clip_val == 1.0
    OmegaConf.resolve(cfg)  # every interpolation resolves


def test_data_config_instantiates_the_datamodule(tmp_path):
    cfg = _compose(
        "train_vq", ["data=synthetic", f"paths.data_dir={tmp_path}", "paths.output_dir=/tmp/unused"]
    )
    datamodule = instantiate(cfg.data)
    assert isinstance(datamodule, InteractionDataModule)
    assert datamodule.root == tmp_path / "synthetic" / "interhuman"
    assert datamodule.mode == "window" and datamodule.max_length == 300 and datamodule.seed == 3407


@pytest.mark.parametrize("data", ["humanml3d", "synthetic_humanml3d"])
def test_momask_rvq_composes_with_momask_values(data, tmp_path):
    import torch

    from intermask.data.text_motion import TextMotionDataModule
    from intermask.vq.views import HumanML3DView

    cfg = _compose(
        "train_vq",
        [
            f"data={data}",
            "experiment=momask_rvq",
            f"paths.data_dir={tmp_path}",
            "paths.output_dir=/tmp/unused",
        ],
    )
    assert cfg.data.mode == "window" and cfg.data.window == 64 and cfg.data.stride == 1
    assert cfg.data.batch_size == 256 and cfg.trainer.max_epochs == 50
    quantizer = cfg.model.net.quantizer
    assert (quantizer.num_quantizers, quantizer.codebook_size, quantizer.dim) == (6, 512, 512)
    assert quantizer.dropout_prob == 0.2 and cfg.model.loss_weights.commitment == 0.02
    assert list(cfg.model.net.encoder.dilations) == [9, 3, 1]
    datamodule = instantiate(cfg.data)
    assert isinstance(datamodule, TextMotionDataModule) and datamodule.mode == "window"
    folder = {"humanml3d": "HumanML3D", "synthetic_humanml3d": "synthetic/humanml3d"}[data]
    assert datamodule.root == tmp_path / folder
    model = instantiate(cfg.model)
    assert isinstance(model.net.view, HumanML3DView)
    indices = model.net.encode(torch.randn(1, 64, 263))
    assert indices.shape == (1, 6, 1, 16)  # 6 layers, one row, one token per 4 frames


def test_unknown_keys_are_rejected():
    from hydra.errors import ConfigCompositionException

    with pytest.raises(
        ConfigCompositionException, match="Could not override 'data.no_such_option'"
    ):
        _compose("train_vq", ["data.no_such_option=1"])


def test_trainer_presets_compose():
    for preset, expected in [("cpu", "cpu"), ("gpu", "gpu"), ("ddp", "gpu"), ("ddp_cpu", "cpu")]:
        cfg = _compose("train_vq", [f"trainer={preset}", "paths.output_dir=/tmp/unused"])
        assert cfg.trainer.accelerator == expected
    assert _compose("train_vq", ["trainer=gpu"]).trainer.precision == "bf16-mixed"


def test_slurm_launcher_composes():
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose("train_vq", overrides=["hydra/launcher=slurm"], return_hydra_config=True)
    assert cfg.hydra.launcher._target_.endswith("SlurmLauncher")
    assert cfg.hydra.launcher.gpus_per_node == 1


@pytest.mark.parametrize(
    ("experiment", "persons", "rows"), [("vq_ablation_two_person", 2, 5), ("vq_ablation_1d", 1, 1)]
)
def test_vq_ablations_are_config_selections(experiment, persons, rows):
    import torch

    cfg = _compose(
        "train_vq",
        [
            f"experiment={experiment}",
            "model.net.encoder.width=8",
            "model.net.quantizer.codebook_size=4",
        ],
    )
    net = instantiate(cfg.model).net
    features = torch.randn(1, 16, 2, 262) if persons == 2 else torch.randn(1, 16, 262)
    assert net.train()(features).indices.shape == (1, 1, rows, 4)
    assert cfg.data.get("window_persons", 1) == persons


def test_decoding_defaults_shared_by_generate_and_eval_say_the_same():
    """Facts stated in two job configs (and MoMask's in its sampler's defaults) must agree:
    a reaction decodes in the paper's 12 iterations (appendix C) whether generated or
    evaluated, and MoMask decodes with section 4's settings in both jobs, stated once in
    configs/sampler/momask.yaml, which both compose."""
    import inspect
    from dataclasses import asdict

    from intermask.evaluation.sources import InterMaskReaction
    from intermask.momask.sampler import MoMaskDecoding, decode_base, decode_residual

    generate, evaluate = _compose("generate", []), _compose("eval", [])
    assert generate.reaction_iterations == evaluate.reaction.iterations == 12
    # the evaluation source has no default of its own: the config is the one owner
    iterations = inspect.signature(InterMaskReaction).parameters["iterations"]
    assert iterations.default is inspect.Parameter.empty
    momask = _compose("sampler/momask", []).sampler  # a group config sits under its group
    assert dict(generate.momask) == dict(evaluate.momask) == dict(momask)
    # the library's defaults (callers that change single settings decode with the rest)
    library = MoMaskDecoding()
    assert asdict(library) == dict(momask)
    assert list(MoMaskDecoding.__dataclass_fields__) == list(momask)
    base = inspect.signature(decode_base).parameters
    residual = inspect.signature(decode_residual).parameters
    assert {k: base[k].default for k in ("iterations", "top_k_ratio", "temperature")} == {
        k: getattr(library, k) for k in ("iterations", "top_k_ratio", "temperature")
    }
    assert (base["cfg_scale"].default, base["schedule"].default, base["noise"].default) == (
        library.mask_cfg_scale,
        library.schedule,
        library.noise,
    )
    assert (residual["cfg_scale"].default, residual["temperature"].default) == (
        library.residual_cfg_scale,
        library.residual_temperature,
    )
