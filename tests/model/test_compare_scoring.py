"""`livescene compare` scoring (score_run) against a fake run whose error on each view is known by construction.

The fake run returns the held-out image plus a constant offset ``e`` that depends on the frame it is asked
for, so each view's PSNR is -20*log10(e) exactly (MSE = e**2, data range 1) and the table's number can be
checked by hand: which frames were rendered, at which size, and how their PSNRs were combined.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import stages.model.run as model_run
from stages.compare.method_comparison import evenly, score_run
from tests.conftest import make_tiny_dataset

W, H = 16, 12
# make_tiny_dataset(n_frames=8): frames 0..7, the 'test' split is the even ones (0, 2, 4, 6).
OFFSET = {0: 0.1, 6: 0.01}  # first and last test frame: 20 dB and 40 dB
OTHER_OFFSET = 0.05  # any other frame: 26.02 dB


class _OffsetRun:
    def __init__(self, ds) -> None:
        self.ds = ds
        self.calls: list[tuple[int, int, int, object]] = []

    def render(self, camera, c2w, states, frame_index=None, outputs=None):
        self.calls.append((frame_index, camera.width, camera.height, states))
        frame = self.ds.frames[frame_index]
        img = self.ds.load_image(frame)[..., :3].astype(np.float64)
        if camera.width != W:  # half size: mean of each 2x2 block (what an area downsample of 2 is)
            img = img.reshape(H // 2, 2, W // 2, 2, 3).mean(axis=(1, 3))
        return {"rgb": img + OFFSET.get(frame_index, OTHER_OFFSET)}


@pytest.fixture
def fake_scored(tmp_path, monkeypatch):
    ds = make_tiny_dataset(tmp_path / "scene", n_frames=8, width=W, height=H)
    assert [i for i, f in enumerate(ds.frames) if f.split == "test"] == [0, 2, 4, 6]
    run = _OffsetRun(ds)
    monkeypatch.setattr(model_run, "load_run", lambda run_dir: run)
    return ds, run


def test_evenly_spreads_over_the_items_including_both_ends():
    assert evenly([0, 2, 4, 6], 2) == [0, 6]
    assert evenly(list(range(9)), 3) == [0, 4, 8]
    assert evenly([1, 2, 3], 0) == [1, 2, 3] and evenly([1, 2, 3], 5) == [1, 2, 3]


def test_score_run_renders_held_out_frames_evenly_and_averages_their_psnr(fake_scored, tmp_path):
    ds, run = fake_scored
    out = score_run(tmp_path / "run", ds.root, eval_frames=2)
    # the first and last frames of the test split, each at its own frame index, at full size
    assert [(c[0], c[1], c[2]) for c in run.calls] == [(0, W, H), (6, W, H)]
    assert out["eval_frames"] == 2
    # -20 log10(0.1) = 20 dB, -20 log10(0.01) = 40 dB: the mean of the views is 30 dB
    assert out["psnr"] == pytest.approx(30.0, abs=1e-6)
    assert 0.0 < out["ssim"] < 1.0


def test_score_run_at_eval_scale_renders_a_smaller_camera_against_the_downsampled_image(fake_scored, tmp_path):
    ds, run = fake_scored
    out = score_run(tmp_path / "run", ds.root, eval_frames=4, eval_scale=2)
    assert [(c[0], c[1], c[2]) for c in run.calls] == [(0, W // 2, H // 2), (2, W // 2, H // 2),
                                                       (4, W // 2, H // 2), (6, W // 2, H // 2)]
    expected = (20.0 + 2 * -20.0 * math.log10(OTHER_OFFSET) + 40.0) / 4
    # the area downsample is the 2x2 block mean up to float32 rounding (~1e-7 of an offset >= 0.01)
    assert out["psnr"] == pytest.approx(expected, abs=1e-3)


SHIFT = 0.25  # the fake alignment moves a view's camera this far along x (dataset units)


class _RefinedRun(_OffsetRun):
    """A run that refined its cameras: it renders a view well (offset 0.01, 40 dB) only at the pose its alignment
    returns, and badly (offset 0.1, 20 dB) at the dataset's pose."""

    refined_cameras = True

    def __init__(self, ds) -> None:
        super().__init__(ds)
        self.aligned: list[tuple[int, int, int]] = []

    def align_pose(self, camera, c2w, image, states=None, frame_index=None, seed=0):
        assert image.shape == (camera.height, camera.width, 3)
        self.aligned.append((frame_index, seed, camera.width))
        out = np.array(c2w, dtype=np.float64)
        out[0, 3] += SHIFT
        return out, np.zeros(6)

    def render(self, camera, c2w, states, frame_index=None, outputs=None):
        self.calls.append((frame_index, camera.width, camera.height, states))
        img = self.ds.load_image(self.ds.frames[frame_index])[..., :3].astype(np.float64)
        aligned = np.asarray(self.ds.frames[frame_index].c2w)[0, 3] + SHIFT
        return {"rgb": img + (0.01 if math.isclose(c2w[0][3], aligned) else 0.1)}


def test_score_run_scores_a_refined_run_at_its_aligned_poses(tmp_path, monkeypatch):
    ds = make_tiny_dataset(tmp_path / "scene", n_frames=8, width=W, height=H)
    run = _RefinedRun(ds)
    monkeypatch.setattr(model_run, "load_run", lambda run_dir: run)
    out = score_run(tmp_path / "run", ds.root, eval_frames=2)
    # each scored view aligned once, at its own frame index and seed (as `livescene evaluate` seeds it)
    assert run.aligned == [(0, 0, W), (6, 6, W)]
    assert out["psnr"] == pytest.approx(40.0, abs=1e-6)  # -20 log10(0.01) at the aligned pose, not 20 dB
