"""Per-frame exposure of a frame sequence from its overlapping neighbours (stages/scene/exposure.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from stages.scene import InputError, read_scene, write_scene
from stages.scene.cli import main as scene_main
from stages.scene.exposure import (
    central_value,
    edge_strength,
    estimate_exposure,
    estimate_log_gains,
    pair_log_ratio,
    read_exposure,
)
from stages.scene.masks import mask_path
from tests.conftest import make_tiny_dataset
from tests.pan_frames import pan, write_pan_dataset


def test_the_gains_of_a_panning_camera_are_recovered():
    rng = np.random.default_rng(1)
    truth = rng.normal(0.0, 0.05, (24, 1)) + rng.normal(0.0, 0.02, (24, 3))
    est = estimate_log_gains(pan(24, truth), [f"{i:05d}" for i in range(24)])
    truth = truth - truth.mean(axis=0)
    assert est.tied.all() and est.pairs == 23 + 21 + 15  # frames 1, 3 and 9 apart
    assert np.abs(est.log_gains - truth).max() < 0.01
    assert est.spread == pytest.approx(float(truth.std(axis=0).mean()), abs=0.003)


def test_constant_exposure_reads_almost_no_spread():
    est = estimate_log_gains(pan(16, np.zeros((16, 3))), [str(i) for i in range(16)])
    assert est.spread < 0.002


def test_a_changing_part_of_the_scene_does_not_read_as_exposure():
    """Two fifths of the pixels brightened by an opening door's light: the plain median moves, the centre of the
    largest cluster stays at the gain the rest of the image shows."""
    rng = np.random.default_rng(5)
    d = np.full((5000, 3), 0.03) + rng.normal(0.0, 0.01, (5000, 3))  # the 8-bit step at mid grey, about
    d[:2000] += rng.uniform(0.05, 0.4, (2000, 1))
    assert np.abs(np.median(d, axis=0) - 0.03).min() > 0.008
    np.testing.assert_allclose(central_value(d), 0.03, atol=0.002)


def test_a_moving_object_s_shading_is_left_out_with_its_masks(tmp_path):
    """A door turning towards the light brightens by 2 % a frame over most of the image, under constant exposure:
    its pixels outnumber the room's, so without masks the comparison reads the door's shading as exposure; with
    the dataset's masks it is left out and the frames read as they were filmed."""
    n = 12
    frames = pan(n, np.zeros((n, 3)))
    for i, img in enumerate(frames):  # texture columns 20-100 (62 % of the frame) are the door
        img[:, max(16 - i, 0):96 - i] = np.round(np.clip(img[:, max(16 - i, 0):96 - i] * np.exp(0.02 * i), 0, 1)
                                                 * 255) / 255
    ds = write_pan_dataset(tmp_path / "ds", np.zeros((n, 3)), frames=frames, object_columns=(20, 100))
    plain, masked = estimate_exposure(ds, use_masks=False), estimate_exposure(ds)
    assert not plain.masked and masked.masked
    assert masked.pairs == 11 + 9 + 3  # every pair still compared, on the room's pixels
    assert plain.spread > 0.03  # the door's 0.02 per frame, read as the camera's
    assert masked.spread < 0.002


def test_frames_without_a_mask_are_compared_on_what_is_known(tmp_path):
    """A dataset may list frames_without_masks: their pairs leave out the other frame's objects only."""
    gains = np.random.default_rng(12).normal(0.0, 0.05, (8, 3))
    ds = write_pan_dataset(tmp_path / "ds", gains, object_columns=(40, 60))
    ds.meta["frames_without_masks"] = ["00003"]
    write_scene(ds, ds.root)
    mask_path(ds.root, "00003").unlink()
    ds = read_scene(ds.root, validate=True)
    est = estimate_exposure(ds)
    assert est.masked and est.tied.all() and est.pairs == 7 + 5
    assert np.abs(est.log_gains - (gains - gains.mean(0))).max() < 0.01


def test_frames_that_do_not_overlap_give_no_spread(tmp_path):
    """Random images (an unordered collection) tie no pair: no number rather than a made-up one."""
    ds = make_tiny_dataset(tmp_path / "ds", n_frames=6, width=64, height=48)
    est = estimate_exposure(ds)
    assert est.pairs == 0 and est.spread is None and not est.log_gains.any()


def test_the_dataset_is_read_in_playback_order(tmp_path):
    """transforms.json may list frames in any order; the source index puts neighbours next to each other."""
    rng = np.random.default_rng(2)
    gains = rng.normal(0.0, 0.05, (8, 3))
    ds = write_pan_dataset(tmp_path / "ds", gains)
    ds.frames.reverse()
    est = estimate_exposure(ds)
    assert est.frame_ids == [f"{i:05d}" for i in range(8)]
    assert np.abs(est.log_gains - (gains - gains.mean(0))).max() < 0.01


def test_the_cli_writes_the_estimate(tmp_path, capsys):
    gains = np.random.default_rng(3).normal(0.0, 0.05, (8, 3))
    write_pan_dataset(tmp_path / "ds", gains)
    assert scene_main(["exposure", str(tmp_path / "ds"), "--out", str(tmp_path / "exposure.json")]) == 0
    saved = json.loads((tmp_path / "exposure.json").read_text())
    assert saved["spread"] == pytest.approx(float((gains - gains.mean(0)).std(0).mean()), abs=0.004)
    assert list(saved["log_gains"]) == [f"{i:05d}" for i in range(8)] and saved["tied_frames"] == 8
    assert "spread" in capsys.readouterr().out


def test_a_saved_estimate_reads_back_to_the_same_doubles(tmp_path):
    """What the workflow's exposure rule writes, every training reads: the gains must be the measured ones to the
    last bit, or some training pixels would round the other way."""
    rng = np.random.default_rng(9)
    ds = write_pan_dataset(tmp_path / "ds", rng.normal(0.0, 0.05, (10, 3)))
    assert scene_main(["exposure", str(ds.root), "--out", str(tmp_path / "exposure.json")]) == 0
    measured, saved = estimate_exposure(ds), read_exposure(tmp_path / "exposure.json", ds)
    assert saved.frame_ids == measured.frame_ids and saved.pairs == measured.pairs
    assert saved.log_gains.tobytes() == measured.log_gains.tobytes() and saved.spread == measured.spread
    np.testing.assert_array_equal(saved.tied, measured.tied)


def test_a_saved_estimate_of_other_images_is_refused(tmp_path):
    """A stale file (the frames re-extracted, an image edited, another dataset) names itself and the command that
    measures again; nothing is trained on gains of other images."""
    rng = np.random.default_rng(10)
    ds = write_pan_dataset(tmp_path / "ds", rng.normal(0.0, 0.05, (8, 3)))
    other = write_pan_dataset(tmp_path / "other", rng.normal(0.0, 0.05, (6, 3)))
    saved = tmp_path / "exposure.json"
    scene_main(["exposure", str(ds.root), "--out", str(saved)])
    fix = r"fix: measure them again: livescene scene exposure"
    other_frames = r"exposure.json: measured on other frames .*names frames .*00006.* the dataset does not have"
    with pytest.raises(InputError, match=rf"{other_frames}.*{fix}"):
        read_exposure(saved, other)
    image = ds.image_path(ds.frames[3])
    image.write_bytes(other.image_path(other.frames[3]).read_bytes())
    with pytest.raises(InputError, match=rf"exposure.json: measured on other images .*digest.*{fix}"):
        read_exposure(saved, ds)
    (tmp_path / "broken.json").write_text('{"spread": 0.1}')
    with pytest.raises(InputError, match=rf"broken.json: not an exposure estimate \(KeyError.*{fix}"):
        read_exposure(tmp_path / "broken.json", ds)
    with pytest.raises(InputError, match=rf"absent.json: no such exposure file.*{fix}"):
        read_exposure(tmp_path / "absent.json", ds)


def test_the_gains_do_not_depend_on_the_number_of_opencv_threads():
    """Machines differ in cores: DIS flow splits its work by thread, and must still give the same gains."""
    import cv2

    rng = np.random.default_rng(4)
    frames = pan(8, rng.normal(0.0, 0.05, (8, 3)), h=120, w=160)
    before = cv2.getNumThreads()
    try:
        runs = []
        for threads in (1, 4):
            cv2.setNumThreads(threads)
            runs.append(estimate_log_gains(frames, [str(i) for i in range(8)]).log_gains)
    finally:
        cv2.setNumThreads(before)
    np.testing.assert_array_equal(runs[0], runs[1])


def test_the_gains_lie_on_a_fixed_grid():
    """Gains that differ in their last bits between two runs would round some training pixels the other way."""
    rng = np.random.default_rng(7)
    est = estimate_log_gains(pan(8, rng.normal(0.0, 0.05, (8, 3))), [str(i) for i in range(8)])
    steps = est.log_gains / 1e-4
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)


def test_edge_strength_is_the_exact_squared_sobel_magnitude():
    grey = np.random.default_rng(8).integers(0, 256, (37, 53), dtype=np.uint8)
    p = np.pad(grey.astype(np.int64), 1, mode="reflect")  # OpenCV's default border, reflect-101
    gx = (p[:-2, 2:] + 2 * p[1:-1, 2:] + p[2:, 2:]) - (p[:-2, :-2] + 2 * p[1:-1, :-2] + p[2:, :-2])
    gy = (p[2:, :-2] + 2 * p[2:, 1:-1] + p[2:, 2:]) - (p[:-2, :-2] + 2 * p[:-2, 1:-1] + p[:-2, 2:])
    np.testing.assert_array_equal(edge_strength(grey), gx * gx + gy * gy)


def test_a_pair_reads_the_same_ratio_wherever_its_arrays_lie_in_memory():
    """The measurement's arrays land at different addresses from run to run, and some OpenCV float code rounds
    differently with the address (`cv2.magnitude` did: a laundry-room gain moved in its last digits between two
    processes, and the training images with it). Every call with the heap shifted in between must agree. These
    smooth frames put no pixel on the rounding's edge, so the exact-integer test above is what holds that fix."""
    import cv2

    rng = np.random.default_rng(9)
    a, b = (np.round(f * 255).astype(np.uint8) for f in pan(2, rng.normal(0.0, 0.05, (2, 3)), h=120, w=160))
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    held, seen = [], set()
    for k in range(48):
        held.append(np.empty(24 * k + 8, np.uint8))  # moves where the next arrays are allocated
        seen.add(tuple(pair_log_ratio(a, b, flow).tolist()))
    assert len(seen) == 1


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -200.0])
def test_a_saved_estimate_with_a_non_finite_or_absurd_gain_is_refused(tmp_path, value):
    """json writes NaN and Infinity; training would turn such a gain into a black or white channel of that frame
    (ray_dataset's uint8 clip) without a word: the file is refused, naming the frame and the fix."""
    ds = write_pan_dataset(tmp_path / "ds", np.random.default_rng(11).normal(0.0, 0.05, (6, 3)))
    saved = tmp_path / "exposure.json"
    assert scene_main(["exposure", str(ds.root), "--out", str(saved)]) == 0
    data = json.loads(saved.read_text())
    data["log_gains"]["00002"][2] = value
    saved.write_text(json.dumps(data))
    with pytest.raises(InputError, match=r"exposure.json: the log gain of frame 00002 \(B\) is .*fix: measure them "
                                         r"again: livescene scene exposure"):
        read_exposure(saved, ds)


def test_flat_frames_do_not_count_as_overlapping():
    """Two featureless frames correlate as NaN (no variance); they share nothing to match, so no ratio is read
    from their brightness difference."""
    import cv2

    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    a, b = np.full((64, 96, 3), 100, np.uint8), np.full((64, 96, 3), 160, np.uint8)
    assert pair_log_ratio(a, b, flow) is None
