"""The cluster path without a cluster: a 2-job sweep through submitit's local executor, and the
Slurm launcher config's sbatch parameters. tests/slurm/ submits the same jobs to a real Slurm."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from lightning.pytorch import Callback

from intermask.train import CONFIG_DIR

ROOT = Path(__file__).resolve().parents[1]


def _local_sweep(sweep: Path, data_root: Path, *overrides: str) -> list[str]:
    """A tiny train_vq multirun through submitit's local executor into ``sweep``."""
    return [
        sys.executable,
        "-m",
        "intermask.train",
        "--config-name",
        "train_vq",
        "--multirun",
        "hydra/launcher=submitit_local",
        "hydra.launcher.timeout_min=10",
        f"hydra.sweep.dir={sweep}",
        f"data.root={data_root}",
        "debug=vq",
        "trainer.limit_val_batches=1",
        "callbacks.sample_animations=null",
        *overrides,
    ]


def test_a_two_job_sweep_runs_through_the_local_executor(synthetic_interhuman_root, tmp_path):
    sweep = tmp_path / "sweep"
    command = _local_sweep(
        sweep,
        synthetic_interhuman_root,
        "model.net.quantizer.codebook_size=16,32",  # the swept value: two jobs
        "trainer.max_epochs=1",
        "trainer.limit_train_batches=2",
    )
    environment = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(command, cwd=ROOT, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    # the jobs went through submitit (its job folders), not Hydra's in-process launcher
    assert len(list((sweep / ".submitit").glob("*/*_result.pkl"))) == 2
    for job, codes in ((0, 16), (1, 32)):
        run = sweep / str(job)
        assert (run / "checkpoints" / "last.ckpt").is_file()
        record = json.loads((run / "run_record.json").read_text())
        assert record["job"] == "train_vq"
        assert f"codebook_size: {codes}" in (run / "config.yaml").read_text()


def test_the_slurm_launcher_renders_the_expected_sbatch_parameters():
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "train_vq",
            overrides=[
                "hydra/launcher=slurm",
                "hydra.launcher.partition=gpu",
                "hydra.launcher.gpus_per_node=4",
                "hydra.launcher.account=lab",
            ],
            return_hydra_config=True,
        )
    launcher = cfg.hydra.launcher
    assert (
        launcher._target_ == "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"
    )
    from submitit.slurm.slurm import _make_sbatch_string

    script = _make_sbatch_string(
        command="python -m intermask.train",
        folder="logs/%j",
        job_name="train_vq",
        partition=launcher.partition,
        time=launcher.timeout_min,
        nodes=launcher.nodes,
        ntasks_per_node=launcher.tasks_per_node,
        cpus_per_task=launcher.cpus_per_task,
        gpus_per_node=launcher.gpus_per_node,
        mem=f"{launcher.mem_gb}GB",
        account=launcher.account,
        signal_delay_s=launcher.signal_delay_s,
    )
    for line in (
        "#SBATCH --partition=gpu",
        "#SBATCH --time=2880",
        "#SBATCH --nodes=1",
        "#SBATCH --ntasks-per-node=4",  # one task per GPU: Lightning's SLURM environment
        "#SBATCH --gpus-per-node=4",
        "#SBATCH --cpus-per-task=8",
        "#SBATCH --mem=64GB",
        "#SBATCH --account=lab",
        "#SBATCH --signal=USR2@",  # submitit's pre-emption signal, ahead of the time limit
    ):
        assert line in script, (line, script)


def test_the_slurm_preset_composes_with_the_generator_job():
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "train_gen",
            overrides=["hydra/launcher=slurm", "vq_ckpt=x"],
            return_hydra_config=True,
        )
    assert cfg.hydra.launcher.tasks_per_node == cfg.hydra.launcher.gpus_per_node


class PreemptOnce(Callback):
    """Sends this process the pre-emption signal submitit listens for (USR2) at batch 1 of
    epoch 1, once per run folder (the requeued job finds the marker and runs on)."""

    def __init__(self, marker: str) -> None:
        self.marker = Path(marker)

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        if trainer.current_epoch == 1 and batch_idx == 1 and not self.marker.exists():
            self.marker.touch()
            os.kill(os.getpid(), signal.SIGUSR2)


@pytest.mark.slow
def test_a_preempted_job_is_requeued_and_resumes_its_checkpoint(
    synthetic_interhuman_root, tmp_path
):
    sweep = tmp_path / "sweep"
    command = _local_sweep(
        sweep,
        synthetic_interhuman_root,
        "model.net.quantizer.codebook_size=16",
        "trainer.max_epochs=2",
        "trainer.limit_train_batches=3",
        "+callbacks.preempt._target_=test_cluster.PreemptOnce",
        f"+callbacks.preempt.marker={sweep / '0' / 'preempted'}",
    )
    environment = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join([str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(command, cwd=ROOT, env=environment, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    run = sweep / "0"
    assert (run / "preempted").is_file()  # the signal was sent ...
    logs = "".join(p.read_text() for p in (sweep / ".submitit").rglob("*_log.*"))
    assert "Caught signal SIGUSR2" in logs and "Requeued job" in logs  # ... submitit requeued
    # the run saved last.ckpt at the end of the signalled batch, then handed over to submitit
    assert "SIGUSR2: step 5 (epoch 1) saved to" in logs and "handing over" in logs
    train_log = (run / "train.log").read_text()
    assert "already holds" in train_log and "resuming from it" in train_log
    checkpoint = torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)
    assert checkpoint["global_step"] == 6  # resumed at step 5, the last batch of epoch 1 run


def test_the_docs_show_the_sbatch_script_as_it_is():
    script = (ROOT / "tools" / "slurm" / "train.sbatch").read_text()
    assert f"```bash\n{script}```" in (ROOT / "docs" / "cluster.md").read_text()
    # tests/slurm submits it as it is; it must stay runnable
    assert (ROOT / "tools" / "slurm" / "train.sbatch").stat().st_mode & 0o111
