"""The whole training step replayed as CUDA graphs (``train.cuda_graphs``; docs/model.md, "Whole-step CUDA graphs").

A gpu-paper step launches about 2,000 kernels, and on an H100 the host's dispatch of them, not the device,
bounds the step. Captured once, a step replays with one launch. What changes from step to step lives in device
tensors that the graph reads: the ray indices (drawn by the CPU generator as in an eager step and copied from
pinned memory), Adam's learning rate (a device tensor the scheduler fills) and the proposal anneal exponent.
The jitter generator is registered with every graph, so each replay draws new numbers. What the schedule
decides in Python (whether the proposal nets get gradients, whether their weights are annealed at all) picks
one of at most four graphs. Each is captured when the schedule first needs it, and all of them share one memory
pool: a replay's outputs are copied out before the next replay, so no graph reads memory another one wrote.
A step that cannot be captured (a configuration with an op that waits for the device, say) is named on stderr
and training goes on with eager steps, the same rays and the same random numbers.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from .trainer import Trainer

EAGER_STEPS = 3
"""Eager steps before the first capture: they create Adam's moments and every kernel's lazy state."""


class GraphCaptureError(RuntimeError):
    """A step could not be captured (an op that syncs or allocates on the host, say): the trainer goes on eagerly."""


@dataclasses.dataclass
class CapturedStep:
    graph: torch.cuda.CUDAGraph
    names: list[str]
    grad_names: list[str]
    flat: torch.Tensor
    """The graph's one output: every loss term and their sum, then the terms' and the gradients' finite flags."""


class StepGraphs:
    """Captures and replays a trainer's step; ``Trainer.train_step`` calls ``run`` once ``ready``."""

    def __init__(self, trainer: Trainer) -> None:
        self.trainer = trainer
        device = trainer.device
        self.indices = torch.zeros(trainer.config.train.batch_rays, dtype=torch.long, device=device)
        self.anneal = torch.ones((), device=device)
        self.captured: dict[tuple[bool, bool], CapturedStep] = {}
        self.pool: tuple[int, int] | None = None
        self.eager_left = EAGER_STEPS

    def ready(self) -> bool:
        """Whether the next step replays (after ``EAGER_STEPS`` eager ones)."""
        return self.eager_left <= 0

    def eager_step_done(self) -> None:
        self.eager_left -= 1

    def key(self, step: int) -> tuple[bool, bool]:
        """The schedule's Python branches at ``step``: proposal gradients, annealed proposal weights."""
        schedule = self.trainer.model.schedule
        return schedule.updates_proposals(step), schedule.anneal(step) != 1.0

    def run(self, step: int, indices: torch.Tensor) -> tuple[list[str], torch.Tensor, torch.Tensor, list[str],
                                                              torch.Tensor]:
        """One step on the CPU-drawn ray ``indices``: what ``Trainer.step_body`` returns, copied out of the graph."""
        key = self.key(step)
        captured = self.captured.get(key) or self._capture(key, step)
        self.indices.copy_(indices.pin_memory(), non_blocking=True)
        if key[1]:
            self.anneal.fill_(self.trainer.model.schedule.anneal(step))
        captured.graph.replay()
        flat = captured.flat.clone()
        n_v, n_t = len(captured.names) + 1, len(captured.names)
        return captured.names, flat[:n_v], flat[n_v : n_v + n_t], captured.grad_names, flat[n_v + n_t :]

    def _capture(self, key: tuple[bool, bool], step: int) -> CapturedStep:
        """Record the step of ``key``'s branches; ``step`` (one with those branches) is what the model is told.

        Raises ``GraphCaptureError`` with Adam set up for eager steps and the jitter generator as it was before.
        """
        trainer = self.trainer
        jitter = trainer.jitter_generator.get_state()
        try:
            return self._record(key, step)
        except Exception as exc:
            lr = trainer.last_lr()  # the schedule's value, not a float32 tensor's
            for group in trainer.optimizer.param_groups:  # Adam as an eager run has it
                group["capturable"], group["lr"] = False, lr
            # a capture that CUDA invalidated can leave a registered generator in its capturing state
            trainer.jitter_generator = torch.Generator(device=trainer.device)
            trainer.jitter_generator.set_state(jitter)
            raise GraphCaptureError(f"capturing the step at step {step} failed ({type(exc).__name__}: {exc})") from exc

    def _record(self, key: tuple[bool, bool], step: int) -> CapturedStep:
        trainer = self.trainer
        optimizer = trainer.optimizer
        for group in optimizer.param_groups:
            # a learning rate baked into the graph would never decay: Adam reads it from the device instead
            group["capturable"] = True
            if not isinstance(group["lr"], torch.Tensor):
                group["lr"] = torch.tensor(float(group["lr"]), device=trainer.device)
        moments = len(optimizer.state)
        graph = torch.cuda.CUDAGraph()
        graph.register_generator_state(trainer.jitter_generator)
        with torch.cuda.graph(graph, pool=self.pool):
            batch = trainer.train_rays.batch(self.indices)
            names, values, terms_ok, grad_names, grads_ok = trainer.step_body(
                batch, step, anneal=self.anneal if key[1] else 1.0, cache_casts=False)
            flat = torch.cat([values, terms_ok.float(), grads_ok.float()])
        if len(optimizer.state) != moments:
            # moments created inside the capture would be zeroed again by every replay
            raise RuntimeError(f"parameters first trained at step {step} have no Adam moments outside the CUDA graph; "
                               "train.cuda_graphs needs every parameter trained in the eager steps before it")
        self.pool = graph.pool()
        self.captured[key] = CapturedStep(graph, names, grad_names, flat)
        return self.captured[key]
