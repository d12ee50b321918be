"""The phone camera's effects (docs/captures.md, "Phone camera effects"), each against what a hand computes.

Most tests film one closed door face-on from a camera walking sideways at 3 m/s, looking at a point a kilometre
ahead (its view turns by 0.02 px a frame): the door's front, 1.78 m away, then moves across the image at
f x 0.3 m / 1.78 m per frame, and its left edge against the far wall (3 m away) is the edge that blur and the
rolling shutter move. Around frame 4 the camera stays between the door's edges (x from -0.45 to -0.15 m, the door
from -0.9 to -0.1 m), so it sees neither of the carcass's sides: the silhouette is the door's front edge.
"""

from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from stages.capture import generate_capture
from stages.capture.camera_effects import exposure_offsets, row_offsets
from stages.capture.camera_path import camera_path
from stages.capture.spec import CameraPathSpec, CaptureSpec, JitterSpec, ScheduleSpec

STEP_M = 0.3  # the walk's 3 m/s at 10 fps: camera travel per frame
DOOR_Z = 1.0 - 0.2 - 0.02 + 1.0  # door front (centre y 1.0, depth 0.4, panel 2 cm) to the camera's y of -1.0


def sideways_spec(small_spec, width: int = 95, height: int = 71, n_frames: int = 7) -> CaptureSpec:
    """The door and the walking camera of the module docstring; flat colours (no texture), no shadows."""
    spec = small_spec(n_frames=n_frames, width=width, height=height)
    spec.room = [5.0, 4.0, 2.6]
    spec.furniture = []
    door = copy.deepcopy(spec.objects[0])
    door.position, door.size, door.yaw_deg = [-0.5, 1.0, 0.0], [0.8, 0.4, 1.6], 0.0
    door.color = door.front_color = [0.1, 0.1, 0.12]
    door.schedule = ScheduleSpec(keys=[[0.0, 0.0]])
    spec.objects = [door]
    spec.camera = CameraPathSpec(
        kind="walk",
        target=[0.0, 1000.0, 0.8],
        waypoints=[[-1.5, -1.0, 0.8], [1.5, -1.0, 0.8]],
        speed_m_s=3.0,
        jitter=JitterSpec(position=0.0, rotation_deg=0.0),
    )
    spec.render.contrast = 0.0
    spec.render.shadows = False
    return spec


def _frame(cap: Path, i: int) -> np.ndarray:
    """Lossless frame i as float RGB in [0, 1]."""
    return cv2.imread(str(cap / "truth" / "images" / f"frame_{i:05d}.png"))[..., ::-1].astype(np.float64) / 255.0


def _mask(cap: Path, i: int) -> np.ndarray:
    return cv2.imread(str(cap / "masks" / f"frame_{i:05d}.png"), cv2.IMREAD_UNCHANGED)


def _focal(cap: Path) -> float:
    return float(json.loads((cap / "truth" / "transforms.json").read_text())["fl_x"])


def _left_edge(mask_row: np.ndarray) -> int:
    """Column of the door's first pixel in a mask row."""
    return int(np.flatnonzero(mask_row == 1)[0])


BEFORE_THE_EFFECTS = "0d456da20e6cec5cf699cdceb071d758dac65a03102f24bf98d331ecfe18801b"
"""sha256 over the paths and bytes of every file but capture.json (timings) and the stage marker of the capture of
small_spec(3, 48, 36), written by the generator of b03b56c, before the effects existed."""


def _digest(cap: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(cap.rglob("*")):
        if p.is_file() and p.name not in ("capture.json", ".livescene-stage"):
            h.update(p.relative_to(cap).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def test_a_spec_without_effects_writes_the_bytes_it_wrote_before_they_existed(tmp_path, small_spec):
    default = generate_capture(small_spec(n_frames=3, width=48, height=36), tmp_path / "default", progress=False)
    spec = small_spec(n_frames=3, width=48, height=36)
    spec.video.shutter, spec.video.blur_samples, spec.video.rolling_shutter = 0.0, 3, 0.0
    spec.video.noise_read = spec.video.noise_shot = spec.video.distortion.k1 = 0.0
    explicit = generate_capture(spec, tmp_path / "explicit", progress=False)  # every effect written, at 0
    assert _digest(default) == _digest(explicit) == BEFORE_THE_EFFECTS
    assert "camera_effects" not in json.loads((explicit / "capture.json").read_text())
    assert "shutter" not in (explicit / "truth" / "spec.yaml").read_text()


def test_exposure_and_row_times():
    spec = CaptureSpec(name="x")
    spec.video.shutter, spec.video.blur_samples = 0.5, 4
    assert np.allclose(exposure_offsets(spec.video), [-0.1875, -0.0625, 0.0625, 0.1875])  # centred, in the shutter
    spec.video.height, spec.video.rolling_shutter = 5, 0.6
    assert np.allclose(row_offsets(spec.video), [-0.3, -0.15, 0.0, 0.15, 0.3])  # top row first, middle at 0


def test_motion_blur_smears_the_edge_over_the_cameras_travel_during_the_exposure(tmp_path, small_spec):
    sharp = generate_capture(sideways_spec(small_spec), tmp_path / "sharp", progress=False)
    spec = sideways_spec(small_spec)
    spec.video.shutter, spec.video.blur_samples = 1.0, 8
    blurred = generate_capture(spec, tmp_path / "blur", progress=False)
    i, row = 4, 35
    speed = _focal(sharp) * STEP_M / DOOR_Z  # px per frame at the door
    # the masks (and depth) are the frame's time's: a segmenter sees the object where the truth pose puts it
    assert np.array_equal(_mask(blurred, i), _mask(sharp, i))
    edge = _left_edge(_mask(sharp, i)[row])
    lum = _frame(blurred, i)[row].mean(axis=1)
    sharp_lum = _frame(sharp, i)[row].mean(axis=1)
    wall, door = sharp_lum[edge - 10], sharp_lum[edge + 10]
    assert wall - door > 0.2  # the dark door against the lit wall: a falling step to measure
    # the edge's profile is the mean of 8 sharp steps spread over the exposure; its derivative's spread is that of 8
    # equally spaced points over shutter x speed (plus a pixel's rounding): sqrt(12 var) = width sqrt(63) / 8
    half = int(np.ceil(spec.video.shutter * speed / 2)) + 2
    lo = edge - half
    fall = np.clip(-np.diff(lum[lo : edge + half]), 0.0, None)  # the lit wall's gentle gradient rises: left out
    assert fall.sum() == pytest.approx(wall - door, abs=0.03)
    weights = fall / fall.sum()
    x = lo + 1 + np.arange(len(fall))  # where each difference lies: pixel k spans [k, k + 1)
    spread = np.sqrt(12 * (weights @ (x - weights @ x) ** 2))
    expected = spec.video.shutter * speed * np.sqrt(63) / 8
    assert 10 < expected < 14
    assert abs(spread - np.hypot(expected, 1.0)) < 0.06 * expected, (spread, expected)
    # the smear is centred on the frame's time: half of it on either side of the sharp edge
    assert abs(weights @ x - edge) < 1.0, (weights @ x, edge)
    # and the sharp frame steps there in one pixel
    assert np.max(-np.diff(sharp_lum[lo : edge + half])) > 0.9 * (wall - door)


def test_one_blur_sample_is_the_sharp_frame(tmp_path, small_spec):
    sharp = generate_capture(small_spec(n_frames=3, width=48, height=36), tmp_path / "sharp", progress=False)
    spec = small_spec(n_frames=3, width=48, height=36)
    spec.video.shutter, spec.video.blur_samples = 0.7, 1
    one = generate_capture(spec, tmp_path / "one", progress=False)
    for sub in ("truth/images", "masks", "truth/depth"):
        assert {p.name: p.read_bytes() for p in (one / sub).iterdir()} == {
            p.name: p.read_bytes() for p in (sharp / sub).iterdir()
        }, sub
    assert (one / "video.mp4").read_bytes() == (sharp / "video.mp4").read_bytes()


def test_rolling_shutter_shears_the_edge_by_each_rows_time(tmp_path, small_spec):
    sharp = generate_capture(sideways_spec(small_spec), tmp_path / "sharp", progress=False)
    spec = sideways_spec(small_spec)
    spec.video.rolling_shutter = 1.0
    rolled = generate_capture(spec, tmp_path / "rolled", progress=False)
    i, h = 4, spec.video.height
    speed = _focal(sharp) * STEP_M / DOOR_Z
    global_mask, rolled_mask = _mask(sharp, i), _mask(rolled, i)
    # the middle row is exposed at the frame's time, where its truth pose is
    assert np.array_equal(rolled_mask[h // 2], global_mask[h // 2])
    assert np.allclose(_frame(rolled, i)[h // 2], _frame(sharp, i)[h // 2], atol=1.5 / 255)
    # the top row is read half a frame earlier, with the camera 15 cm further left: the door lies further right
    for row in (5, 20, 50, 65):
        shift = _left_edge(rolled_mask[row]) - _left_edge(global_mask[row])
        expected = -speed * (row / (h - 1) - 0.5) * spec.video.rolling_shutter
        assert abs(shift - expected) <= 1.0, (row, shift, expected)
    assert _left_edge(rolled_mask[5]) - _left_edge(rolled_mask[65]) >= 9
    # depth is cast through the same rolling rays as the masks (the door's front stands 1.78 m away, the wall 3 m)
    depth = np.load(rolled / "truth" / "depth" / f"frame_{i:05d}.npy")
    rows = slice(8, 50)  # the door's rows above the floor
    assert np.array_equal(np.abs(depth[rows] - DOOR_Z) < 0.05, rolled_mask[rows] == 1)
    # the image too: its door pixels follow the rolled mask
    dark = _frame(rolled, i)[rows].mean(axis=2) < 0.2
    assert (dark == (rolled_mask[rows] == 1)).mean() > 0.99


def test_rolling_shutter_with_blur_rolls_every_sample(tmp_path, small_spec):
    spec = sideways_spec(small_spec)
    spec.video.rolling_shutter = 1.0
    rolled = generate_capture(spec, tmp_path / "rolled", progress=False)
    spec.video.shutter, spec.video.blur_samples = 0.5, 4
    both = generate_capture(spec, tmp_path / "both", progress=False)
    i = 4
    assert np.array_equal(_mask(both, i), _mask(rolled, i))  # masks at the frame's time, rolled
    # each row's smear is centred where the rolled sharp edge is: top and bottom rows sheared as without blur
    for row in (8, 62):
        lum = _frame(both, i)[row].mean(axis=1)
        step = -np.diff(lum)  # the wall is brighter than the door: a falling edge
        edge = _left_edge(_mask(rolled, i)[row])
        weights = np.clip(step[edge - 8 : edge + 8], 0.0, None)
        centre = (edge - 7 + np.arange(16)) @ weights / weights.sum()  # difference k lies at k + 1
        assert abs(centre - edge) < 1.0, (row, centre, edge)


def test_sensor_noise_has_the_modelled_deviation_and_follows_the_seed(tmp_path, small_spec):
    from stages.capture import TruthRenderer

    spec = small_spec(n_frames=2, width=96, height=72)
    spec.video.noise_read, spec.video.noise_shot = 0.02, 0.01
    a = generate_capture(spec, tmp_path / "a", progress=False)
    again = generate_capture(spec, tmp_path / "again", progress=False)
    assert (a / "video.mp4").read_bytes() == (again / "video.mp4").read_bytes()
    other = copy.deepcopy(spec)
    other.seed += 1
    b = generate_capture(other, tmp_path / "b", progress=False)
    assert not np.array_equal(_frame(a, 0), _frame(b, 0))
    renderer = TruthRenderer.from_capture(a)  # renders clean: the noise is the video's, not the scene's
    x, r = [], []
    for i, fr in enumerate(renderer.truth_frames()):
        clean = renderer.render(np.array(fr["transform_matrix"]), fr["state"])["rgb"].astype(np.float64)
        x.append(clean.ravel())
        r.append((_frame(a, i) - clean).ravel())
    x, r = np.concatenate(x), np.concatenate(r)
    model = spec.video.noise_read**2 + spec.video.noise_shot * x + 1 / (12 * 255**2)  # + 8-bit rounding
    inside = (x - 4 * np.sqrt(model) > 0) & (x + 4 * np.sqrt(model) < 1)  # not clipped
    assert abs(r[inside].mean()) < 0.003
    for lo, hi in ((0.0, 0.3), (0.3, 1.0)):  # darker and brighter pixels: the shot noise grows with intensity
        sel = inside & (x >= lo) & (x < hi)
        assert sel.sum() > 5000
        measured, predicted = np.mean(r[sel] ** 2), np.mean(model[sel])
        assert abs(measured / predicted - 1) < 0.06, (lo, measured, predicted)
    dark, bright = inside & (x < 0.3), inside & (x >= 0.3)
    assert np.mean(r[bright] ** 2) > 1.3 * np.mean(r[dark] ** 2)
    # masks and depth carry no noise
    clean = copy.deepcopy(spec)
    clean.video.noise_read = clean.video.noise_shot = 0.0
    c = generate_capture(clean, tmp_path / "clean", progress=False)
    for sub in ("masks", "truth/depth"):
        assert [p.read_bytes() for p in sorted((a / sub).iterdir())] == [
            p.read_bytes() for p in sorted((c / sub).iterdir())
        ], sub


def test_a_distorted_lens_puts_a_point_where_opencv_projects_it(tmp_path, small_spec):
    from stages.scene.camera import opengl_to_opencv, pixel_directions
    from stages.scene.transforms import camera_from_dict

    spec = sideways_spec(small_spec)
    spec.video.distortion.k1, spec.video.distortion.k2, spec.video.distortion.p1 = -0.3, 0.08, 0.01
    cap = generate_capture(spec, tmp_path / "cap", progress=False)
    truth = json.loads((cap / "truth" / "transforms.json").read_text())
    camera = camera_from_dict(truth, cap / "truth" / "transforms.json", "top level")
    assert truth["camera_model"] == "OPENCV" and camera.distortion == {"k1": -0.3, "k2": 0.08, "p1": 0.01}
    door = spec.objects[0]  # its front's top-left corner, seen against the wall from frame 4's camera
    w, d, h = door.size
    corner = np.array([door.position[0] - w / 2, door.position[1] - d / 2 - door.thickness, door.position[2] + h])
    i = 4
    c2w = np.asarray(truth["frames"][i]["transform_matrix"])
    w2c = np.linalg.inv(opengl_to_opencv(c2w))
    rvec, _ = cv2.Rodrigues(w2c[:3, :3])
    dist = np.array([-0.3, 0.08, 0.01, 0.0])
    (uv,), _ = cv2.projectPoints(corner[None], rvec, w2c[:3, 3], camera.K, dist)
    (pin,), _ = cv2.projectPoints(corner[None], rvec, w2c[:3, 3], camera.K, np.zeros(4))
    u, v = uv[0]  # OpenCV's continuous pixel coordinates: pixel (i, j) spans [i, i + 1) x [j, j + 1)
    assert 2 < u < camera.width - 2 and 2 < v < camera.height - 2
    assert np.hypot(*(uv[0] - pin[0])) > 2.0  # the lens moves the corner: a pinhole would miss it
    # back-project the cabinet pixels near it through the lens with the truth depth: the corner is at (u, v)
    depth = np.load(cap / "truth" / "depth" / f"frame_{i:05d}.npy")
    ids = _mask(cap, i)
    vv, uu = np.mgrid[0 : camera.height, 0 : camera.width]
    near = (np.hypot(uu + 0.5 - u, vv + 0.5 - v) < 4) & (ids == 1)
    rays = pixel_directions(camera, uu[near], vv[near])  # z = -1: scaled by z-depth, camera coordinates
    world = (rays * depth[near][:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
    best = int(np.argmin(np.linalg.norm(world - corner, axis=1)))
    assert np.hypot(uu[near][best] + 0.5 - u, vv[near][best] + 0.5 - v) < 1.0
    assert np.linalg.norm(world[best] - corner) < 1.5 * depth[near][best] / camera.fx


def test_a_distorted_truth_camera_reaches_every_reader(tmp_path, small_spec):
    from stages.capture import TruthRenderer, capture_to_dataset
    from stages.capture.cli import main
    from stages.evaluate.truth_source import TruthSource

    spec = small_spec(n_frames=4, width=64, height=48)
    spec.video.distortion.k1, spec.video.distortion.k2 = -0.1, 0.02
    cap = generate_capture(spec, tmp_path / "cap", progress=False)
    lens = {"k1": -0.1, "k2": 0.02}
    ds = capture_to_dataset(cap, tmp_path / "ds", progress=False, images="truth")
    assert ds.camera.distortion == lens
    renderer = TruthRenderer.from_capture(cap)
    assert renderer.camera.distortion == lens
    fr = renderer.truth_frames()[2]
    out = renderer.render(np.array(fr["transform_matrix"]), fr["state"])
    assert np.array_equal(np.round(np.clip(out["rgb"], 0, 1) * 255).astype(np.uint8), (_frame(cap, 2) * 255).round())
    assert np.array_equal(out["ids"], _mask(cap, 2))
    png = tmp_path / "view.png"  # `livescene capture render` at a truth pose: the frame, through the lens
    assert main(["render", "--capture", str(cap), "--pose", "2", "--out", str(png)]) == 0
    assert np.array_equal(cv2.imread(str(png)), cv2.imread(str(cap / "truth" / "images" / "frame_00002.png")))
    source = TruthSource.from_capture(cap)
    half = source.camera_for(32, 24)  # the coefficients are in normalised coordinates: kept at any image size
    assert half.distortion == lens and half.fx == pytest.approx(renderer.camera.fx / 2)


@pytest.mark.parametrize("supersample", [1, 2])
def test_rows_of_one_pose_and_state_render_as_a_global_shutter(small_spec, supersample):
    """``render_rows`` with every row at the frame's pose and states is ``render`` (but for float rounding), through a
    distorted lens and with supersampling; rows of other states take their own scene."""
    from stages.capture.renderer import SceneRenderer

    spec = small_spec(n_frames=2, width=40, height=30)
    spec.video.distortion.k1 = -0.1
    spec.render.supersample = supersample
    renderer = SceneRenderer(spec)
    pose = camera_path(spec)[1]
    states = np.array([0.6, 0.8])
    whole = renderer.render(pose, states)
    rows = renderer.render_rows(np.repeat(pose[None], 30, axis=0), np.repeat(states[None], 30, axis=0))
    assert np.allclose(rows["rgb"], whole["rgb"], atol=1e-5) and np.allclose(rows["depth"], whole["depth"], atol=1e-5)
    assert (rows["ids"] == whole["ids"]).mean() > 0.995 and (rows["shadow_ids"] == whole["shadow_ids"]).mean() > 0.995
    # the bottom half with both objects closed: as a closed render there, as the open one above
    half = np.repeat(states[None], 30, axis=0)
    half[15:] = 0.0
    mixed = renderer.render_rows(np.repeat(pose[None], 30, axis=0), half)
    closed = renderer.render(pose, np.zeros(2))
    assert np.allclose(mixed["rgb"][15:], closed["rgb"][15:], atol=1e-5)
    assert np.allclose(mixed["rgb"][:15], whole["rgb"][:15], atol=1e-5)
    assert not np.allclose(closed["rgb"], whole["rgb"], atol=1e-3)  # the states show


def test_rows_of_two_poses_take_their_own_poses_in_millimetres_and_supersampled(small_spec):
    """The top half of the rows at one pose, the bottom half at a pose 20 cm to the side, in millimetres, with 2x2
    supersampling: each half is what ``render`` gives at its own pose (sub-pixel rows share their pixel row's pose),
    depth in millimetres as ``render``'s."""
    from stages.capture.renderer import SceneRenderer
    from stages.capture.spec import Units

    spec = small_spec(n_frames=2, width=40, height=30)
    spec.units = Units(name="mm", per_metre=1000.0)
    spec.render.supersample = 2
    renderer = SceneRenderer(spec)
    top = camera_path(spec)[1]
    top[:3, 3] *= 1000.0
    bottom = top.copy()
    bottom[:3, 3] += 200.0 * top[:3, 0]  # 20 cm along the camera's right
    states = np.array([0.6, 0.8])
    rows = renderer.render_rows(np.r_[np.repeat(top[None], 15, 0), np.repeat(bottom[None], 15, 0)],
                                np.repeat(states[None], 30, axis=0))
    for half, pose in ((slice(0, 15), top), (slice(15, 30), bottom)):
        whole = renderer.render(pose, states)
        assert np.allclose(rows["rgb"][half], whole["rgb"][half], atol=1e-5)
        assert np.allclose(rows["depth"][half], whole["depth"][half], rtol=1e-5)
        assert whole["depth"][half].max() > 500.0  # millimetres: the room is metres away
    assert not np.allclose(renderer.render(top, states)["rgb"][15:], rows["rgb"][15:], atol=1e-3)  # the poses show
