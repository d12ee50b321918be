"""The demo capture's state schedules leave enough state vectors unseen for the unseen-combination test.

The default job evaluates unseen combinations at 4 held-out views and needs at least 8 unseen renders, so
the demo must leave at least 3 distinct test vectors farther than novelty_min from every training state,
whatever interpolation the states stage picks, while each object still visits 0 and 1 in training frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from stages.capture import load_spec
from stages.capture.generate import key_frame_values
from stages.capture.state_schedule import state_table
from stages.evaluate import EvaluateConfig, unseen_combinations
from stages.scene import make_split
from stages.states.interpolation import interpolate

DEMO = Path(__file__).resolve().parents[2] / "config" / "captures" / "demo.yaml"


def _train_states(method: str) -> np.ndarray:
    """Training-frame states as the default job builds them: key frames interpolated, alternate split."""
    spec = load_spec(DEMO)
    truth = state_table(spec)
    n = len(truth)
    keys = key_frame_values(spec, truth)
    key_x = np.array([int(k.rsplit("_", 1)[1]) for k in keys], dtype=np.float64)
    states = np.stack([interpolate(key_x, np.array([keys[k][name] for k in keys]), np.arange(n), method)
                       for name in spec.object_names], axis=1)
    train = np.array(make_split(n, "alternate")) == "train"
    return states[train]


@pytest.mark.parametrize("method", ["truth", "linear", "pchip"])
def test_demo_leaves_three_state_vectors_unseen(method):
    spec = load_spec(DEMO)
    if method == "truth":
        train = state_table(spec)[np.array(make_split(spec.video.n_frames, "alternate")) == "train"]
    else:
        train = _train_states(method)
    cfg = EvaluateConfig()
    combos = unseen_combinations(len(spec.objects), train, cfg.levels, cfg.novelty_min)
    unseen = {c.values for c in combos if c.unseen}
    assert len(unseen) >= 3, [(c.values, round(c.novelty, 3)) for c in combos]
    # not by a hair: each unseen vector is at least twice the threshold from training
    assert min(c.novelty for c in combos if c.unseen) >= 2 * cfg.novelty_min
    for j in range(len(spec.objects)):  # every object opens fully and closes fully in training frames
        assert np.isclose(train[:, j], 0.0).any() and np.isclose(train[:, j], 1.0).any()
