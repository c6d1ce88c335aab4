"""A one-node Slurm for the ``slurm`` tests: tests/slurm/slurm_up.sh starts munged, slurmctld and
slurmd in a session folder (installing Debian's packages when missing), the tests submit real
jobs to it, and slurm_down.sh stops it at the end of the session, jobs still queued included.
Not root, no apt-get or no package: every test here skips with the script's reason."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
UP, DOWN = HERE / "slurm_up.sh", HERE / "slurm_down.sh"
# what `scontrol show job` calls a job that will not run again
FINISHED = {
    "BOOT_FAIL",
    "CANCELLED",
    "COMPLETED",
    "DEADLINE",
    "FAILED",
    "NODE_FAIL",
    "OUT_OF_MEMORY",
    "PREEMPTED",
    "TIMEOUT",
}


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class SlurmCluster:
    """The running cluster: its folder, and its client commands with ``SLURM_CONF`` set."""

    folder: Path
    env: dict[str, str] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)  # the commands run, for failure messages

    def run(self, *command: str, check: bool = True, timeout: float = 60) -> str:
        self.log.append(" ".join(command))
        done = subprocess.run(
            command, env=self.env, capture_output=True, text=True, timeout=timeout
        )
        if check and done.returncode != 0:
            raise AssertionError(f"{' '.join(command)} failed ({done.returncode}): {done.stderr}")
        return done.stdout

    def job_env(self, **extra: str) -> dict[str, str]:
        """The environment sbatch passes on to a job (``--export=ALL``, sbatch's default): this
        Python for the sbatch script, one intra-op thread per process (the tasks share the
        node's cores), and tests/slurm on the path for the callbacks the tests add."""
        path = os.pathsep.join(
            [str(HERE), str(ROOT / "tests"), *filter(None, [self.env.get("PYTHONPATH")])]
        )
        return {
            **self.env,
            "PYTHON": sys.executable,
            "OMP_NUM_THREADS": "1",
            "PYTHONPATH": path,
            **extra,
        }

    def sbatch(self, *arguments: str, env: dict[str, str] | None = None, cwd: Path = ROOT) -> str:
        """Submit; the job id."""
        command = ["sbatch", "--parsable", *arguments]
        self.log.append(" ".join(command))
        done = subprocess.run(
            command, env=env or self.job_env(), cwd=cwd, capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 0, f"{' '.join(command)}: {done.stderr}"
        return done.stdout.strip().split(";")[0]

    def jobs(self, job_id: str) -> list[dict[str, str]]:
        """``scontrol show job`` as dicts (JobId, JobState, Reason, Restarts, ExitCode, ...): one
        per job, or per task of a job array (``ArrayJobId``, ``ArrayTaskId``)."""
        text = self.run("scontrol", "show", "job", "--oneliner", job_id)
        return [dict(re.findall(r"(\w+)=(\S*)", line)) for line in text.splitlines() if line]

    def job(self, job_id: str) -> dict[str, str]:
        (info,) = self.jobs(job_id)
        return info

    def wait(self, job_id: str, timeout: float, *, release_requeued: bool = False) -> dict:
        """Poll until the job has finished; its last ``scontrol show job``.

        ``release_requeued``: Slurm holds a requeued batch job for two minutes before it may
        start again (Reason=BeginTime); move its start to now instead of waiting them out."""
        deadline = time.monotonic() + timeout
        while True:
            info = self.job(job_id)
            if info.get("JobState") in FINISHED:
                return info
            if (
                release_requeued
                and info.get("JobState") == "PENDING"
                and info.get("Reason") == "BeginTime"
                and int(info.get("Restarts", "0")) > 0
            ):
                self.run("scontrol", "update", f"JobId={job_id}", "StartTime=now")
            if time.monotonic() > deadline:
                self.run("scancel", job_id, check=False)
                raise AssertionError(f"job {job_id} did not finish in {timeout} s: {info}")
            time.sleep(0.5)

    def sacct(self, *job_ids: str) -> list[dict[str, str]]:
        """The job completion records of ``job_ids`` (``sacct --completion``: this cluster has
        no accounting daemon; slurmctld writes each finished run of a job to jobcomp.txt, and
        sacct reads it there). Raw job ids: this sacct does not know array ids (1_0)."""
        fields = "JobID,JobName,Partition,State,ExitCode,Start,End,Elapsed,NCPUS,NodeList"
        out = self.run(
            "sacct", "--completion", "--parsable2", "--noheader", "-o", fields,
            *(f"--jobs={job}" for job in job_ids),
        )  # fmt: skip
        names = fields.split(",")
        return [dict(zip(names, line.split("|"), strict=True)) for line in out.splitlines()]


@pytest.fixture(scope="session")
def slurm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SlurmCluster]:
    if os.name != "posix" or sys.platform != "linux":
        pytest.skip("the one-node Slurm runs on Linux")
    folder = tmp_path_factory.mktemp("slurm")
    env = {
        **os.environ,
        "SLURM_CONF": str(folder / "slurm.conf"),
        "SLURM_TEST_CTLD_PORT": str(_free_port()),
        "SLURM_TEST_SLURMD_PORT": str(_free_port()),
    }
    for name in [n for n in env if n.startswith(("SLURM_JOB", "SLURM_STEP", "SLURM_PROCID"))]:
        del env[name]  # a test session inside a Slurm job must not look like one of our jobs
    started = subprocess.run(
        [str(UP), str(folder)], env=env, capture_output=True, text=True, timeout=900
    )
    if started.returncode == 3:
        reason = [line for line in started.stderr.splitlines() if line.startswith("skip: ")]
        pytest.skip(reason[-1][len("skip: ") :] if reason else started.stderr.strip())
    try:
        assert started.returncode == 0, f"slurm_up.sh failed:\n{started.stderr}"
        yield SlurmCluster(folder, env)
    finally:
        subprocess.run([str(DOWN), str(folder)], env=env, capture_output=True, timeout=180)
