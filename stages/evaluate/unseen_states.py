"""State vectors never seen together in training: the test of independent control.

For each object ``i`` and level ``v`` in {0, 0.5, 1}, the other objects are
set to levels other than ``v``, choosing among those assignments the one
farthest (L-infinity) from every training state vector. A vector counts as
unseen when that distance is at least ``novelty_min``; its distance is kept
so a reader sees how novel each combination is.

Only levels each object was *observed* at take part: a training frame holds
that object within ``observed_within`` of the level. The test asks whether
states seen apart can be combined; an object the capture never opened fully
has no appearance to recombine at 1, and the novelty search would otherwise
prefer exactly such levels (they are the farthest from every training state).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stages.scene.dataset import STATE_SEEN_WITHIN

MAX_ASSIGNMENTS = 512
"""Above this many assignments of the other objects, a seeded random subset is searched instead."""

OBSERVED_WITHIN = STATE_SEEN_WITHIN
"""A level counts as observed for an object when a training frame holds the object within this distance of it
(half the least novelty of an unseen combination, 0.25)."""


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


def observed_levels(train_states: np.ndarray, levels: Sequence[float],
                    within: float | None = OBSERVED_WITHIN) -> list[list[float]]:
    """Per object (column of ``[N, alpha]``), the levels some training frame holds it within ``within`` of.

    ``None`` counts every level as observed (also where training has no states). An object observed at no level
    (it stays between them) keeps the level nearest to its states, so every object takes part.
    """
    levels = [float(v) for v in levels]
    train_states = np.asarray(train_states, dtype=np.float64)
    out = []
    for column in train_states.T:
        column = column[np.isfinite(column)]
        if within is None or column.size == 0:
            out.append(list(levels))
            continue
        distance = [float(np.abs(column - v).min()) for v in levels]
        out.append([v for v, d in zip(levels, distance, strict=True) if d <= within]
                   or [levels[int(np.argmin(distance))]])
    return out


def unseen_combinations(n_objects: int, train_states: np.ndarray, levels: Sequence[float] = (0.0, 0.5, 1.0),
                        novelty_min: float = 0.25, seed: int = 0,
                        observed_within: float | None = OBSERVED_WITHIN) -> list[StateCombination]:
    """Test vectors (see module docstring), de-duplicated, in (object, level) order; none for a room without
    objects."""
    if n_objects == 0:
        return []
    rng = np.random.default_rng(seed)
    train_states = np.asarray(train_states, dtype=np.float64).reshape(-1, n_objects)
    allowed = observed_levels(train_states, levels, observed_within)
    out: list[StateCombination] = []
    seen: set[tuple[float, ...]] = set()
    for i in range(n_objects):
        for v in allowed[i]:
            others = [[lv for lv in allowed[j] if abs(lv - v) > 1e-9] or allowed[j]
                      for j in range(n_objects) if j != i]
            n_assign = int(np.prod([len(o) for o in others]))
            if n_assign <= MAX_ASSIGNMENTS:
                assignments = list(itertools.product(*others))
            else:
                assignments = [tuple(rng.choice(o) for o in others) for _ in range(MAX_ASSIGNMENTS)]
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
