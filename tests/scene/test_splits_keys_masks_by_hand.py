"""Splits, frame numbers, key-frame matching, masks and the camera box, against hand-computed cases."""

from __future__ import annotations

import numpy as np

from stages.scene import Frame, make_split
from stages.scene.dataset import split_lists
from stages.scene.key_frame_states import frame_times, match_key_frames
from stages.scene.keyframes import frame_number_of
from stages.scene.masks import label_map_to_onehot, unreliable_masks
from stages.scene.normalization import camera_bounds_box


def test_the_fraction_split_of_an_odd_count_is_nerfstudio_s() -> None:
    """nerfstudio: ceil(0.9 * 15) = 14 train frames at int(linspace(0, 14, 14)) = int(k * 14 / 13) = 0..12 and 14,
    so frame 13 alone is held out (13 train frames would hold out 6 and 13)."""
    split = make_split(15, "fraction", test_fraction=0.1)
    assert [i for i, s in enumerate(split) if s == "test"] == [13]


def test_the_split_lists_put_every_frame_in_exactly_one_of_train_and_test() -> None:
    """A frame that names no split trains (``frames_in``): nerfstudio must find it in train_filenames."""
    frames = [Frame(file_path=f"images/frame_{i:05d}.png", c2w=np.eye(4), split=s)
              for i, s in enumerate(["train", None, "test", "train", None])]
    lists = split_lists(frames)
    train, test = set(lists["train_filenames"]), set(lists["test_filenames"])
    assert not train & test and train | test == {f.file_path for f in frames}
    assert test == {"images/frame_00002.png"} and lists["val_filenames"] == lists["test_filenames"]


def test_the_frame_number_is_the_last_run_of_digits() -> None:
    assert frame_number_of("cam2-frame12") == 12
    assert frame_number_of("IMG_0012") == 12
    assert frame_number_of("v2_take") == 2  # no digit in the frame id: the digits of the whole stem


def test_a_key_frame_whose_number_two_frames_carry_matches_neither() -> None:
    """``frame_5`` names the frame numbered 5; when two frames carry 5 (``a_0005``, ``b_005``) it is ambiguous."""
    frames = [Frame(file_path=p, c2w=np.eye(4)) for p in ("images/a_0005.png", "images/b_005.png", "images/c_7.png")]
    matched, unmatched = match_key_frames(["frame_5", "frame_7"], frames)
    assert matched == {"frame_7": 2} and unmatched == ["frame_5"]


def test_a_label_map_becomes_one_channel_per_object_and_background_last() -> None:
    onehot = label_map_to_onehot(np.array([[0, 1, -1, 2]]), 2)  # 2 objects: -1 and 2 are background
    expected = np.array([[[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]]], dtype=bool)
    np.testing.assert_array_equal(onehot, expected)


def test_a_sliver_of_a_large_object_is_unreliable_and_a_small_object_at_its_usual_size_is_not() -> None:
    """30 x 30 pixels: H W / 300 = 3. Object 0 usually covers 100 pixels (limit min(3, 25) = 3): 2 pixels is a
    sliver, 10 is not. Object 1 always covers 2 (limit min(3, 0.5) = 0.5): reliable everywhere."""
    counts = np.array([[100, 2], [100, 2], [10, 2], [2, 2], [100, 0]])
    expected = np.array([[False, False], [False, False], [False, False], [True, False], [False, False]])
    np.testing.assert_array_equal(unreliable_masks(counts, 30, 30), expected)


def test_the_camera_box_is_padded_by_a_share_of_its_longest_side() -> None:
    centres = np.array([[0.0, 0.0, 0.0], [10.0, 1.0, 2.0]])
    lo, hi = camera_bounds_box(centres, margin=0.1)  # pad = 0.1 * 10 on every side
    np.testing.assert_allclose(lo, [-1.0, -1.0, -1.0])
    np.testing.assert_allclose(hi, [11.0, 2.0, 3.0])


def test_frame_times_run_from_the_first_frame_number_to_the_last() -> None:
    """Frames at video indices 10, 20, 30 (a clip cut from a longer video) lie at t = 0, 0.5 and 1."""
    frames = [Frame(file_path=f"images/frame_{k:05d}.png", c2w=np.eye(4), source_index=k) for k in (10, 20, 30)]
    np.testing.assert_array_equal(frame_times(frames), [0.0, 0.5, 1.0])
