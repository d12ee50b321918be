"""The pose gate beyond registration: a still camera found before COLMAP, implausible camera paths after it."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from poses_testdata import orbit_poses, write_sequence

from stages.poses import PosesConfig, StaticCameraError, estimate_poses
from stages.poses.camera_motion import FeatureMotion
from stages.poses.errors import DegenerateTrajectoryError
from stages.poses.quality_gate import check_trajectory, registration_advice
from stages.poses.static_check import MotionPrecheck, measure_motion
from stages.poses.trajectory_check import TrajectorySettings, judge_trajectory

NO_MOTION = FeatureMotion(n_pairs=10, max_median_px=5.0, rotation_only_fraction=0.0)


def names(n: int) -> list[str]:
    return [f"frame_{i:05d}.png" for i in range(n)]


def gate(tmp_path: Path) -> PosesConfig:
    return PosesConfig(frames_dir=tmp_path / "frames", out_dir=tmp_path / "out")


def sfm_gate(tmp_path: Path, matcher: str) -> tuple[Path, TrajectorySettings, str]:
    """The trajectory gate's arguments as the poses stage passes them after a run with ``matcher``."""
    cfg = gate(tmp_path)
    return cfg.frames_dir, cfg.trajectory_settings(), registration_advice(cfg, matcher)


def arc(n: int, radius: float = 3.0, seed: int = 0) -> np.ndarray:
    t = np.linspace(0.0, 1.5, n)
    rng = np.random.default_rng(seed)
    return np.stack([radius * np.cos(t), radius * np.sin(t), np.zeros(n)], 1) + rng.normal(0, 0.005, (n, 3))


def tripod_after_pan() -> np.ndarray:
    """Issue 17's measured model: 65 cameras up to 36 units away, then 202 within 0.01 of each other."""
    rng = np.random.default_rng(1)
    pan = np.cumsum(rng.normal(0, 1, (65, 3)), 0)
    pan = pan - pan[-1] + [0.3, 0.0, 0.0]  # the pan ends next to the tripod spot, not on it
    pan *= 36.0 / np.max(np.linalg.norm(pan, axis=1))
    return np.vstack([pan, rng.normal(0, 0.002, (202, 3))])


def test_a_tripod_clip_after_a_short_pan_is_refused_naming_the_frames(tmp_path: Path) -> None:
    judged = judge_trajectory(names(267), tripod_after_pan(), np.arange(267), 4.75, 267, [267])
    assert judged.verdict == "refuse" and judged.reason == "mostly still"
    assert judged.still_share == pytest.approx(202 / 267) and judged.still_spread < 0.02
    assert judged.moving_reach == pytest.approx(36.0, abs=0.01)
    with pytest.raises(DegenerateTrajectoryError) as info:
        check_trajectory(judged, *sfm_gate(tmp_path, "sequential"), NO_MOTION, None)
    message = str(info.value)
    assert "frames frame_00000..frame_00064 (65) lie up to 36 units from the other 202 cameras" in message
    assert "frame_00065..frame_00266 (202)" in message and "median point depth 4.75" in message
    assert "202 of 267 registered frames (76%, above 50%)" in message
    assert "fix: film the scene moving around the room" in message
    # the pan is 65 frames with a baseline of their own: cutting the clip to them is offered
    assert "cut the clip to the frames where the camera moves (frame_00000..frame_00064 (65))" in message
    # when the feature tracks say the moving frames only turn (a tripod pan), cutting to them is no fix
    pan = MotionPrecheck(n_frames_sampled=24, n_pairs=26, long_side_px=512, still_threshold_px=2.3, n_lost=0,
                         max_still_px=30.0, still_pair_fraction=0.76, still_frames=[], still_spans=[],
                         parallax_threshold_px=2.3, rotation_only_fraction=1.0, seconds=1.0)
    with pytest.raises(DegenerateTrajectoryError) as info:
        check_trajectory(judged, *sfm_gate(tmp_path, "sequential"), NO_MOTION, pan)
    assert "the frames that move show no parallax" in str(info.value) and "cut the clip" not in str(info.value)


def test_a_smooth_path_passes_and_a_frame_gap_is_no_jump() -> None:
    times = np.arange(50)
    times[30:] += 14  # frames 30.. come 14 source frames later (the ones between were dropped as blurry)
    t = 0.03 * times  # so the camera moved on by 15 steps between frames 29 and 30
    centres = np.stack([3 * np.cos(t), 3 * np.sin(t), np.zeros(50)], 1)
    judged = judge_trajectory(names(50), centres, times, 3.0, 50, [50])
    assert judged.verdict == "pass" and judged.trimmed == [] and len(judged.pieces) == 1
    assert judged.baseline_ratio > 1.0 and judged.still_share < 0.1 and judged.largest_model_share == 1.0
    # the same positions without the gap in time: one step of 15 typical ones is a jump
    assert judge_trajectory(names(50), centres, np.arange(50), 3.0, 50, [50]).verdict == "trim"


def test_a_camera_that_jumps_away_and_back_is_trimmed(tmp_path: Path) -> None:
    centres = arc(50)
    centres[20] += [2.0, 0.0, 0.0]
    judged = judge_trajectory(names(50), centres, np.arange(50), 3.0, 50, [50])
    assert judged.verdict == "trim" and judged.jump_outliers == ["frame_00020.png"]
    assert judged.trimmed == ["frame_00020.png"] and len(judged.kept) == 49
    (warning,) = check_trajectory(judged, *sfm_gate(tmp_path, "sequential"), NO_MOTION, None)
    assert warning.startswith("dropped 1 frame(s) whose cameras jump away from their neighbours in time "
                              "(frame_00020)")


def test_a_broken_path_is_cut_to_its_majority_or_refused(tmp_path: Path) -> None:
    centres = arc(50)
    centres[40:] += [5.0, 0.0, 0.0]  # the last 10 frames continue somewhere else
    judged = judge_trajectory(names(50), centres, np.arange(50), 3.0, 50, [50])
    assert judged.verdict == "trim" and judged.trimmed == names(50)[40:]
    assert judged.pieces == [["frame_00000.png", "frame_00039.png"], ["frame_00040.png", "frame_00049.png"]]
    centres[25:] += [5.0, 0.0, 0.0]  # now three pieces of 25, 15 and 10: no majority
    judged = judge_trajectory(names(50), centres, np.arange(50), 3.0, 50, [50])
    assert judged.verdict == "refuse" and judged.piece_sizes == [25, 15, 10]
    with pytest.raises(DegenerateTrajectoryError) as info:
        check_trajectory(judged, *sfm_gate(tmp_path, "exhaustive"), NO_MOTION, None)
    message = str(info.value)
    assert "breaks into 3 pieces" in message and "frame_00025.png..frame_00039.png (15)" in message
    assert "--matcher exhaustive" not in message  # already tried


def test_a_model_without_baseline_is_static(tmp_path: Path) -> None:
    centres = np.random.default_rng(0).normal(0, 0.001, (20, 3))
    judged = judge_trajectory(names(20), centres, np.arange(20), 4.0, 20, [20])
    assert judged.verdict == "refuse" and judged.reason == "static" and judged.baseline_ratio < 0.01
    with pytest.raises(StaticCameraError, match="the camera does not move"):
        check_trajectory(judged, *sfm_gate(tmp_path, "sequential"), NO_MOTION, None)


# -- before structure from motion --------------------------------------------------------------------------------


def test_precheck_tells_a_still_camera_from_a_moving_one(tmp_path: Path) -> None:
    pose = orbit_poses(5)[2]
    images, _, _ = write_sequence(tmp_path / "still", [pose] * 8, noise_std=2.0)
    still = measure_motion(images, sorted(p.name for p in images.iterdir()), 0.004)
    assert still.static and still.n_pairs >= 7 and still.max_still_px < 0.5 and still.still_pair_fraction == 1.0
    images, _, _ = write_sequence(tmp_path / "moving", orbit_poses(8), noise_std=2.0)
    moving = measure_motion(images, sorted(p.name for p in images.iterdir()), 0.004)
    assert not moving.static and moving.still_pair_fraction == 0.0


def test_precheck_ignores_a_person_walking_in_front_of_a_still_camera(tmp_path: Path) -> None:
    """A textured block crossing a still view holds most corners: the background says the camera does not move."""
    pose = orbit_poses(5)[2]
    images, _, _ = write_sequence(tmp_path / "still", [pose] * 8, noise_std=2.0)
    texture = cv2.GaussianBlur(np.random.default_rng(3).normal(0, 1, (120, 200)).astype(np.float32), (0, 0), 2.0)
    texture = np.clip(128 + 60 * texture / texture.std(), 0, 255).astype(np.uint8)
    for k, path in enumerate(sorted(images.iterdir())):
        image = cv2.imread(str(path))
        image[:, 20 + 3 * k:110 + 3 * k] = texture[:, 40 - 3 * k:130 - 3 * k, None]  # moves 6 px a frame
        cv2.imwrite(str(path), image)
    pre = measure_motion(images, sorted(p.name for p in images.iterdir()), 0.004)
    assert pre.static
    # while the median corner (what COLMAP's check uses) does move in some pair
    assert max(p.median_px or 0.0 for p in pre.pairs) > pre.still_threshold_px


def test_still_clip_is_refused_before_colmap(tmp_path: Path) -> None:
    pose = orbit_poses(5)[2]
    write_sequence(tmp_path / "frames", [pose] * 6, noise_std=2.0)
    with pytest.raises(StaticCameraError) as info:
        estimate_poses(PosesConfig(frames_dir=tmp_path / "frames", out_dir=tmp_path / "poses", threads=2,
                                   progress=False))
    message = str(info.value)
    assert "before structure from motion" in message and "frame_00000..frame_00005 (6 frames)" in message
    assert not (tmp_path / "poses").exists()


def test_tripod_clip_with_a_short_pan_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Rendered room: 6 frames on an arc, then 14 from the last arc pose (sensor noise): refused, frames named."""
    poses = orbit_poses(6, arc_deg=30.0)
    write_sequence(tmp_path / "frames", poses + [poses[-1]] * 14, noise_std=1.5)
    out = tmp_path / "poses"
    with pytest.raises(DegenerateTrajectoryError) as info:
        estimate_poses(PosesConfig(frames_dir=tmp_path / "frames", out_dir=out, threads=2, progress=False))
    message = str(info.value)
    assert "were filmed from one spot" in message and "frames frame_00000..frame_00004 (5) lie up to" in message
    assert not out.exists()
    # the pre-check saw it coming and said so before COLMAP ran
    assert "74% of neighbouring sampled frames show no camera motion (frame_00005..frame_00019)" in \
        capsys.readouterr().err
    # with the bar raised past the still share the same frames pass, and poses.json holds the judged numbers
    summary = estimate_poses(PosesConfig(frames_dir=tmp_path / "frames", out_dir=out, threads=2, progress=False,
                                         max_still_share=0.9))
    written = json.loads((out / "poses.json").read_text())["trajectory"]
    assert written == json.loads(json.dumps(summary["trajectory"]))
    assert written["still_share"] >= 0.7 and written["verdict"] == "pass"
    for key in ("baseline_ratio", "spread_ratio", "largest_model_share", "median_point_depth", "jump_outliers"):
        assert key in written
    assert summary["motion_precheck"]["still_pair_fraction"] > 0.5


def test_trimmed_frames_leave_the_model(tmp_path: Path) -> None:
    """A COLMAP model with one camera thrown across the room: judged, trimmed, and gone from transforms.json."""
    import pycolmap

    from stages.poses import cam_from_world_from_c2w_opengl
    from stages.poses.model_export import drop_frames, judge_camera_path, transforms_dict
    from stages.poses.sfm import SfmResult
    from stages.scene import look_at

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=160, height=120,
                                                    params=[100.0, 100.0, 80.0, 60.0], camera_id=1))
    frame_names = names(30)
    for k, (name, eye) in enumerate(zip(frame_names, arc(30), strict=True)):
        if k == 12:
            eye = eye + np.array([0.0, 0.0, 2.5])  # a mis-registered frame, 2.5 units above its neighbours
        rotation, translation = cam_from_world_from_c2w_opengl(look_at(eye, np.zeros(3)))
        pose = pycolmap.Rigid3d(rotation=pycolmap.Rotation3d(rotation), translation=translation)
        rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=1, image_id=k + 1), pose)
    for xyz in np.random.default_rng(0).uniform(-0.5, 0.5, (200, 3)):
        rec.add_point3D(xyz, pycolmap.Track())
    sfm = SfmResult(reconstruction=rec, n_models=1, matcher="sequential", model_sizes=[30])
    judged = judge_camera_path(rec, frame_names, {n: float(k) for k, n in enumerate(frame_names)}, set(frame_names),
                               sfm.model_sizes, gate(tmp_path).trajectory_settings())
    assert judged.verdict == "trim" and judged.trimmed == ["frame_00012.png"]
    assert judged.median_point_depth == pytest.approx(3.0, abs=0.3) and judged.max_step_ratio > 10
    drop_frames(rec, judged.trimmed)
    written = [f["file_path"] for f in transforms_dict(rec, {})["frames"]]
    assert len(written) == 29 and "images/frame_00012.png" not in written
