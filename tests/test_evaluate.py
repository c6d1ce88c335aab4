"""The eval job end to end on tiny trained stages: interaction, reaction and reconstruction rows,
results written as JSON / Markdown / TensorBoard, and the generate command on the same runs."""

from __future__ import annotations

import inspect
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import open_dict
from test_train_arflow import _config as arflow_config
from test_train_evaluator import TINY_INTERCLIP
from test_train_evaluator import _config as evaluator_config
from test_train_gen import _gen_config
from test_train_vq import _config as vq_config

from intermask.cli import main as cli
from intermask.evaluate import evaluate
from intermask.train import CONFIG_DIR, train


@pytest.fixture(scope="module")
def runs(synthetic_interhuman_root, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("stages")
    train(vq_config(synthetic_interhuman_root, root / "vq"))
    vq_ckpt = root / "vq" / "checkpoints" / "last.ckpt"
    train(_gen_config(synthetic_interhuman_root, vq_ckpt, root / "gen"))
    train(evaluator_config("synthetic", synthetic_interhuman_root, root / "ev", TINY_INTERCLIP))
    evaluator = sorted((root / "ev" / "checkpoints").glob("best*.ckpt"))[0]
    train(arflow_config("synthetic", synthetic_interhuman_root, root / "arflow"))
    return {"vq": vq_ckpt, "gen": root / "gen", "evaluator": evaluator, "arflow": root / "arflow"}


def _eval_config(
    data_root: Path, runs: dict[str, Path], out: Path, mode: str, extra: tuple[str, ...] = ()
):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "eval",
            overrides=[
                "data=synthetic",
                f"data.root={data_root}",
                "data.num_workers=0",
                "split=train",  # the 48-clip fixture's test split is smaller than one eval batch
                f"mode={mode}",
                f"eval_ckpt={runs['evaluator']}",
                f"gen_ckpt={runs['gen']}",
                # a run folder, as gen_ckpt takes: its checkpoints/last.ckpt
                f"vq_ckpt={runs['vq'].parent.parent if mode == 'reconstruction' else ''}",
                "fast=true",
                "fast_replications=2",
                "protocol.eval_batch_size=8",
                "protocol.diversity_pairs=8",
                "sampler.iterations=2",
                "reaction.iterations=2",
                "penetration.modes=[interaction,reaction,reconstruction]",
                "penetration.pitch=0.05",  # 5 cm voxels: untrained models overlap a lot
                *extra,
            ],
        )
    with open_dict(cfg):
        cfg.paths.output_dir = str(out)
    return cfg


@pytest.mark.parametrize("mode", ["interaction", "reaction", "reconstruction"])
def test_eval_job_writes_the_table(synthetic_interhuman_root, runs, tmp_path, mode, capsys):
    result = evaluate(_eval_config(synthetic_interhuman_root, runs, tmp_path, mode))
    model_row = {
        "interaction": "InterMask",
        "reaction": "InterMask (reaction)",
        "reconstruction": "VQ-VAE reconstruction",
    }[mode]
    assert list(result["rows"]) == ["Ground Truth", model_row]
    truth, model = result["rows"]["Ground Truth"], result["rows"][model_row]
    for row in (truth, model):
        assert 0.0 <= row["top1"]["mean"] <= row["top2"]["mean"] <= row["top3"]["mean"] <= 1.0
        assert len(row["fid"]["values"]) == 2 and row["diversity"]["mean"] > 0
    assert "multimodality" not in model  # fast mode
    assert (mode == "reconstruction") == ("mpjpe_mm" in model)
    assert truth["if"]["mean"] >= 0 and model["iv_cm3"]["mean"] >= 0  # penetration on every row
    assert "latency_ms" in model and "latency_ms" not in truth
    # synthetic items carry action labels: interaction success on every row, per action in JSON
    assert truth["success"]["mean"] >= 0.95 and 0.0 <= model["success"]["mean"] <= 1.0
    assert any(name.startswith("success/") for name in model)
    header = result["header"]
    assert header["fast"] and header["evaluator"].startswith("interclip[trained:synthetic]")
    assert len(header["constants"]) > 10 and header["mode"] == mode
    table = (tmp_path / "results.md").read_text()
    assert "FAST MODE" in table and f"| {model_row} |" in table and "Success % ↑" in table
    # and per action, why the motions fail: a line per action in the test split
    assert f"| Action | Motions | Ground Truth | {model_row} |" in table
    assert any(name.startswith("fails/") for name in model)
    assert any(name.startswith("signal/") for name in model)
    assert (
        json.loads((tmp_path / "results.json").read_text())["rows"].keys() == result["rows"].keys()
    )
    assert list((tmp_path / "tensorboard").glob("events.out.tfevents.*"))
    assert "| Ground Truth |" in capsys.readouterr().out


def test_reaction_table_compares_intermask_and_arflow(synthetic_interhuman_root, runs, tmp_path):
    overrides = (
        f"arflow_ckpt={runs['arflow']}",
        "arflow.steps=2",
        "arflow.step_ablation=[1,2,3]",
        "fast_replications=1",
    )
    cfg = _eval_config(synthetic_interhuman_root, runs, tmp_path, "reaction", overrides)
    result = evaluate(cfg)
    rows = result["rows"]
    assert list(rows) == [
        "Ground Truth",
        "InterMask (reaction)",
        "ARFlow (2 steps)",
        "ARFlow + guidance (2 steps)",
        "ARFlow + vanilla guidance (Alg. 1) (2 steps)",
        "ARFlow + clean-gradient guidance (2 steps)",
        "ARFlow + guidance (1 step)",
        "ARFlow + guidance (3 steps)",
    ]
    # Algorithm 1 differentiates the network, the clean-gradient variant does not: two readings
    # of one update, two different results
    assert (
        rows["ARFlow + vanilla guidance (Alg. 1) (2 steps)"]["iv_cm3"]
        != rows["ARFlow + clean-gradient guidance (2 steps)"]["iv_cm3"]
        or rows["ARFlow + vanilla guidance (Alg. 1) (2 steps)"]["fid"]
        != rows["ARFlow + clean-gradient guidance (2 steps)"]["fid"]
    )
    for name, row in rows.items():
        assert row["iv_cm3"]["mean"] >= 0 and 0 <= row["if"]["mean"] <= 1
        assert ("latency_ms" in row) == (name != "Ground Truth")
    # more Euler steps cost more network calls
    assert (
        rows["ARFlow + guidance (3 steps)"]["latency_ms"]["mean"]
        > (rows["ARFlow + guidance (1 step)"]["latency_ms"]["mean"])
    )
    header = result["header"]
    assert header["arflow_sampling"]["guidance"]["mode"] == "improved"
    assert header["arflow"].startswith(str(runs["arflow"] / "checkpoints" / "last.ckpt"))
    assert "| ARFlow + guidance (2 steps) |" in (tmp_path / "results.md").read_text()
    assert "Latency (ms/sample)" in (tmp_path / "results.md").read_text()


def test_reaction_mode_needs_a_model_and_known_penetration_modes(
    synthetic_interhuman_root, runs, tmp_path
):
    cfg = _eval_config(synthetic_interhuman_root, runs, tmp_path, "reaction", ("gen_ckpt=null",))
    with pytest.raises(ValueError, match="mode=reaction needs gen_ckpt=.* and / or arflow_ckpt="):
        evaluate(cfg)
    cfg = _eval_config(
        synthetic_interhuman_root, runs, tmp_path, "reaction", ("penetration.modes=[reactions]",)
    )
    with pytest.raises(ValueError, match=r"penetration.modes: unknown mode\(s\) \['reactions'\]"):
        evaluate(cfg)


def test_generate_command_writes_samples(runs, tmp_path, capsys):
    code = cli(
        [
            "generate",
            "--checkpoint",
            str(runs["gen"]),
            "--text",
            "two people shake hands",
            "--seconds",
            "1",
            "--samples",
            "2",
            "--iterations",
            "2",
            "--out",
            str(tmp_path),
        ]
    )
    assert code == 0, capsys.readouterr().err
    folders = sorted(tmp_path.iterdir())
    assert [f.name for f in folders] == [
        "two_people_shake_hands_00-00",
        "two_people_shake_hands_00-01",
    ]
    for folder in folders:
        assert np.load(folder / "joints.npy").shape == (28, 2, 22, 3)  # 1 s at 30 fps -> 28 frames
        assert np.load(folder / "features.npy").shape == (2, 28, 262)
        record = json.loads((folder / "sample.json").read_text())
        assert (
            record["caption"] == "two people shake hands"
            and len(record["generator"]["sha256"]) == 16
        )
        assert record["settings"]["schedule"] == "paper"  # configs/sampler/paper.yaml
        assert record["settings"]["noise"] == "per_sample"
        for name in ("animation.gif", "animation.mp4", "viewer.html"):
            assert (folder / name).stat().st_size > 1000
    seeds = [json.loads((f / "sample.json").read_text())["seed"] for f in folders]
    assert seeds == [0, 1]
    out = capsys.readouterr().out
    assert "2 sample(s)" in out and "28 frames" in out
    # a re-run into the same folder is refused before any work; nothing written is lost
    before = {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*")}
    code = cli(
        ["generate", "--checkpoint", str(runs["gen"]), "--text", "two people shake hands"]
        + ["--samples", "2", "--out", str(tmp_path)]
    )
    assert code == 2
    assert "two_people_shake_hands_00-00: a sample folder already exists (2 of 2)" in (
        capsys.readouterr().err
    )
    assert {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*")} == before


def test_captions_sharing_a_prefix_or_repeated_get_their_own_folders(runs, tmp_path, capsys):
    prefix = "two people stand face to face and then one of them "  # > 40 characters
    captions = [prefix + "waves", prefix + "bows", prefix + "waves"]
    options = sum((["--text", c] for c in captions), [])
    code = cli(
        ["generate", "--checkpoint", str(runs["gen"]), *options, "--seconds", "1"]
        + ["--iterations", "1", "--no-render", "--out", str(tmp_path)]
    )
    assert code == 0, capsys.readouterr().err
    folders = sorted(p.name for p in tmp_path.iterdir())
    assert folders == [f"two_people_stand_face_to_face_and_then_o_{c:02d}-00" for c in range(3)]
    recorded = [json.loads((tmp_path / f / "sample.json").read_text())["caption"] for f in folders]
    assert recorded == captions


def test_generation_precision_is_opt_in_and_named_in_the_header(
    synthetic_interhuman_root, runs, tmp_path, monkeypatch
):
    """fp32 unless the caller asks for bf16 autocast; the table says which, the passes run it."""
    from intermask.interm.model import InterMTransformer

    seen, forward = [], InterMTransformer.forward_with_condition

    def recording_forward(self, *args, **kwargs):
        enabled = torch.is_autocast_enabled("cpu")
        seen.append(torch.get_autocast_dtype("cpu") if enabled else torch.float32)
        return forward(self, *args, **kwargs)

    monkeypatch.setattr(InterMTransformer, "forward_with_condition", recording_forward)
    headers = {}
    for precision in ("32-true", "bf16-mixed"):
        seen.clear()
        out = tmp_path / precision
        cfg = _eval_config(
            synthetic_interhuman_root, runs, out, "interaction", (f"precision={precision}",)
        )
        headers[precision] = evaluate(cfg)["header"]["generation_precision"]
        wanted = torch.bfloat16 if precision == "bf16-mixed" else torch.float32
        assert seen and set(seen) == {wanted}
        table = (out / "results.md").read_text()
        assert f"- **generation_precision**: {precision} (set explicitly)" in table
    assert headers == {
        "32-true": "32-true (set explicitly)",
        "bf16-mixed": "bf16-mixed (set explicitly)",
    }


def test_the_sampler_refuses_an_unresolved_or_unknown_precision(runs):
    from intermask.interm.load import load_generator
    from intermask.interm.sampler import InteractionSampler

    generator = load_generator(runs["gen"])
    for precision in ("auto", "16-mixed"):
        with pytest.raises(
            ValueError, match=f"sampler precision must be one of .*got '{precision}'"
        ):
            InteractionSampler(
                net=generator.net, vq=generator.vq, text=generator.text, precision=precision
            )


def test_the_generate_command_reaches_the_logits_through_each_module_once(
    runs, tmp_path, monkeypatch
):
    from intermask.interm.model import InterMTransformer

    paths, forward = [], InterMTransformer.forward_with_condition

    def recording_forward(self, *args, **kwargs):
        paths.append([Path(f.filename) for f in reversed(inspect.stack())])  # outermost first
        return forward(self, *args, **kwargs)

    monkeypatch.setattr(InterMTransformer, "forward_with_condition", recording_forward)
    code = cli(
        ["generate", "--checkpoint", str(runs["gen"]), "--text", "they hug", "--seconds", "1"]
        + ["--iterations", "1", "--no-render", "--out", str(tmp_path)]
    )
    assert code == 0 and paths
    package = Path(inspect.getfile(InterMTransformer)).parents[1]
    for stack in paths:
        modules = [p.relative_to(package).as_posix() for p in stack if p.is_relative_to(package)]
        visits = [m for i, m in enumerate(modules) if i == 0 or modules[i - 1] != m]
        # the recording stands in for interm/model.py's forward, the next and last stop; on a
        # CPU the graphed forward runs it eagerly
        assert visits == [
            "cli.py", "generate/__init__.py", "generate/interm.py", "interm/sampler.py",
            "interm/decoding.py", "interm/graphs.py",
        ]  # fmt: skip


def test_the_generate_job_runs_from_python_as_from_the_command_line(runs, tmp_path):
    from intermask.generate import Request, run

    request = Request(checkpoint=str(runs["gen"]), text=["they hug"], samples=2, seconds=1.0)
    folders = run(
        Request(
            **{**request.__dict__, "sampler": {"iterations": 1}, "no_render": True, "out": tmp_path}
        )
    )
    assert [f.name for f in folders] == ["they_hug_00-00", "they_hug_00-01"]
    records = [json.loads((f / "sample.json").read_text()) for f in folders]
    assert [r["seed"] for r in records] == [0, 1] and records[0]["settings"]["iterations"] == 1
    assert np.load(folders[0] / "features.npy").shape == (2, 28, 262)  # 1 s at 30 fps -> 28


def _assert_refused(args: list[str], message: str, tmp_path: Path, capsys) -> None:
    """`intermask <args>` exits 2 with ``message`` on stderr and writes nothing under tmp_path."""
    before = sorted(tmp_path.rglob("*"))
    assert cli(args) == 2
    assert message in capsys.readouterr().err
    assert sorted(tmp_path.rglob("*")) == before


def test_generate_revisits_re_decode_in_turn_and_are_refused_together(runs, tmp_path, capsys):
    base = ["generate", "--checkpoint", str(runs["gen"]), "--text", "they hug", "--seconds", "1"]
    base += ["--iterations", "1", "--no-render", "--persons", "in_turn"]
    for revisits in ("0", "1"):
        out = tmp_path / revisits
        assert cli([*base, "--revisits", revisits, "--out", str(out)]) == 0, capsys.readouterr().err
    plain, revisited = (tmp_path / r / "they_hug_00-00" for r in ("0", "1"))
    assert json.loads((revisited / "sample.json").read_text())["settings"]["revisits"] == 1
    motions = [np.load(folder / "features.npy") for folder in (plain, revisited)]
    assert motions[0].shape == motions[1].shape == (2, 28, 262)
    assert not np.array_equal(*motions)  # the same seed: the revisit re-decoded the persons
    together = [*base[:-2], "--persons", "together", "--revisits", "2", "--out", str(tmp_path)]
    _assert_refused(
        together, "--revisits 2 needs --persons in_turn, got 'together'", tmp_path, capsys
    )


def test_generate_remask_noise_is_recorded_and_needs_per_sample_noise(runs, tmp_path, capsys):
    base = ["generate", "--checkpoint", str(runs["gen"]), "--text", "they hug", "--seconds", "1"]
    base += ["--iterations", "3", "--no-render"]
    for noise in ("0", "2"):
        out = tmp_path / noise
        assert cli([*base, "--remask-noise", noise, "--out", str(out)]) == 0
    plain, noisy = (tmp_path / n / "they_hug_00-00" for n in ("0", "2"))
    assert json.loads((noisy / "sample.json").read_text())["settings"]["remask_noise"] == 2.0
    motions = [np.load(folder / "features.npy") for folder in (plain, noisy)]
    assert not np.array_equal(*motions)  # the same seed: other codes were kept early
    reference = [*base, "--remask-noise", "1", "--noise", "reference", "--out", str(tmp_path)]
    message = (
        "--remask-noise 1.0 draws each sample's noise from its own seed; it needs --noise "
        "per_sample, got --noise reference"
    )
    _assert_refused(reference, message, tmp_path, capsys)


def test_generate_precision_is_recorded_and_defaults_to_fp32(runs, tmp_path):
    base = ["generate", "--checkpoint", str(runs["gen"]), "--text", "they hug", "--seconds", "1"]
    base += ["--iterations", "3", "--no-render", "--device", "cpu"]
    recorded = {}
    for option in ([], ["--precision", "32"], ["--precision", "bf16"]):
        out = tmp_path / ("_".join(option) or "default")
        assert cli([*base, *option, "--out", str(out)]) == 0
        sample = json.loads((out / "they_hug_00-00" / "sample.json").read_text())
        recorded[out.name] = sample["settings"]["precision"]
        features = np.load(out / "they_hug_00-00" / "features.npy")
        assert features.dtype == np.float32 and np.isfinite(features).all()
    assert recorded == {
        "default": "32-true",
        "--precision_32": "32-true",
        "--precision_bf16": "bf16-mixed",
    }


def test_generate_partner_guidance_is_recorded_and_refused_together(runs, tmp_path, capsys):
    base = ["generate", "--checkpoint", str(runs["gen"]), "--text", "they hug", "--seconds", "1"]
    base += ["--iterations", "2", "--no-render"]
    in_turn = [*base, "--persons", "in_turn", "--partner-scale", "1.5", "--out", str(tmp_path)]
    assert cli(in_turn) == 0, capsys.readouterr().err
    record = json.loads((tmp_path / "they_hug_00-00" / "sample.json").read_text())
    assert record["settings"]["partner_scale"] == 1.5 and record["settings"]["persons"] == "in_turn"
    together = [*base, "--partner-scale", "1", "--out", str(tmp_path / "together")]
    message = (
        "--partner-scale 1.0 needs --persons in_turn or --reaction (one person decoded beside "
        "the other's tokens), got --persons together"
    )
    _assert_refused(together, message, tmp_path, capsys)


def _features_file(tmp_path: Path) -> Path:
    generator = np.random.default_rng(0)
    path = tmp_path / "pair.npy"
    np.save(path, (generator.standard_normal((2, 32, 262)) * 0.1).astype(np.float32))
    return path


@pytest.mark.parametrize("mode", ["reaction", "edit"])
def test_generate_keeps_the_fixed_person(runs, tmp_path, mode, capsys):
    motion = _features_file(tmp_path)
    options = ["--reaction", str(motion)] if mode == "reaction" else ["--edit", str(motion)]
    if mode == "edit":
        options += ["--frames", "8:24", "--person", "2", "--text", "they wave"]
    out = tmp_path / "out"
    code = cli(
        ["generate", "--checkpoint", str(runs["gen"]), *options, "--samples", "2"]
        + ["--iterations", "2", "--no-render", "--out", str(out)]
    )
    assert code == 0, capsys.readouterr().err
    first, second = (np.load(folder / "features.npy") for folder in sorted(out.iterdir()))
    assert first.shape == second.shape == (2, 32, 262)
    np.testing.assert_array_equal(first[0], second[0])  # person 1 is fixed: same tokens
    assert not np.array_equal(first[1], second[1])  # person 2 follows each sample's seed
    record = json.loads((sorted(out.iterdir())[0] / "sample.json").read_text())
    assert record["mode"] == mode


def test_demo_protocol_setting():
    """`make demo` evaluates with experiment=eval_demo: the synthetic protocol, fewer replications."""
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose("eval", overrides=["experiment=eval_demo", "eval_ckpt=e.ckpt"])
    assert cfg.protocol.eval_batch_size == 32 and cfg.protocol.replications == 5
    assert cfg.data.max_length == 96  # gen_demo's crop length
    # persons in turn, 5 iterations each: the forward passes of 10 iterations together
    assert (cfg.sampler.persons, cfg.sampler.iterations) == ("in_turn", 5)
    assert cfg.protocol.mm_replications == 1 and cfg.data.synthesize_if_missing
    assert (cfg.protocol.mm_texts, cfg.protocol.mm_generations) == (16, 10)  # synthetic: 32 x 10
    assert cfg.penetration.modes == ["reaction"] and cfg.arflow.steps == 5
    assert list(cfg.arflow.step_ablation) == [2, 10]


def test_interaction_table_can_show_the_generators_tokenizer_beside_it(
    synthetic_interhuman_root, runs, tmp_path
):
    cfg = _eval_config(
        synthetic_interhuman_root, runs, tmp_path, "interaction", ("reconstruction_row=true",)
    )
    rows = evaluate(cfg)["rows"]
    assert list(rows) == ["Ground Truth", "VQ-VAE reconstruction", "InterMask"]
    reconstruction = rows["VQ-VAE reconstruction"]
    # the generator's own VQ-VAE: joint error measured, timed like every model row, no MModality
    assert reconstruction["mpjpe_mm"]["mean"] > 0 and "latency_ms" in reconstruction
    assert "mpjpe_mm" not in rows["InterMask"]


def test_periodic_protocol_logs_quality_during_generator_training(
    synthetic_interhuman_root, runs, tmp_path
):
    cfg = _gen_config(synthetic_interhuman_root, runs["vq"], tmp_path)
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        callbacks = compose(
            "train_gen",
            overrides=[
                "callbacks=[default,protocol]",
                f"callbacks.protocol.evaluator={runs['evaluator']}",
                "callbacks.protocol.split=train",  # the 48-clip fixture's val split is tiny
                "callbacks.protocol.iterations=2",
                "callbacks.protocol.constants.eval_batch_size=8",
                "callbacks.protocol.constants.diversity_pairs=8",
                "vq_ckpt=unused",
            ],
        ).callbacks
    with open_dict(cfg):
        cfg.callbacks = callbacks
        cfg.callbacks.rich_progress_bar = None
        cfg.callbacks.sample_animations = None
    metrics = train(cfg)
    for name in ("top1", "top3", "fid", "mm_dist", "diversity", "gt_top3"):
        assert np.isfinite(metrics[f"protocol/{name}"]), name
    assert 0.0 <= metrics["protocol/top1"] <= metrics["protocol/top3"] <= 1.0
    assert metrics["protocol/fid"] > 0.0  # an untrained generator is not the GT
    assert 0.0 <= metrics["protocol/success"] <= 1.0 and metrics["protocol/gt_success"] > 0.5
    assert any(name.startswith("protocol/success/") for name in metrics)
    # the per-check failure shares and signals and the per-action counts stay in the eval's JSON
    assert not any(
        name.startswith(("protocol/fails/", "protocol/samples/", "protocol/signal/"))
        for name in metrics
    )
    assert 0.0 < metrics["protocol/hours"] < 1.0


def test_periodic_protocol_rejects_bad_settings(tmp_path):
    from callbacks.protocol import PeriodicProtocol
    from intermask.evaluation.protocol import ProtocolConstants

    with pytest.raises(FileNotFoundError, match="missing.ckpt: evaluator checkpoint not found"):
        PeriodicProtocol(evaluator=str(tmp_path / "missing.ckpt"), constants=ProtocolConstants())
    (tmp_path / "e.ckpt").write_bytes(b"")
    with pytest.raises(ValueError, match="every_n_epochs and iterations must be >= 1, got 0"):
        PeriodicProtocol(
            evaluator=str(tmp_path / "e.ckpt"), constants=ProtocolConstants(), every_n_epochs=0
        )
    with pytest.raises(ValueError, match="split must be 'train', 'val' or 'test', got 'dev'"):
        PeriodicProtocol(
            evaluator=str(tmp_path / "e.ckpt"), constants=ProtocolConstants(), split="dev"
        )


def test_periodic_protocol_clock_and_count_continue_after_a_resume(tmp_path, monkeypatch):
    from callbacks import protocol as module
    from intermask.evaluation.protocol import ProtocolConstants

    (tmp_path / "e.ckpt").write_bytes(b"")
    clock = iter([100.0, 100.0 + 1800.0, 5000.0, 5000.0 + 900.0])
    monkeypatch.setattr(module.time, "monotonic", lambda: next(clock))
    first = module.PeriodicProtocol(
        evaluator=str(tmp_path / "e.ckpt"), constants=ProtocolConstants()
    )
    first._validations = 3
    state = first.state_dict()  # half an hour after the first run's start
    assert state == {"validations": 3, "hours": 0.5}

    resumed = module.PeriodicProtocol(
        evaluator=str(tmp_path / "e.ckpt"), constants=ProtocolConstants()
    )
    resumed.load_state_dict(state)
    assert resumed._validations == 3
    assert resumed.hours() == pytest.approx(0.5 + 900.0 / 3600)  # 15 more minutes


@pytest.mark.slow  # fits two bodies to every evaluated interaction: 5 min on 2 loaded cores
def test_reaction_table_has_mesh_penetration_beside_the_capsules(
    synthetic_interhuman_root, runs, tmp_path
):
    """With penetration.body_model (here the generated stand-in), every row of one reaction run
    reports IV / IF on fitted body meshes beside the capsule proxy's (docs/bodies.md)."""
    from intermask.body.standin import write_standin_model

    model = write_standin_model(tmp_path / "body_models", "smplx")
    overrides = (f"penetration.body_model={model}", "fast_replications=1", "penetration.pitch=0.02")
    cfg = _eval_config(synthetic_interhuman_root, runs, tmp_path / "eval", "reaction", overrides)
    rows = evaluate(cfg)["rows"]
    assert list(rows) == ["Ground Truth", "InterMask (reaction)"]
    for row in rows.values():
        assert row["mesh_iv_cm3"]["mean"] >= 0 and 0 <= row["mesh_if"]["mean"] <= 1
        assert row["iv_cm3"]["mean"] >= 0 and row["mesh_fit_error_mm"]["mean"] >= 0
    table = (tmp_path / "eval" / "results.md").read_text()
    assert "| IV (cm³) ↓ | IF ↓ | Mesh IV (cm³) ↓ | Mesh IF ↓ | Body fit (mm) ↓ |" in table
