"""Count what a training step costs beyond its arithmetic: host-device synchronisations and torch ops.

A host sync is any call that needs a tensor's value on the host (``.item()``,
``bool(t)``, ``float(t)``, ``int(t)``, ``.tolist()``, ``.numpy()``): on a GPU
each one stalls the queue until every launched kernel has finished. On the CPU
the same calls are cheap, but counting them there is how a CPU-only test holds
the training step to zero (docs/model.md, "Training step without host syncs").
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

import torch
from torch.utils._python_dispatch import TorchDispatchMode

SYNC_METHODS = ("item", "__bool__", "__float__", "__int__", "__index__", "tolist", "numpy")


@contextmanager
def count_host_syncs() -> Iterator[Counter]:
    """Patch the value-reading methods of ``torch.Tensor``; the yielded Counter tallies calls by method."""
    counts: Counter = Counter()
    originals = {name: getattr(torch.Tensor, name) for name in SYNC_METHODS}

    def wrap(name: str, fn):
        def counted(self, *args, **kwargs):
            counts[name] += 1
            return fn(self, *args, **kwargs)
        return counted

    try:
        for name, fn in originals.items():
            setattr(torch.Tensor, name, wrap(name, fn))
        yield counts
    finally:
        for name, fn in originals.items():
            setattr(torch.Tensor, name, fn)


class _OpCounter(TorchDispatchMode):
    def __init__(self) -> None:
        super().__init__()
        self.counts: Counter = Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.counts[str(func.overloadpacket)] += 1
        return func(*args, **(kwargs or {}))


@contextmanager
def count_torch_ops() -> Iterator[Counter]:
    """Every aten op dispatched inside the block (forward and backward), by name."""
    mode = _OpCounter()
    with mode:
        yield mode.counts
