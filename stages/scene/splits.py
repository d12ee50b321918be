"""Train/test splits over frames."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

SplitMethod = Literal["alternate", "every_n", "fraction"]


def make_split(n_frames: int, method: SplitMethod = "alternate", n: int = 10, test_fraction: float = 0.1) -> list[str]:
    """``"train"``/``"test"`` per frame, in frame order.

    - ``alternate``: even frames test, odd frames train (the reference code's
      choice for synthetic sets);
    - ``every_n``: every n-th frame (starting at n // 2) is a test frame;
    - ``fraction``: nerfstudio's rule, which the reference code's parser of real
      sets inherits: ``ceil((1 - test_fraction) * n)`` train frames evenly
      spaced from the first to the last (``linspace``, truncated), the rest test.
    """
    if n_frames <= 0:
        return []
    idx = np.arange(n_frames)
    if method == "alternate":
        test = idx % 2 == 0
    elif method == "every_n":
        if n < 2:
            raise ValueError(f"every_n split needs n >= 2, got {n}")
        test = (idx % n) == (n // 2)
    elif method == "fraction":
        if not 0.0 < test_fraction < 1.0:
            raise ValueError(f"test_fraction must lie in (0, 1), got {test_fraction}")
        train = np.linspace(0, n_frames - 1, math.ceil(n_frames * (1.0 - test_fraction)), dtype=int)
        test = ~np.isin(idx, train)
    else:
        raise ValueError(f"unknown split method {method!r}; use alternate, every_n or fraction")
    if test.all():  # a single frame: keep it for training
        test[:] = False
    return ["test" if t else "train" for t in test]


def reference_split(file_paths: Sequence[str], blender: bool) -> tuple[list[str], str]:
    """The split the reference code gives a dataset whose transforms.json names none (no per-frame ``split``, no
    split lists), as the published datasets ship: every other frame in file order for the Blender form (its
    synthetic sets; nerfstudio's interval rule, even positions held out), nerfstudio's 90/10 ``fraction`` over the
    frames sorted by file path for the nerfstudio form (its real sets). Returns the splits in file order and a
    note saying which rule was applied."""
    n = len(file_paths)
    if blender:
        return make_split(n, "alternate"), "every other frame held out (the reference's rule for Blender-form sets)"
    order = sorted(range(n), key=lambda i: file_paths[i])
    by_name = make_split(n, "fraction")
    out = [""] * n
    for rank, i in enumerate(order):
        out[i] = by_name[rank]
    note = "10 % held out, evenly over the frames sorted by name (nerfstudio's rule; the reference's for real sets)"
    return out, note
