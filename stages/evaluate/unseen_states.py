"""State vectors never seen together in training: the test of independent control.

For each object ``i`` and level ``v`` in {0, 0.5, 1}, the other objects are
set to levels other than ``v``, choosing among those assignments the one
farthest (L-infinity) from every training state vector. A vector counts as
unseen when that distance is at least ``novelty_min``; its distance is kept
so a reader sees how novel each combination is.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

MAX_ASSIGNMENTS = 512
"""Above this many assignments of the other objects, a seeded random subset is searched instead."""


@dataclass(frozen=True)
class StateCombination:
    """One test state vector."""

    values: tuple[float, ...]
    """State per object, in the dataset's object order."""
    anchor: int
    """Index of the object set to ``level``."""
    level: float
    novelty: float
    """L-infinity distance to the nearest training state vector (inf when training has no states)."""
    unseen: bool


def novelty(vector: np.ndarray, train_states: np.ndarray) -> float:
    """L-infinity distance from ``[alpha]`` to the nearest row of ``[N, alpha]`` (rows with NaN ignored)."""
    rows = train_states[np.isfinite(train_states).all(axis=1)] if train_states.size else train_states
    if rows.size == 0:
        return float("inf")
    return float(np.abs(rows - vector[None]).max(axis=1).min())


def unseen_combinations(n_objects: int, train_states: np.ndarray, levels: Sequence[float] = (0.0, 0.5, 1.0),
                        novelty_min: float = 0.25, seed: int = 0) -> list[StateCombination]:
    """Test vectors (see module docstring), de-duplicated, in (object, level) order."""
    levels = [float(v) for v in levels]
    rng = np.random.default_rng(seed)
    train_states = np.asarray(train_states, dtype=np.float64).reshape(-1, n_objects)
    out: list[StateCombination] = []
    seen: set[tuple[float, ...]] = set()
    for i in range(n_objects):
        for v in levels:
            others = [lv for lv in levels if abs(lv - v) > 1e-9] or levels
            n_assign = len(others) ** (n_objects - 1)
            if n_assign <= MAX_ASSIGNMENTS:
                assignments = list(itertools.product(others, repeat=n_objects - 1))
            else:
                assignments = [tuple(rng.choice(others, n_objects - 1)) for _ in range(MAX_ASSIGNMENTS)]
            best, best_d = None, -1.0
            for a in assignments:
                vec = np.array([*a[:i], v, *a[i:]], dtype=np.float64)
                d = novelty(vec, train_states)
                if d > best_d:
                    best, best_d = vec, d
            assert best is not None
            key = tuple(float(x) for x in best)
            if key in seen:
                continue
            seen.add(key)
            out.append(StateCombination(values=key, anchor=i, level=v, novelty=best_d, unseen=best_d >= novelty_min))
    return out
