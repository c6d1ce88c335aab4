"""InteractionSuccess against the plain per-sample function: overall and per-action rates,
sample-id de-duplication, a 2-process DDP run, and its errors."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from torch.utils.data import DistributedSampler

from intermask.data.common import single_threaded
from intermask.data.synthetic import generate_clip
from intermask.metrics import InteractionSuccess
from intermask.metrics.interaction import (
    ACTIONS,
    CHECKS,
    SuccessThresholds,
    interaction_success,
    judge,
)

CHOSEN = ("handshake", "wave", "chase", "bow", "push")


def _batch() -> dict[str, torch.Tensor]:
    """10 samples: 2 clips each of CHOSEN, the second of each with the reactor frozen (fails)."""
    with single_threaded():
        clips = [generate_clip(seed=3, index=i, action=a) for a in CHOSEN for i in range(2)]
    frames = max(c.frames for c in clips)
    joints = torch.zeros(len(clips), frames, 2, 22, 3)
    for row, clip in enumerate(clips):
        motion = clip.positions.transpose(0, 1).float()  # (T, 2, 22, 3)
        if row % 2:
            reactor = 2 - clip.actor  # index of the reactor
            motion[:, reactor] = motion[:1, reactor]
        joints[row, : clip.frames] = motion
    return {
        "joints": joints,
        "lengths": torch.tensor([c.frames for c in clips]),
        "action_ids": torch.tensor([c.action_id for c in clips]),
        "actors": torch.tensor([c.actor for c in clips]),
    }


@pytest.fixture(scope="module")
def batch() -> dict[str, torch.Tensor]:
    return _batch()


def test_rates_equal_the_plain_computation(batch):
    plain = interaction_success(
        batch["joints"], batch["lengths"], batch["action_ids"], batch["actors"]
    )
    assert plain.tolist() == [True, False] * len(CHOSEN)
    metric = InteractionSuccess()
    metric.update(
        batch["joints"][:4], batch["lengths"][:4], batch["action_ids"][:4], batch["actors"][:4]
    )
    metric.update(
        batch["joints"][4:], batch["lengths"][4:], batch["action_ids"][4:], batch["actors"][4:]
    )
    rates = metric.compute()
    assert float(rates.overall) == pytest.approx(plain.double().mean().item())
    for index in range(len(ACTIONS)):
        count = int((batch["action_ids"] == index).sum())
        assert int(rates.counts[index]) == count
        if count:
            expected = plain[batch["action_ids"] == index].double().mean().item()
            assert float(rates.per_action[index]) == pytest.approx(expected)
        else:
            assert torch.isnan(rates.per_action[index])
    values = rates.as_dict()
    assert values["success"] == pytest.approx(0.5)
    assert values["success/handshake"] == pytest.approx(0.5)
    fails = {f"fails/{a}/{check.name}" for a in CHOSEN for check in CHECKS[a]}
    counts = {f"samples/{a}" for a in CHOSEN}
    signals = {f"signal/{a}/{check.name}" for a in CHOSEN for check in CHECKS[a]}
    assert set(values) == (
        {"success"} | {f"success/{a}" for a in CHOSEN} | counts | fails | signals
    )
    assert values["samples/handshake"] == 2.0


def test_failure_shares_name_the_checks_the_frozen_reactors_miss(batch):
    metric = InteractionSuccess()
    metric.update(batch["joints"], batch["lengths"], batch["action_ids"], batch["actors"])
    rates = metric.compute()
    values = rates.as_dict()
    # one clip of two per action has its reactor frozen: it misses the reactor's part
    missed = {
        "handshake": {"hand_gap<=hand_gap", "arrival_lead>=lead"},
        "wave": {"reactor_raise>=raise_height"},
        "chase": {"chase_run>=run", "min_distance>=escape", "spacing>=spacing"},
        "bow": {"reactor_bow>=bow_pitch"},
        "push": {"recoil>=push_recoil"},
    }
    for action, names in missed.items():
        for check in CHECKS[action]:
            expected = 0.5 if check.name in names else 0.0
            assert values[f"fails/{action}/{check.name}"] == expected, (action, check.name)
    for index, action in enumerate(ACTIONS):
        row = rates.failures[index]
        if action in missed:
            assert not row[: len(CHECKS[action])].isnan().any()
            assert row[len(CHECKS[action]) :].isnan().all()  # past the action's checks
        else:
            assert row.isnan().all()  # no samples


def test_signal_medians_are_those_of_the_readings_judged(batch):
    """Per action and check, the median (torch's: the lower middle value) of what the check
    read on each sample, the reading ``judge`` reports: of two chases, the one whose fleer is
    frozen sets both medians (it never runs, and the chaser reaches it)."""
    metric = InteractionSuccess()
    metric.update(batch["joints"], batch["lengths"], batch["action_ids"], batch["actors"])
    rates, values = metric.compute(), metric.compute().as_dict()
    for row, action in enumerate(CHOSEN):
        readings = [
            judge(
                batch["joints"][index, : int(batch["lengths"][index])],
                action=action,
                actor=int(batch["actors"][index]) - 1,
                thresholds=SuccessThresholds(),
            )[1]
            for index in (2 * row, 2 * row + 1)
        ]
        for slot, check in enumerate(CHECKS[action]):
            lower = min(float(reading[check.signal]) for reading in readings)
            assert values[f"signal/{action}/{check.name}"] == pytest.approx(lower, abs=1e-12)
            assert float(rates.signals[ACTIONS.index(action), slot]) == pytest.approx(lower)
        assert rates.signals[ACTIONS.index(action), len(CHECKS[action]) :].isnan().all()
    assert values["signal/chase/chase_run>=run"] == 0.0  # the frozen fleer never runs
    assert values["signal/chase/min_distance>=escape"] < SuccessThresholds().escape
    assert rates.signals[ACTIONS.index("hug")].isnan().all()  # no samples


def test_duplicated_sample_ids_count_once(batch):
    metric = InteractionSuccess()
    ids = torch.arange(10)
    metric.update(
        batch["joints"], batch["lengths"], batch["action_ids"], batch["actors"], sample_ids=ids
    )
    # a DistributedSampler's padding repeats the first samples (passes) on a later rank
    metric.update(
        batch["joints"][:1],
        batch["lengths"][:1],
        batch["action_ids"][:1],
        batch["actors"][:1],
        sample_ids=ids[:1],
    )
    assert float(metric.compute().overall) == pytest.approx(0.5)


def test_errors():
    metric = InteractionSuccess()
    with pytest.raises(
        ValueError, match=r"InteractionSuccess.compute\(\) called before any update"
    ):
        metric.compute()
    joints = torch.zeros(2, 6, 2, 22, 3)
    with pytest.raises(
        ValueError, match=r"joints of shape \(B, T, 2, 22, 3\), got \(2, 6, 2, 21, 3\)"
    ):
        metric.update(joints[..., :21, :], torch.tensor([6, 6]), torch.tensor([0, 0]))
    with pytest.raises(ValueError, match=r"sample_ids must have shape \(2,\)"):
        metric.update(
            joints, torch.tensor([6, 6]), torch.tensor([0, 0]), sample_ids=torch.arange(3)
        )


def _run(rank: int, world: int, data: dict[str, torch.Tensor]) -> torch.Tensor:
    metric = InteractionSuccess()
    shard = torch.tensor(
        list(DistributedSampler(range(10), num_replicas=world, rank=rank, shuffle=True, seed=1))
    )
    for ids in shard.split(2):
        metric.update(
            data["joints"][ids],
            data["lengths"][ids],
            data["action_ids"][ids],
            data["actors"][ids],
            sample_ids=ids,
        )
    rates = metric.compute()
    return torch.cat(
        (
            rates.overall[None],
            rates.per_action,
            rates.counts.double(),
            rates.failures.flatten(),
            rates.signals.flatten(),
        )
    )


def _worker(rank: int, world: int, port: int, out_dir: str) -> None:
    torch.set_num_threads(1)  # a forked child must not reuse the parent's OpenMP pool
    data = torch.load(Path(out_dir) / "batch.pt", weights_only=True)
    dist.init_process_group(
        "gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world
    )
    try:
        torch.save(_run(rank, world, data), Path(out_dir) / f"rank{rank}.pt")
    finally:
        dist.destroy_process_group()


def test_ddp_over_three_processes_gives_the_single_process_rates(batch, tmp_path):
    """3 ranks over 10 samples: the sampler pads to 12, the padding is dropped by id. Forked
    children inherit the imports (as in test_ddp.py), so the run takes seconds."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    world = 3
    torch.save(batch, tmp_path / "batch.pt")
    mp.start_processes(
        _worker, args=(world, port, str(tmp_path)), nprocs=world, join=True, start_method="fork"
    )
    single = _run(0, 1, batch)
    for rank in range(world):
        assert torch.allclose(
            torch.load(tmp_path / f"rank{rank}.pt", weights_only=True), single, equal_nan=True
        )
