"""Train/test splits over frames."""

from __future__ import annotations

from typing import Literal

import numpy as np

SplitMethod = Literal["alternate", "every_n", "fraction"]


def make_split(n_frames: int, method: SplitMethod = "alternate", n: int = 10, test_fraction: float = 0.1) -> list[str]:
    """``"train"``/``"test"`` per frame, in frame order.

    - ``alternate``: even frames test, odd frames train (the reference code's
      choice for synthetic sets);
    - ``every_n``: every n-th frame (starting at n // 2) is a test frame;
    - ``fraction``: ``test_fraction`` of frames, evenly spaced (the reference
      code's 90/10 for real sets).
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
        n_test = max(1, round(n_frames * test_fraction))
        picks = np.unique(np.round(np.linspace(0, n_frames - 1, n_test + 2)[1:-1]).astype(int))
        test = np.isin(idx, picks)
    else:
        raise ValueError(f"unknown split method {method!r}; use alternate, every_n or fraction")
    if test.all():  # a single frame: keep it for training
        test[:] = False
    return ["test" if t else "train" for t in test]
