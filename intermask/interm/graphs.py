"""Inter-M's decoding passes replayed as CUDA graphs.

At batch 1 a paper-size decoding pass on a GPU is bound by kernel launches, not by the GPU: a
profile of one interaction showed 135 ms of kernels under about 1 s of host work
(docs/performance.md). A CUDA graph records one forward pass's kernels once per input shape and
replays them with a single launch. The kernels are the same, so the logits are the same; only the
host's work goes.

:class:`GraphedForward` is a drop-in for ``InterMTransformer.forward_with_condition`` that
:func:`~intermask.interm.decoding.generate` takes as ``forward``. Each new combination of input
shapes, dtypes, autocast state and parameter storage is run eagerly, once with the token checks
and twice more as it will be captured, then captured; later calls copy their inputs into the
captured buffers and replay. Off a CUDA device, and wherever capture fails, it runs the eager
forward (a failed capture is logged once and not retried).
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from typing import NamedTuple

import torch

from intermask.interm.model import InterMOutput, InterMTransformer
from intermask.interm.tokens import unchecked_tokens

log = logging.getLogger(__name__)

WARMUP_PASSES = 2  # unchecked eager passes on a side stream before capture (cuBLAS, allocator)


class _Captured(NamedTuple):
    graph: torch.cuda.CUDAGraph
    inputs: tuple[torch.Tensor, ...]  # the static buffers the graph reads
    output: InterMOutput  # the static buffers the graph writes


def _signature(inputs: tuple[torch.Tensor, ...], model: InterMTransformer) -> tuple:
    """What a captured graph is only valid for: input shapes and dtypes, the autocast state and
    the addresses of the weights it read (``.to()`` or a reload that reallocates them)."""
    autocast = torch.is_autocast_enabled("cuda")
    dtype = torch.get_autocast_dtype("cuda") if autocast else None
    storage = tuple(t.data_ptr() for t in (*model.parameters(), *model.buffers()))
    return (*((tuple(t.shape), t.dtype) for t in inputs), autocast, dtype, storage)


class GraphedForward:
    """``forward_with_condition(tokens_a, tokens_b, condition, lengths_in_steps)`` of ``model``,
    one CUDA graph per input signature (see the module docstring). Eval mode only: a training
    model (dropout) or a grad-enabled call runs eagerly. ``failure`` says why a capture failed
    (None while none has)."""

    def __init__(self, model: InterMTransformer, *, enabled: bool = True) -> None:
        self.model, self.enabled = model, enabled
        self._graphs: dict[tuple, _Captured] = {}
        self._pool = None  # one memory pool for every shape: passes replay one at a time
        self.failure: str | None = None

    @property
    def captured(self) -> int:
        """How many input signatures have a graph."""
        return len(self._graphs)

    def _forward(self, *inputs: torch.Tensor) -> InterMOutput:
        return self.model.forward_with_condition(*inputs)

    def __call__(
        self,
        tokens_a: torch.Tensor,
        tokens_b: torch.Tensor,
        condition: torch.Tensor,
        lengths_in_steps: torch.Tensor,
    ) -> InterMOutput:
        inputs = (tokens_a, tokens_b, condition, lengths_in_steps)
        if (
            not self.enabled
            or self.failure is not None
            or tokens_a.device.type != "cuda"
            or self.model.training
            or torch.is_grad_enabled()
        ):
            return self._forward(*inputs)
        key = _signature(inputs, self.model)
        captured = self._graphs.get(key)
        if captured is None:
            captured = self._capture(key, inputs)
            if captured is None:
                return self._forward(*inputs)
        for static, value in zip(captured.inputs, inputs, strict=True):
            static.copy_(value)
        captured.graph.replay()
        return InterMOutput(*(t.clone() for t in captured.output))

    def _capture(self, key: tuple, inputs: tuple[torch.Tensor, ...]) -> _Captured | None:
        static = tuple(t.clone() for t in inputs)
        device = static[0].device
        autocast, dtype = torch.is_autocast_enabled("cuda"), torch.get_autocast_dtype("cuda")

        def unchecked_uncached():
            # autocast's cast cache must be off while capturing: cached casts would be freed
            # after the capture while the graph still reads them. The warm-up runs as captured.
            stack = ExitStack()
            stack.enter_context(unchecked_tokens())
            stack.enter_context(
                torch.autocast("cuda", dtype=dtype, enabled=autocast, cache_enabled=False)
            )
            return stack

        side = torch.cuda.Stream(device=device)
        side.wait_stream(torch.cuda.current_stream(device))
        try:
            with torch.cuda.stream(side):
                self._forward(*static)  # checked: the inputs are valid tokens and lengths
                with unchecked_uncached():
                    for _ in range(WARMUP_PASSES):
                        self._forward(*static)
            torch.cuda.current_stream(device).wait_stream(side)
            if self._pool is None:
                self._pool = torch.cuda.graph_pool_handle()
            graph = torch.cuda.CUDAGraph()
            with unchecked_uncached(), torch.cuda.graph(graph, pool=self._pool):
                output = self._forward(*static)
        except RuntimeError as error:  # an op that cannot be captured: stay eager from now on
            self.failure = f"{type(error).__name__}: {error}"
            log.warning("CUDA graph capture failed, decoding eagerly: %s", self.failure)
            return None
        captured = _Captured(graph, static, InterMOutput(*output))
        self._graphs[key] = captured
        return captured
