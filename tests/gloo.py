"""Helpers for tests that run a function on several CPU processes joined by gloo."""

from __future__ import annotations

import socket
from collections.abc import Callable

import torch
import torch.distributed as dist
import torch.multiprocessing as mp


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _entry(rank: int, world: int, port: int, work: Callable[[int, int], None]) -> None:
    torch.set_num_threads(1)  # a forked child must not reuse the parent's OpenMP pool
    dist.init_process_group(
        "gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world
    )
    try:
        work(rank, world)
    finally:
        dist.destroy_process_group()


def run_on_processes(
    work: Callable[[int, int], None], *, world: int, start_method: str = "fork"
) -> None:
    """``work(rank, world)`` on ``world`` processes in one gloo group (a module-level function,
    so that spawned processes can import it)."""
    mp.start_processes(
        _entry, args=(world, free_port(), work), nprocs=world, join=True, start_method=start_method
    )
