"""Fixtures of the evaluation tests; the fakes themselves live in evaluate_fakes.py (importable by the tests)."""

from __future__ import annotations

import pytest
from evaluate_fakes import FakeRun, FakeTruthRenderer, make_eval_dataset

from stages.evaluate import TruthSource


@pytest.fixture
def eval_scene(tmp_path):
    """(dataset, fake run, truth source) sharing one fake truth renderer."""
    ds = make_eval_dataset(tmp_path / "scene")
    renderer = FakeTruthRenderer()
    truth = TruthSource(renderer=renderer, camera=ds.camera, object_ids={"fridge": 1, "drawer": 2},
                        poses={f.source_index: f.c2w for f in ds.frames},
                        states={f.source_index: dict(f.state) for f in ds.frames}, origin="fake capture")
    return ds, FakeRun(ds, renderer), truth
