"""Data-parallel training on one machine: several processes, one model each, every step's batch
shared between them and their gradients averaged before each optimiser step.

Why: the Mask R-CNN's per-image Python (anchor matching, RoI sampling, NMS) holds one training
process to 15-30 images/s on a GPU it leaves mostly idle; N processes on one GPU, each with its own
CPU core, train N shares of the batch at once. The processes talk over gloo on localhost; the
gradients (a few MB) are averaged on the CPU, so any device works and no NCCL is needed (NCCL
refuses two ranks on one GPU).

Every process starts from the same weights (the leader's are broadcast) and applies the same
averaged gradients, so the replicas stay equal; only the leader (rank 0) logs, validates and saves.
"""

from __future__ import annotations

import os
import socket
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from torch import nn


@dataclass(frozen=True)
class Ranks:
    """This process's place among ``size`` training processes (``Ranks()``: training alone)."""

    rank: int = 0
    size: int = 1

    @property
    def leader(self) -> bool:
        """The process that logs, validates and saves."""
        return self.rank == 0

    def batches(self, order: Sequence[int], batch: int) -> list[list[int]]:
        """This process's batches of an epoch in ``order``: step ``s`` of rank ``r`` takes images
        ``[(s * size + r) * batch, ... + batch)``. Alone, the last batch may be short; together,
        the images that would leave some process without a whole batch wait for another epoch's
        order, so every process takes every step (each step is a collective)."""
        if self.size == 1:
            return [list(order[k : k + batch]) for k in range(0, len(order), batch)]
        steps = len(order) // (batch * self.size)
        start = self.rank * batch
        return [
            list(order[s * batch * self.size + start : s * batch * self.size + start + batch])
            for s in range(steps)
        ]

    def same_as_leader(self, model: nn.Module) -> None:
        """Overwrite this process's parameters and buffers with the leader's."""
        if self.size == 1:
            return
        for tensor in [*model.parameters(), *model.buffers()]:
            staged = tensor.detach().cpu()
            dist.broadcast(staged, src=0)
            tensor.data.copy_(staged)

    def average_gradients(self, model: nn.Module) -> None:
        """Replace every parameter's gradient with the mean over the processes. A parameter with no
        gradient here (a head no instance of this share reached) counts as zeros, and gets the mean,
        so every replica's optimiser sees the same gradients."""
        if self.size == 1:
            return
        params = [p for p in model.parameters() if p.requires_grad]
        for p in params:
            if p.grad is None:
                p.grad = torch.zeros_like(p)
        grads = torch.cat([p.grad.detach().reshape(-1) for p in params])
        flat = grads.float().cpu()  # gloo reduces CPU tensors; one copy each way per step
        dist.all_reduce(flat)
        flat = (flat / self.size).to(grads.device)
        offset = 0
        for p in params:
            n = p.numel()
            p.grad.copy_(flat[offset : offset + n].view_as(p.grad))
            offset += n

    def mean(self, values: dict[str, float]) -> dict[str, float]:
        """The mean of each value over the processes (each process's losses of a step)."""
        if self.size == 1:
            return values
        keys = sorted(values)
        t = torch.tensor([values[k] for k in keys], dtype=torch.float64)
        dist.all_reduce(t)
        return {k: float(v) / self.size for k, v in zip(keys, t.tolist(), strict=True)}

    def replicas_agree(self, model: nn.Module) -> bool:
        """Whether every process's parameters equal the leader's, bit for bit (the same averaged
        gradients applied to the same weights give the same weights; anything else is a bug that
        would train N models and save one). The same answer in every process."""
        if self.size == 1:
            return True
        local = torch.stack([p.detach().double().sum() for p in model.parameters()]).cpu()
        leader = local.clone()
        dist.broadcast(leader, src=0)
        agree = torch.tensor([int(torch.equal(local, leader))])
        dist.all_reduce(agree, op=dist.ReduceOp.MIN)
        return bool(agree.item())

    def from_leader(self, value: int) -> int:
        """The leader's ``value`` (a decision it took alone, such as the epochs that fit)."""
        if self.size == 1:
            return value
        t = torch.tensor([value], dtype=torch.int64)
        dist.broadcast(t, src=0)
        return int(t.item())


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


REFUSED = 2  # the run's exit status when a process stops on one of ``refused``


def _entry(
    rank: int,
    size: int,
    port: int,
    fn: Callable[..., int],
    args: tuple[Any, ...],
    result: Any,
    refused: tuple[type[BaseException], ...],
    was_refused: Any,
) -> None:
    os.environ["MASTER_ADDR"], os.environ["MASTER_PORT"] = "127.0.0.1", str(port)
    dist.init_process_group("gloo", rank=rank, world_size=size)
    try:
        try:
            code = fn(*args, Ranks(rank, size))
        except refused as exc:
            print(f"error: {exc}", file=sys.stderr, flush=True)
            # Said before the others, left waiting in a collective, fail on the broken group.
            was_refused.value = 1
            os._exit(REFUSED)
        if rank == 0:
            result.value = code
        # The others wait for the leader's validation and saving: gloo aborts a process whose
        # group is torn down while a peer is still connected.
        dist.barrier()
    finally:
        dist.destroy_process_group()


def run_ranks(
    fn: Callable[..., int], size: int, *args: Any, refused: tuple[type[BaseException], ...] = ()
) -> int:
    """Run ``fn(*args, ranks)`` in ``size`` processes and return the leader's exit status. A
    process that raises one of ``refused`` (a bad input found only while running) prints
    ``error: <message>`` and ends the run with status 2; any other exception ends it raised here,
    with its traceback."""
    if size == 1:
        return fn(*args, Ranks())
    context = mp.get_context("spawn")
    result, was_refused = context.Value("i", 1), context.Value("i", 0)
    try:
        mp.spawn(
            _entry, args=(size, _free_port(), fn, args, result, refused, was_refused), nprocs=size, join=True
        )
    except (mp.ProcessExitedException, mp.ProcessRaisedException):
        if not was_refused.value:
            raise
        return REFUSED
    return int(result.value)


__all__ = ["Ranks", "run_ranks"]
