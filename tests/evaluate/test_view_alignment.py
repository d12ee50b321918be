"""A run that refined its cameras is scored at held-out poses aligned to it, one alignment per view reused by every
render there; an unrefined run is evaluated as before (docs/model.md, "Camera refinement")."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
from evaluate_fakes import FakeRun

from stages.evaluate import EvaluateConfig, evaluate_run
from stages.model.scene_normalization import SceneNormalization

# a correction of 0.1 normalised units along x and 0.01 rad about z; x_unit = 2 x_world: 0.05 dataset units
ADJUSTMENT = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.01])
SHIFT = 0.05


class RefinedRun(FakeRun):
    """The fake run of a refined training: its alignment moves each view by SHIFT along x."""

    refined_cameras = True
    camera_opt: ClassVar[dict] = {"mode": "SO3xR3"}
    ALIGNMENT: ClassVar[dict] = {"steps": 100, "rays_per_step": 1024, "lr": 0.002}
    norm = SceneNormalization(np.diag([2.0, 2.0, 2.0, 1.0]), "test")

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.aligned: list[int | None] = []
        self.poses: list[tuple[int | None, np.ndarray]] = []

    def align_pose(self, camera, c2w, image, states=None, frame_index=None, seed=0):
        self.aligned.append(frame_index)
        assert image.shape == (camera.height, camera.width, 3) and states == self.ds.frames[frame_index].state
        out = np.array(c2w, float)
        out[0, 3] += SHIFT
        return out, ADJUSTMENT

    def render(self, camera, c2w, states, frame_index=None, outputs=None):
        self.poses.append((frame_index, np.array(c2w)))
        return super().render(camera, c2w, states, frame_index, outputs)


def test_a_refined_run_is_scored_at_aligned_poses(eval_scene, tmp_path):
    ds, plain, truth = eval_scene
    run = RefinedRun(ds, plain.truth)
    metrics = evaluate_run(run, ds, tmp_path / "e", truth, None, EvaluateConfig(unseen_views=2, save_renders=False))
    test_indices = [i for i, f in enumerate(ds.frames) if f.split == "test"]
    assert sorted(run.aligned) == test_indices  # once per view, whichever tests render it
    assert len(run.poses) > len(test_indices)  # unseen combinations and locality render the same views again
    for index, c2w in run.poses:  # every render at a view is at its aligned pose
        np.testing.assert_allclose(c2w[:3, 3], np.asarray(ds.frames[index].c2w)[:3, 3] + [SHIFT, 0.0, 0.0])
    record = metrics["view_alignment"]
    assert record["steps"] == 100 and record["training_cameras"] == "SO3xR3"
    assert [v["frame"] for v in record["views"]] == [ds.frames[i].frame_id for i in test_indices]
    for view in record["views"]:
        assert math.isclose(view["translation"], SHIFT) and math.isclose(view["rotation_deg"], math.degrees(0.01))
    assert record["rotation_deg"]["n"] == len(test_indices)


def test_an_unrefined_run_is_scored_at_the_datasets_poses(eval_scene, tmp_path):
    ds, run, truth = eval_scene
    poses = []
    render = run.render
    run.render = lambda camera, c2w, *a, **k: poses.append(np.array(c2w)) or render(camera, c2w, *a, **k)
    metrics = evaluate_run(run, ds, tmp_path / "e", truth, None, EvaluateConfig(unseen_views=2, save_renders=False))
    assert "view_alignment" not in metrics
    test_poses = [np.asarray(f.c2w) for f in ds.frames if f.split == "test"]
    assert poses and all(any(np.array_equal(p, t) for t in test_poses) for p in poses)
