"""Camera paths (nerfstudio's camera_path.json with per-keyframe states) and ``livescene render`` videos."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from stages.model.camera_path import (
    camera_from_fov,
    fit_orbit,
    keyframe_times,
    orbit_path,
    read_camera_path,
    states_sweep_path,
)
from stages.model.render_cli import main as render_main
from stages.model.run import LoadedRun
from stages.scene import Camera, InputError, look_at

OBJECTS = ["object0", "object1", "object2"]


def _path_file(tmp_path, n_frames: int = 10, **extra) -> str:
    """A 3-keyframe, non-cyclic path (1 s per transition): object0 0 -> 1 -> 0.5, object1 only at keyframe 1."""
    poses = [look_at(np.array([3 * math.cos(a), 3 * math.sin(a), 1.0]), np.zeros(3))
             for a in np.linspace(0, 1, n_frames)]
    data = {
        "camera_type": "perspective", "render_width": 16, "render_height": 12, "fps": 5, "seconds": 2.0,
        "default_fov": 50.0, "default_transition_sec": 1.0, "is_cycle": False,
        "keyframes": [{"matrix": poses[0].ravel().tolist(), "fov": 50.0, "states": {"object0": 0.0}},
                      {"matrix": poses[5].ravel().tolist(), "fov": 50.0, "states": {"object0": 1.0, "object1": 0.25}},
                      {"matrix": poses[-1].ravel().tolist(), "fov": 50.0, "states": {"object0": 0.5}}],
        "camera_path": [{"camera_to_world": p.ravel().tolist(), "fov": 50.0, "aspect": 16 / 12} for p in poses],
        **extra,
    }
    path = tmp_path / "camera_path.json"
    path.write_text(json.dumps(data))
    return str(path)


def test_keyframe_states_interpolate_along_the_path(tmp_path):
    cp = read_camera_path(_path_file(tmp_path), OBJECTS, defaults={"object2": 0.75})
    assert len(cp.frames) == 10 and cp.fps == 5 and (cp.width, cp.height) == (16, 12)
    # nerfstudio's viewer samples frame j of N at duration * j / N; keyframes at 0, 1, 2 s
    s = [f.states for f in cp.frames]
    assert s[0] == {"object0": 0.0, "object1": 0.25, "object2": 0.75}
    assert s[5]["object0"] == pytest.approx(1.0)  # t = 1 s: the middle keyframe exactly
    assert s[3]["object0"] == pytest.approx(0.6)  # t = 0.6 s: 60 % of the way from 0 to 1
    assert s[8]["object0"] == pytest.approx(0.7)  # t = 1.6 s: 1 -> 0.5, 60 % of the way
    assert all(f["object1"] == 0.25 for f in s)  # named by one keyframe: held
    assert all(f["object2"] == 0.75 for f in s)  # named by none: the caller's default
    # the fov is vertical (three.js): f = (H / 2) / tan(fov / 2)
    assert cp.frames[0].camera.fy == pytest.approx(6 / math.tan(math.radians(25)))
    written = json.loads((tmp_path / "camera_path.json").read_text())["camera_path"][4]["camera_to_world"]
    assert np.array_equal(cp.frames[4].c2w, np.asarray(written).reshape(4, 4))  # row major


def test_transition_overrides_cycles_and_per_frame_states(tmp_path):
    keys = [{}, {"override_transition_enabled": True, "override_transition_sec": 3.0}, {}]
    assert keyframe_times(keys, 1.0, cycle=False).tolist() == [0.0, 3.0, 4.0]
    assert keyframe_times(keys, 1.0, cycle=True).tolist() == [0.0, 3.0, 4.0, 5.0]
    path = _path_file(tmp_path, is_cycle=True)
    data = json.loads(Path(path).read_text())
    data["camera_path"][2]["states"] = {"object2": 1.0}
    Path(path).write_text(json.dumps(data))
    cp = read_camera_path(path, OBJECTS)
    # a cycle returns to keyframe 0's states over a third transition: t = 3 * j / 10
    assert cp.frames[5].states["object0"] == pytest.approx(0.5 + 0.5 * 0.5)  # t = 1.5 s: 1 -> 0.5, halfway
    assert cp.frames[9].states["object0"] == pytest.approx(0.5 * (1 - 0.7))  # t = 2.7 s: 0.5 -> 0, 70 %
    assert cp.frames[2].states["object2"] == 1.0 and cp.frames[3].states["object2"] == 0.0


@pytest.mark.parametrize(("change", "message"), [
    ({"camera_type": "fisheye"}, "camera_type 'fisheye' is not supported"),
    ({"render_width": "wide"}, "render_width is 'wide', not a number"),
    ({"camera_path": []}, 'no "camera_path" list'),
    ({"keyframes": [{"states": {"fridge": 1}}]}, r"keyframes\[0\].states names unknown objects \['fridge'\]"),
    ({"keyframes": [{"states": {"object0": 2}}]}, r"keyframes\[0\].states.object0 = 2 is outside \[0, 1\]"),
])
def test_bad_camera_paths_are_explained(tmp_path, change, message):
    path = _path_file(tmp_path)
    data = json.loads(Path(path).read_text())
    data.update(change)
    Path(path).write_text(json.dumps(data))
    with pytest.raises(InputError, match=message):
        read_camera_path(path, OBJECTS)


def test_orbit_is_fitted_to_the_training_cameras():
    target = np.array([0.5, -0.2, 0.3])
    angles = np.radians(np.linspace(-40, 50, 12))
    c2ws = [look_at(target + np.array([2 * math.cos(a), 2 * math.sin(a), 0.8]), target) for a in angles]
    orbit = fit_orbit(c2ws)
    assert np.allclose(orbit.target, target, atol=1e-6)
    assert np.allclose(orbit.up, [0, 0, 1], atol=1e-9) and orbit.radius == pytest.approx(2.0)
    assert math.degrees(orbit.angles.max() - orbit.angles.min()) == pytest.approx(90.0, abs=1e-6)
    cam = Camera(fx=10.0, fy=10.0, cx=8.0, cy=6.0, width=16, height=12)
    cp = orbit_path(c2ws, cam, 24, 12.0, {"a": 0.0})
    for fr in cp.frames:  # every frame looks at the target from the fitted circle
        forward = -fr.c2w[:3, 2]
        to_target = target - fr.c2w[:3, 3]
        assert np.allclose(np.cross(forward, to_target / np.linalg.norm(to_target)), 0, atol=1e-9)
    centres = np.array([f.c2w[:3, 3] for f in cp.frames])
    lo, hi = orbit.angles.min(), orbit.angles.max()
    # over the cameras' arc and back: first frame at one end, the middle one at the other, a loop
    assert np.allclose(centres[0], orbit.point(lo)) and np.allclose(centres[12], orbit.point(hi))
    assert np.allclose(centres[1], centres[-1])
    assert np.allclose(np.linalg.norm(centres[:, :2] - target[:2], axis=1), 2.0)
    sweep = states_sweep_path(c2ws, 3, cam, 24, 12.0, "a", {"a": 0.0, "b": 0.4}, sway_deg=10)
    assert np.allclose(sweep.frames[0].c2w, c2ws[3])
    assert [f.states["a"] for f in sweep.frames][::6] == pytest.approx([0.0, 0.5, 1.0, 0.5])
    assert all(f.states["b"] == 0.4 for f in sweep.frames)


def test_fov_camera_matches_nerfstudio():
    cam = camera_from_fov(90.0, 200, 100)
    assert cam.fy == pytest.approx(50.0) and cam.fx == cam.fy and (cam.cx, cam.cy) == (100.0, 50.0)


def _recording_render(monkeypatch) -> list[dict]:
    calls: list[dict] = []
    original = LoadedRun.render

    def render(self, camera, c2w, states=None, frame_index=None, outputs=("rgb",)):
        calls.append({"states": dict(states), "size": (camera.width, camera.height)})
        return original(self, camera, c2w, states, frame_index, outputs)

    monkeypatch.setattr(LoadedRun, "render", render)
    return calls


def test_render_a_camera_path_to_a_video_resumably(trained_run, tmp_path, monkeypatch, capsys):
    path = _path_file(tmp_path)
    video = tmp_path / "video.mp4"
    calls = _recording_render(monkeypatch)
    args = ["--run", str(trained_run), "--camera-path", path, "--out", str(video), "--no-progress"]
    assert render_main(args) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["frames"] == 10 and stats["rendered"] == 10 and stats["skipped"] == 0
    cap = cv2.VideoCapture(str(video))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 10
    assert (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))) == (16, 12)
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(5.0)
    frames = tmp_path / "video_frames"
    assert sorted(p.name for p in frames.glob("frame_*.png")) == [f"frame_{j:05d}.png" for j in range(10)]
    # the mid frame was rendered at the interpolated state, and the resolved path records it
    assert calls[3]["states"]["object0"] == pytest.approx(0.6) and calls[3]["size"] == (16, 12)
    resolved = json.loads((frames / "camera_path.json").read_text())
    assert resolved["camera_path"][3]["states"]["object0"] == pytest.approx(0.6)

    # a rerun renders only the missing frames
    (frames / "frame_00004.png").unlink()
    (frames / "frame_00007.png").unlink()
    calls.clear()
    assert render_main(args) == 0
    stats = json.loads(capsys.readouterr().out)
    assert (stats["rendered"], stats["skipped"]) == (2, 8) and len(calls) == 2
    # another state for the objects the path leaves alone: the old frames are stale, all are rendered again
    assert render_main([*args, "--state", "object2=1"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert (stats["rendered"], stats["stale_deleted"]) == (10, 10)
    assert all(c["states"]["object2"] == 1.0 for c in calls[2:])


def test_orbit_and_state_sweep_shortcuts(trained_run, tmp_path, monkeypatch, capsys):
    calls = _recording_render(monkeypatch)
    video = tmp_path / "sweep.mp4"
    assert render_main(["--run", str(trained_run), "--states-sweep", "object1", "--fps", "4", "--seconds", "2",
                        "--width", "12", "--height", "8", "--out", str(video), "--no-progress"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["frames"] == 8 and (stats["width"], stats["height"]) == (12, 8)
    assert [c["states"]["object1"] for c in calls] == pytest.approx([0, 0.25, 0.5, 0.75, 1, 0.75, 0.5, 0.25])
    assert int(cv2.VideoCapture(str(video)).get(cv2.CAP_PROP_FRAME_COUNT)) == 8
    calls.clear()
    assert render_main(["--run", str(trained_run), "--orbit", "--fps", "3", "--seconds", "1", "--state", "object0=1",
                        "--out", str(tmp_path / "orbit.mp4"), "--no-progress"]) == 0
    assert len(calls) == 3 and all(c["states"]["object0"] == 1.0 for c in calls)
    assert render_main(["--run", str(trained_run), "--states-sweep", "fridge", "--out", str(tmp_path / "x.mp4")]) == 2
    assert "unknown object 'fridge'" in capsys.readouterr().err
    bad = ["--run", str(trained_run), "--orbit", "--state", "object0=2", "--out", str(tmp_path / "y.mp4")]
    assert render_main(bad) == 2
    assert "'object0=2': state 2 is not in [0, 1]" in capsys.readouterr().err
    # sizes and devices that crashed with a traceback (or after rendering every frame) are refused first
    for size, flag in ((["--width", "0"], "--width: 0 pixels"), (["--width", "-5", "--height", "10"], "--width: -5"),
                       (["--width", "1", "--height", "1"], "--width: 1 pixels; fix: give at least 2")):
        assert render_main(["--run", str(trained_run), "--orbit", *size, "--out", str(tmp_path / "z.mp4")]) == 2
        assert flag in capsys.readouterr().err
    assert not calls[3:] and not (tmp_path / "z.mp4").exists()
    assert render_main(["--run", str(trained_run), "--orbit", "--device", "gpu", "--out", str(tmp_path / "z.mp4")]) == 2
    assert "--device: 'gpu' is not a device; fix: use --device cpu, cuda" in capsys.readouterr().err
