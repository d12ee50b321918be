"""Count what a training step costs beyond its arithmetic: host-device synchronisations and torch ops.

A host sync is any call that needs a tensor's value on the host (``.item()``,
``bool(t)``, ``float(t)``, ``int(t)``, ``.tolist()``, ``.numpy()``): on a GPU
each one stalls the queue until every launched kernel has finished. On the CPU
the same calls are cheap, but counting them there is how a CPU-only test holds
the training step to zero (docs/model.md, "Training step without host syncs").
On CUDA only calls on device tensors count (reading a CPU scalar waits for
nothing), and CUDA's own sync debug mode adds what no Python method shows (a
copy from pageable memory, ``nonzero``).
"""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

import torch
from torch.utils._python_dispatch import TorchDispatchMode

SYNC_METHODS = ("item", "__bool__", "__float__", "__int__", "__index__", "tolist", "numpy")


@contextmanager
def count_host_syncs(device: torch.device | str = "cpu") -> Iterator[Counter]:
    """Patch the value-reading methods of ``torch.Tensor``; the yielded Counter tallies calls by method. On a
    CUDA ``device`` the calls on CPU tensors are left out and CUDA's sync debug warnings are counted as
    ``cuda_sync``."""
    counts: Counter = Counter()
    originals = {name: getattr(torch.Tensor, name) for name in SYNC_METHODS}
    cuda = torch.device(device).type == "cuda"

    def wrap(name: str, fn):
        def counted(self, *args, **kwargs):
            if not (cuda and self.device.type == "cpu"):
                counts[name] += 1
            return fn(self, *args, **kwargs)
        return counted

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            for name, fn in originals.items():
                setattr(torch.Tensor, name, wrap(name, fn))
            if cuda:
                torch.cuda.set_sync_debug_mode("warn")
            yield counts
        finally:
            if cuda:
                torch.cuda.set_sync_debug_mode("default")
            for name, fn in originals.items():
                setattr(torch.Tensor, name, fn)
    # the sync warning's own text (setting the mode also warns that it is a prototype)
    n_cuda = sum("called a synchronizing CUDA operation" in str(w.message) for w in caught)
    if n_cuda:
        counts["cuda_sync"] += n_cuda


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
