"""The definitions behind the unseen-combination and locality tests, on inputs whose answers are known by hand:
L-infinity novelty, the "at least novelty_min" threshold, the swept region (states between 0 and 1, shadows,
dilation), and the locality verdict (mean over channels, the 1/255 line, a visible change inside)."""

from __future__ import annotations

import numpy as np
import pytest
from evaluate_fakes import H, W

from stages.evaluate.locality import locality, swept_region
from stages.evaluate.unseen_states import StateCombination, novelty, unseen_combinations


def test_novelty_ignores_training_rows_with_an_unknown_state():
    # the only complete row is (0, 0): L-infinity distance 1; the row with a NaN says nothing
    assert novelty(np.array([0.0, 1.0]), np.array([[0.0, 0.0], [np.nan, 1.0]])) == 1.0


def test_a_combination_exactly_novelty_min_away_is_unseen():
    # level 0.5 between training states 0.25 and 0.75: 0.25 away from both (exact in binary), and the threshold is
    # "at least novelty_min"
    combos = unseen_combinations(1, np.array([[0.25], [0.75]]), levels=(0.5,), novelty_min=0.25,
                                 observed_within=None)
    assert combos == [StateCombination(values=(0.5,), anchor=0, level=0.5, novelty=0.25, unseen=True)]


def test_the_swept_region_covers_every_swept_state_and_the_shadows():
    """The door on column 2 + 4s at s = 0, .25, .5, .75, 1 (columns 2..6) and its shadow on column 14 at s = 1,
    dilated by 2 px: columns 0..8 and 12..15 of 16."""
    def truth_render(states):
        s = states["door"]
        ids = np.zeros((H, W), dtype=np.int32)
        ids[:, 2 + round(float(4 * s))] = 1
        shadow = np.zeros((1, H, W), dtype=np.int32)
        if s == 1.0:
            shadow[0, :, 14] = 1
        return {"ids": ids, "shadow_ids": shadow}

    region = swept_region(truth_render, 1, "door", {"door": 0.0}, (H, W))
    expected = np.zeros((H, W), dtype=bool)
    expected[:, 0:9] = True
    expected[:, 12:16] = True
    np.testing.assert_array_equal(region, expected)
    assert region.sum() == 13 * H


def _frame_and_truth(eval_scene):
    ds, _, truth = eval_scene
    return ds, truth, ds.frames_in("test")[:1]  # view 00000, both objects at 0


def test_the_truths_own_change_is_reported_inside_and_outside(eval_scene):
    """The fake truth moves the fridge's columns 0..5 by 0.5 in every channel, nothing else; the swept region is
    those columns dilated by 2 px, 0..7: inside 0.5 x 255 x 6/8, outside 0."""
    ds, truth, frames = _frame_and_truth(eval_scene)

    def render(frame, states):
        return truth.renderer.render(frame.c2w, states)["rgb"]

    out = locality(render, truth, frames, ds.camera_of, ds.objects, progress=False)
    fridge = out["objects"]["fridge"]
    assert fridge["truth_outside_x255"]["mean"] == 0.0
    assert fridge["truth_inside_x255"]["mean"] == pytest.approx(0.5 * 255 * 6 / 8, abs=1e-3)
    assert fridge["model_inside_x255"]["mean"] == pytest.approx(0.5 * 255 * 6 / 8, abs=1e-3)
    assert out["all_local"]


def test_a_run_that_ignores_the_states_is_not_local(eval_scene):
    """Nothing changes outside, but nothing inside either: a run that does not respond is not in control."""
    ds, truth, frames = _frame_and_truth(eval_scene)
    frozen = np.full((H, W, 3), 0.4)
    out = locality(lambda frame, states: frozen, truth, frames, ds.camera_of, ds.objects, progress=False)
    for name in ds.objects:
        assert out["objects"][name]["model_outside_x255"]["mean"] == 0.0
        assert out["objects"][name]["model_inside_x255"]["mean"] == 0.0
        assert not out["objects"][name]["local"]
    assert not out["all_local"]


def test_the_change_is_the_mean_over_the_colour_channels(eval_scene):
    """Opening the fridge adds 0.3 to the red channel of every pixel: |change| averaged over R, G, B is 0.1,
    i.e. 25.5 in 1/255 steps, inside the region and outside it."""
    ds, truth, frames = _frame_and_truth(eval_scene)

    def render(frame, states):
        rgb = np.full((H, W, 3), 0.5)
        rgb[..., 0] += 0.3 * states["fridge"]
        return rgb

    out = locality(render, truth, frames, ds.camera_of, ds.objects, progress=False)
    fridge = out["objects"]["fridge"]
    assert fridge["model_outside_x255"]["mean"] == pytest.approx(25.5, abs=1e-9)
    assert fridge["model_inside_x255"]["mean"] == pytest.approx(25.5, abs=1e-9)
    assert not fridge["local"]


@pytest.mark.parametrize(("leak_x255", "local"), [(2.0, False), (0.5, True)])
def test_locality_draws_the_line_at_one_255th(eval_scene, leak_x255, local):
    """The truth's own change plus a leak of leak/255 on every pixel when the fridge opens: the mean change
    outside the swept region is the leak, judged against OUTSIDE_LIMIT_X255 = 1 (docs: 1/255)."""
    ds, truth, frames = _frame_and_truth(eval_scene)

    def render(frame, states):
        return truth.renderer.render(frame.c2w, states)["rgb"].astype(np.float64) + leak_x255 / 255 * states["fridge"]

    out = locality(render, truth, frames, ds.camera_of, ds.objects, progress=False)
    fridge = out["objects"]["fridge"]
    assert fridge["model_outside_x255"]["mean"] == pytest.approx(leak_x255, abs=1e-6)
    assert fridge["local"] is local
    assert out["objects"]["drawer"]["local"]  # the drawer's 0 / 1 renders share the fridge's state: no leak
