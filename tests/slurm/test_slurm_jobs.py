"""Cluster jobs on a real Slurm (the one-node cluster of conftest.py): a sweep through Hydra's
submitit launcher, two tasks through srun equal to one process, a job signalled before its time
limit that requeues itself and ends bit-identical to an uninterrupted run, ``scancel`` leaving a
loadable checkpoint, and the evaluation as a Slurm job writing the table of a local run.

Every job is what docs/cluster.md tells users to run: the launcher config
``configs/hydra/launcher/slurm.yaml`` and the sbatch script ``tools/slurm/train.sbatch``, with
tiny debug stages and sbatch options on the command line. The only additions are the callbacks of
slurm_callbacks.py, which hold training still until Slurm's signal has come."""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from test_parallel_training import STEPS

pytestmark = pytest.mark.slurm

ROOT = Path(__file__).resolve().parents[2]
SBATCH_SCRIPT = ROOT / "tools" / "slurm" / "train.sbatch"
TINY_VQ = [
    "debug=vq",
    "trainer.limit_val_batches=1",
    "callbacks.sample_animations=null",
    "trainer.precision=32-true",  # the equalities below are fp32's (docs/cluster.md)
]


def _documented(*words: str) -> None:
    """docs/cluster.md shows these words of a command the test runs (paths are the test's own)."""
    page = (ROOT / "docs" / "cluster.md").read_text()
    missing = [word for word in words if word not in page]
    assert not missing, f"docs/cluster.md does not show {missing}"


def _last(run: Path) -> dict:
    return torch.load(run / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=True)


def test_a_sweep_through_the_slurm_launcher_runs_each_job_to_its_end(
    slurm, synthetic_interhuman_root, tmp_path
):
    sweep = tmp_path / "sweep"
    command = [
        sys.executable, "-m", "intermask.train", "--config-name", "train_vq", "--multirun",
        "hydra/launcher=slurm", "hydra.launcher.partition=debug",
        "hydra.launcher.gpus_per_node=0", "hydra.launcher.tasks_per_node=1",
        "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=2",
        "hydra.launcher.timeout_min=10", f"hydra.sweep.dir={sweep}",
        f"data.root={synthetic_interhuman_root}", *TINY_VQ,
        "model.net.quantizer.codebook_size=16,32",  # the swept value: two jobs
    ]  # fmt: skip
    _documented(*(w for w in command[3:] if "/" not in w or w == "hydra/launcher=slurm"))
    done = subprocess.run(
        command, cwd=ROOT, env=slurm.job_env(), capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    # one job array, a task per value; submitit's folders are named by the array's task ids
    array = next(p.name for p in (sweep / ".submitit").iterdir() if p.name.isdigit())
    folders = sorted(p.name for p in (sweep / ".submitit").glob(f"{array}_*"))
    assert folders == [f"{array}_0", f"{array}_1"], folders
    tasks = slurm.jobs(array)
    assert sorted(t["ArrayTaskId"] for t in tasks) == ["0", "1"]
    jobs = [t["JobId"] for t in tasks]
    records = {r["JobID"]: r for r in slurm.sacct(*jobs)}
    assert records.keys() == set(jobs), records
    assert {r["State"] for r in records.values()} == {"COMPLETED"}, records
    assert {r["JobName"] for r in records.values()} == {"train"}, records  # hydra.job.name
    assert {r["Partition"] for r in records.values()} == {"debug"}
    for job, codes in ((0, 16), (1, 32)):
        run = sweep / str(job)
        assert f"codebook_size: {codes}" in (run / "config.yaml").read_text()
        assert json.loads((run / "run_record.json").read_text())["job"] == "train_vq"
        assert _last(run)["global_step"] == 3  # debug=vq: 1 epoch of 3 batches
    # the sbatch script submitit wrote carries the launcher's settings
    script = (sweep / ".submitit" / array / f"{array}_submission.sh").read_text()
    for line in ("--partition=debug", "--cpus-per-task=1", "--mem=2GB", "--time=10"):
        assert f"#SBATCH {line}" in script, line
    assert "#SBATCH --signal=USR2@120" in script


def _sbatch_train(slurm, out: Path, job: str, *overrides: str, options=(), time="10") -> str:
    """tools/slurm/train.sbatch as docs/cluster.md runs it, into the run folder ``out``; the job
    id (its output goes to ``<out>.out``)."""
    return slurm.sbatch(
        "--partition=debug", "--mem=3G", f"--time={time}", f"--output={out}.out", *options,
        str(SBATCH_SCRIPT), job, *overrides, env=slurm.job_env(RUN_DIR=str(out)),
    )  # fmt: skip


def _finished(slurm, job: str, out: Path, timeout: float = 240, **wait) -> dict:
    info = slurm.wait(job, timeout, **wait)
    log = Path(f"{out}.out")
    assert info["JobState"] == "COMPLETED", (info, log.read_text()[-3000:] if log.exists() else "")
    return info


def test_two_tasks_through_srun_equal_one_process(slurm, synthetic_interhuman_root, tmp_path):
    from test_parallel_training import _assert_same_weights, _single_writer
    from test_train_gen import _gen_config
    from test_train_vq import _config as vq_config

    from intermask.train import train

    data = f"data.root={synthetic_interhuman_root}"
    vq_steps = [f"trainer.limit_train_batches={STEPS}", "model.net.encoder.dropout=0.0"]
    ddp = ["trainer=ddp", "trainer.accelerator=cpu", "threads=1"]  # Lightning's SLURMEnvironment
    two = ["--ntasks-per-node=2", "--cpus-per-task=1"]
    vq_overrides = [*TINY_VQ, *vq_steps, "data.batch_size=4", *ddp]
    _documented(*two, "tools/slurm/train.sbatch train_vq", *vq_overrides)
    vq_job = _sbatch_train(slurm, tmp_path / "vq2", "train_vq", data, *vq_overrides, options=two)
    gen = [
        f"trainer.limit_train_batches={STEPS}",
        "trainer.precision=32-true",
        "++model.step_unroll=true",
        "++model.validation_samples=0",
        "model.net.dropout=0.0",  # dropout draws per process (docs/cluster.md)
        "model.net.text_dropout=0.0",
        "callbacks.sample_animations=null",
    ]
    vq_ckpt = tmp_path / "vq2" / "checkpoints" / "last.ckpt"
    # Inter-M on the 2-task tokenizer, once that job has ended well (--dependency)
    gen_job = _sbatch_train(
        slurm, tmp_path / "gen2", "train_gen", data, "debug=gen", *gen, "data.batch_size=4", *ddp,
        f"vq_ckpt={vq_ckpt}", f"text.cache_dir={tmp_path / 'gen2' / 'text_cache'}",
        options=[*two, f"--dependency=afterok:{vq_job}"],
    )  # fmt: skip
    # the 1-process runs, here, meanwhile: batches of 8 = 2 tasks x 4
    one = ["data.batch_size=8", "threads=1"]
    tiny_vq = [o for o in TINY_VQ if o != "debug=vq"]  # vq_config adds it
    train(vq_config(synthetic_interhuman_root, tmp_path / "vq1", [*tiny_vq, *vq_steps, *one]))
    _finished(slurm, vq_job, tmp_path / "vq2")
    cfg = _gen_config(synthetic_interhuman_root, vq_ckpt, tmp_path / "gen1", extra=(*gen, *one))
    train(cfg)
    _finished(slurm, gen_job, tmp_path / "gen2")

    for stage in ("vq", "gen"):
        log = Path(f"{tmp_path / stage}2.out").read_text()
        # Lightning took each task's rank from Slurm; the batch is global
        for task in (0, 1):
            assert f"task {task} of 2: rank and world size from Lightning's SLURMEnvironment" in log
        assert "GLOBAL_RANK: 0, MEMBER: 1/2" in log and "GLOBAL_RANK: 1, MEMBER: 2/2" in log
        assert "effective batch 8 = 4 per process x 2 process(es) x 1 accumulated" in log
        _assert_same_weights(_last(tmp_path / f"{stage}1"), _last(tmp_path / f"{stage}2"))
        _single_writer(tmp_path / f"{stage}2")
    records = slurm.sacct(vq_job, gen_job)
    assert [(r["State"], r["NCPUS"]) for r in records] == [("COMPLETED", "2")] * 2, records


def _hold(marker: Path, epoch: int, batch: int) -> list[str]:
    return [
        "+callbacks.hold._target_=slurm_callbacks.HoldForSignal",
        f"+callbacks.hold.marker={marker}",
        f"+callbacks.hold.epoch={epoch}",
        f"+callbacks.hold.batch={batch}",
    ]


def test_a_job_warned_before_its_time_limit_requeues_itself_and_ends_as_the_uninterrupted_run(
    slurm, synthetic_interhuman_root, tmp_path
):
    from test_train_vq import _config as vq_config

    from intermask.train import train

    # 2 epochs of 3 batches, dropout on: the resumed run must continue torch's random stream
    steps = ["trainer.max_epochs=2", "trainer.limit_train_batches=3", "threads=1"]
    run, held = tmp_path / "run", tmp_path / "held"
    # a 1-minute limit, SIGUSR1 10 s before it: slurmctld checks every 30 s and sends the signal
    # when it is due before its next check, 20 to 50 s into the job. The run waits for it in
    # epoch 1, before batch 1.
    job = _sbatch_train(
        slurm, run, "train_vq", f"data.root={synthetic_interhuman_root}", *TINY_VQ, *steps,
        *_hold(held, epoch=1, batch=1),
        options=["--cpus-per-task=1", "--signal=SIGUSR1@10"], time="1",
    )  # fmt: skip
    tiny_vq = [o for o in TINY_VQ if o != "debug=vq"]
    train(vq_config(synthetic_interhuman_root, tmp_path / "whole", [*tiny_vq, *steps]))
    info = _finished(slurm, job, run, timeout=300, release_requeued=True)

    assert int(info["Restarts"]) >= 1, info  # Slurm ran the job again
    log = Path(f"{run}.out").read_text()
    assert held.read_text() == "4\n"  # held at step 4 (epoch 1, batch 1) ...
    # ... saved after that batch, at the end of the step, and requeued itself
    assert f"SIGUSR1: step 5 (epoch 1) saved to {run}/checkpoints/last.ckpt; Slurm job {job} " \
        "requeued" in log, log[-3000:]  # fmt: skip
    assert "(restart 1)" in log  # the sbatch script's line of the second start
    assert f"{run}/checkpoints/last.ckpt (a requeued job?): resuming from it" in log
    whole, resumed = _last(tmp_path / "whole"), _last(run)
    assert resumed["global_step"] == whole["global_step"] == 6
    assert whole["state_dict"].keys() == resumed["state_dict"].keys()
    for name, value in whole["state_dict"].items():
        assert torch.equal(resumed["state_dict"][name], value), name
    for name, state in whole["optimizer_states"][0]["state"].items():
        for key in ("exp_avg", "exp_avg_sq"):
            assert torch.equal(resumed["optimizer_states"][0]["state"][name][key], state[key])
    # every start of the job is in the completion log; the last one completed
    records = slurm.sacct(job)
    assert len(records) == int(info["Restarts"]) + 1 and records[-1]["State"] == "COMPLETED"


def test_scancel_leaves_a_loadable_checkpoint_at_the_current_step(
    slurm, synthetic_interhuman_root, tmp_path
):
    run, held = tmp_path / "run", tmp_path / "held"
    job = _sbatch_train(
        slurm, run, "train_vq", f"data.root={synthetic_interhuman_root}", *TINY_VQ,
        "trainer.max_epochs=2", "trainer.limit_train_batches=3", "threads=1",
        *_hold(held, epoch=0, batch=1), options=["--cpus-per-task=1"],
    )  # fmt: skip
    info = slurm.job(job)
    for _ in range(240):  # the run holds at step 1
        if held.exists():
            break
        info = slurm.job(job)
        assert info["JobState"] in ("PENDING", "RUNNING"), info
        time.sleep(0.5)
    assert held.read_text() == "1\n", info
    slurm.run("scancel", job)  # SIGTERM to the job's tasks, SIGKILL 30 s (KillWait) later
    info = slurm.wait(job, 120)
    assert info["JobState"] == "CANCELLED", info
    log = Path(f"{run}.out").read_text()
    last = run / "checkpoints" / "last.ckpt"
    assert f"SIGTERM at step 2 (epoch 0): state saved to {last}" in log, log[-3000:]
    checkpoint = _last(run)  # loads with weights_only=True
    assert checkpoint["global_step"] == 2 and checkpoint["epoch"] == 0
    assert checkpoint["InteractionDataModule"] == {"train_loader": {"epoch": 0, "batches": 2}}


def _numbers(results: Path) -> dict:
    """results.json without what measures the machine rather than the models."""
    table = json.loads(results.read_text())
    rows = {
        method: {name: value for name, value in metrics.items() if "latency" not in name}
        for method, metrics in table["rows"].items()
    }
    header = {k: v for k, v in table["header"].items() if not k.endswith("_s")}
    return {"header": header, "rows": rows}


def test_the_evaluation_as_a_slurm_job_writes_the_table_of_a_local_run(
    slurm, synthetic_interhuman_root, tmp_path
):
    from test_train_evaluator import TINY_INTERCLIP
    from test_train_evaluator import _config as evaluator_config
    from test_train_gen import _gen_config
    from test_train_vq import _config as vq_config

    from intermask.train import train

    root, quiet = synthetic_interhuman_root, "callbacks.sample_animations=null"
    train(vq_config(root, tmp_path / "vq", [quiet]))
    vq_ckpt = tmp_path / "vq" / "checkpoints" / "last.ckpt"
    train(_gen_config(root, vq_ckpt, tmp_path / "gen", extra=(quiet,)))
    train(evaluator_config("synthetic", root, tmp_path / "ev", TINY_INTERCLIP))

    def evaluate(out: Path, python: str) -> list[str]:
        return [
            python, "-m", "intermask.evaluate", "data=synthetic", f"data.root={root}",
            "data.num_workers=0", "split=train", "mode=interaction",
            f"eval_ckpt={tmp_path / 'ev' / 'checkpoints' / 'last.ckpt'}",
            f"gen_ckpt={tmp_path / 'gen'}", "fast=true", "fast_replications=1",
            "protocol.eval_batch_size=8", "protocol.diversity_pairs=8", "sampler.iterations=2",
            f"hydra.run.dir={out}",
        ]  # fmt: skip

    on_slurm, here = tmp_path / "eval_slurm", tmp_path / "eval_here"
    _documented(*(w for w in evaluate(here, "python")[:-1] if "/" not in w), "--job-name=eval")
    wrapped = shlex.join(evaluate(on_slurm, sys.executable))
    job = slurm.sbatch(
        "--partition=debug", "--cpus-per-task=1", "--mem=3G", "--time=10",
        f"--output={on_slurm}.out", "--job-name=eval", f"--wrap={wrapped}",
    )  # fmt: skip
    local = subprocess.run(
        evaluate(here, sys.executable), cwd=ROOT, env=slurm.job_env(), capture_output=True,
        text=True, timeout=300,
    )  # fmt: skip
    assert local.returncode == 0, local.stderr[-3000:]
    _finished(slurm, job, on_slurm)
    slurm_table, local_table = _numbers(on_slurm / "results.json"), _numbers(here / "results.json")
    assert slurm_table["rows"]["InterMask"]["fid"]["values"]  # a generated row was measured
    assert slurm_table == local_table

    # the Markdown tables too, but for the latency column (the machine's speed)
    def rows(run: Path) -> list[list[str]]:
        lines = (run / "results.md").read_text().splitlines()
        header = next(line.split("|") for line in lines if line.startswith("| Method |"))
        latency = next(i for i, cell in enumerate(header) if "Latency" in cell)
        cells = [line.split("|") for line in lines if line.startswith("| ")]
        return [row[:latency] + row[latency + 1 :] for row in cells]

    assert rows(on_slurm) == rows(here) and len(rows(here)) > 3


def test_a_sweep_job_warned_before_its_time_limit_is_requeued_by_submitit_and_resumes(
    slurm, synthetic_interhuman_root, tmp_path
):
    from test_train_vq import _config as vq_config

    from intermask.train import train

    sweep, held = tmp_path / "sweep", tmp_path / "held"
    steps = ["trainer.max_epochs=2", "trainer.limit_train_batches=3", "threads=1"]
    command = [
        sys.executable, "-m", "intermask.train", "--config-name", "train_vq", "--multirun",
        "hydra/launcher=slurm", "hydra.launcher.partition=debug",
        "hydra.launcher.gpus_per_node=0", "hydra.launcher.tasks_per_node=1",
        "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=2",
        # submitit's USR2 10 s before a 1-minute limit (slurmctld sends it 20 to 50 s in)
        "hydra.launcher.timeout_min=1", "hydra.launcher.signal_delay_s=10",
        f"hydra.sweep.dir={sweep}", f"data.root={synthetic_interhuman_root}", *TINY_VQ, *steps,
        *_hold(held, epoch=1, batch=1),
    ]  # fmt: skip
    launcher = subprocess.Popen(
        command, cwd=ROOT, env=slurm.job_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        tiny_vq = [o for o in TINY_VQ if o != "debug=vq"]
        train(vq_config(synthetic_interhuman_root, tmp_path / "whole", [*tiny_vq, *steps]))
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:  # submitit's folder for the job, named by its id
            folders = [p.name for p in (sweep / ".submitit").glob("*") if p.name.isdigit()]
            if folders:
                break
            time.sleep(0.5)
        (job,) = folders  # one job: no array
        info = slurm.wait(job, deadline - time.monotonic(), release_requeued=True)
        _, errors = launcher.communicate(timeout=120)
    finally:
        launcher.kill()
    assert launcher.returncode == 0, errors[-3000:]
    assert info["JobState"] == "COMPLETED" and int(info["Restarts"]) >= 1, info
    logs = "".join(p.read_text() for p in (sweep / ".submitit" / job).glob("*_log.*"))
    assert "SIGUSR2: step 5 (epoch 1) saved to" in logs and "handing over" in logs, logs[-3000:]
    assert "Caught signal SIGUSR2" in logs and f"Requeued job {job}" in logs  # submitit's
    assert "(a requeued job?): resuming from it" in (sweep / "0" / "train.log").read_text()
    assert held.read_text() == "4\n"
    whole, resumed = _last(tmp_path / "whole"), _last(sweep / "0")
    assert resumed["global_step"] == whole["global_step"] == 6
    for name, value in whole["state_dict"].items():
        assert torch.equal(resumed["state_dict"][name], value), name
