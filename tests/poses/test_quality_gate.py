"""The quality gate: too few frames, a still camera, or frames that do not register fail with advice."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from poses_testdata import orbit_poses, write_sequence

from stages.poses import PosesConfig, StaticCameraError, estimate_poses, pipeline
from stages.poses.cli import main
from stages.poses.pipeline import registration_detail
from stages.poses.quality_gate import (
    blank_frames_note,
    compact_names,
    intrinsics_warnings,
    registration_advice,
    split_model_warning,
    too_few_frames_advice,
)
from stages.poses.sfm import SfmResult
from stages.poses.static_check import MotionPrecheck
from stages.scene import InputError, write_json


def test_too_short_sequence(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_sequence(tmp_path / "frames", orbit_poses(2))
    out = tmp_path / "poses"
    assert main(["--frames", str(tmp_path / "frames"), "--out", str(out), "--threads", "2", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "only 2 frame(s); structure from motion needs at least 3" in err and "--stride 1" in err
    assert not out.exists()


def test_static_camera_is_reported_as_such(tmp_path: Path) -> None:
    pose = orbit_poses(5)[2]
    write_sequence(tmp_path / "frames", [pose] * 6, noise_std=2.0)
    out = tmp_path / "poses"
    with pytest.raises(StaticCameraError) as info:
        estimate_poses(PosesConfig(frames_dir=tmp_path / "frames", out_dir=out, threads=2, progress=False))
    message = str(info.value)
    assert "the camera does not move" in message and "move the camera through the room" in message
    assert not out.exists()


def test_unregistered_frames_are_listed_with_advice(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """8 frames of the room, then 4 of a room with other textures (nothing matches them): 67% < 80%."""
    frames = tmp_path / "frames"
    write_sequence(frames, orbit_poses(8))
    other = tmp_path / "other"
    write_sequence(other, orbit_poses(4, arc_deg=20), source_indices=[8, 9, 10, 11], seed=7)
    for png in (other / "images").iterdir():
        shutil.copy(png, frames / "images" / png.name)
    # the frames stage found two of them blank (the note names those, not every unregistered frame)
    (frames / "frames.json").write_text(json.dumps({"blank_frames": ["frame_00009.png", "frame_00010.png"]}))
    out = tmp_path / "poses"
    code = main(["--frames", str(frames), "--out", str(out), "--threads", "2", "--seed", "0", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith(f"error: {frames}: only 8 of 12 frames (67%) received a pose, below the required 80%")
    assert "(2 of them hold almost one grey level, as `livescene frames` warned: frame_00009..frame_00010 (2);" in err
    assert "unregistered frames: frame_00008..frame_00011 (4)" in err
    # 12 frames: auto matching was already exhaustive, so the advice must not suggest it again (issue 17)
    assert "--matcher exhaustive" not in err and "overlap" in err and "sharper frames" in err
    assert "lower --min-registered, now 0.8" in err
    assert not out.exists()
    # a lower bar accepts the partial model and records what is missing; had the other room's frames made a
    # model of their own (COLMAP keeps the largest), the run warns with the frames it leaves out
    real_sfm = pipeline.run_sfm
    monkeypatch.setattr(pipeline, "run_sfm", lambda *a, **k: dataclasses.replace(real_sfm(*a, **k), n_models=2))
    summary = estimate_poses(PosesConfig(frames_dir=frames, out_dir=out, threads=2, min_registered=0.6,
                                         progress=False))
    assert summary["unregistered"] == [f"frame_{i:05d}.png" for i in range(8, 12)]
    assert [w for w in summary["warnings"] if "broke into 2 separate models" in w and
            "the 4 frame(s) it does not pose (of the other models, or of none) are left out: "
            "frame_00008..frame_00011 (4)" in w]


def test_advice_leaves_out_what_was_tried(tmp_path: Path) -> None:
    cfg = PosesConfig(frames_dir=tmp_path, out_dir=tmp_path / "out")
    sequential = registration_advice(cfg, "sequential")
    assert "`--matcher exhaustive`" in sequential and "a larger `--overlap` (now 10)" in sequential
    assert "smaller `livescene frames --stride`" in sequential and "lower --min-registered, now 0.8" in sequential
    exhaustive = registration_advice(cfg, "exhaustive")
    assert "--matcher exhaustive" not in exhaustive and "--overlap" not in exhaustive
    tried = PosesConfig(frames_dir=tmp_path, out_dir=tmp_path / "out", sequential_overlap=30, min_registered=0.5)
    advice = registration_advice(tried, "sequential")
    assert "--overlap" not in advice and "--min-registered" not in advice and "--matcher exhaustive" in advice
    # every source frame already extracted: a smaller stride is no fix, for too few frames either
    assert "--stride 1" in too_few_frames_advice(tmp_path)
    write_json(tmp_path / "frames.json", {"n_frames": 20, "decoded_frame_count": 20})
    assert "--stride" not in registration_advice(cfg, "sequential")
    assert "film a longer clip" in too_few_frames_advice(tmp_path)


def test_compact_names() -> None:
    names = [f"frame_{i:05d}.png" for i in (3, 4, 5, 9, 11, 12)]
    assert compact_names(names) == "frame_00003..frame_00005 (3), frame_00009, frame_00011..frame_00012 (2)"
    # in playback order a clip that skips frames 6-8 and 10 still runs from 3 to 12
    order = [f"frame_{i:05d}.png" for i in (1, 3, 4, 5, 9, 11, 12, 14)]
    assert compact_names(names, order=order) == "frame_00003..frame_00012 (6)"
    without_9 = names[:3] + names[4:]
    assert compact_names(without_9, order=order) == "frame_00003..frame_00005 (3), frame_00011..frame_00012 (2)"


def test_missing_frames_folder(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="frames folder not found"):
        estimate_poses(PosesConfig(frames_dir=tmp_path / "nowhere", out_dir=tmp_path / "o", progress=False))


def test_intrinsics_warnings() -> None:
    assert intrinsics_warnings(100.0, 102.0, 160, 120) == []
    (warning,) = intrinsics_warnings(80.0, 877.0, 96, 72)
    assert "differ by more than 25%" in warning and "SIMPLE_RADIAL" in warning
    (warning,) = intrinsics_warnings(5000.0, 5000.0, 160, 120)
    assert "field of view is 2 degrees" in warning


def test_few_features_are_named_before_the_matching(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Painted walls: frames of a 70-degree orbit at 0.15 of their contrast hold few SIFT features; the error
    says so and leads with texture, not with matching harder or with a turn on the spot (docs/poses.md)."""
    frames = tmp_path / "frames"
    write_sequence(frames, orbit_poses(8))
    for png in (frames / "images").iterdir():
        image = cv2.imread(str(png)).astype(np.float32)
        cv2.imwrite(str(png), np.clip(128 + 0.15 * (image - image.mean()), 0, 255).astype(np.uint8))
    out = tmp_path / "poses"
    assert main(["--frames", str(frames), "--out", str(out), "--threads", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "received a pose" in err and "the frames hold few features: SIFT kept a median of " in err
    assert "fix: film with more texture in view" in err and "turns on the spot" not in err
    assert not out.exists()


def test_feature_shortage_detail_and_advice(tmp_path: Path) -> None:
    cfg = PosesConfig(frames_dir=tmp_path, out_dir=tmp_path / "out")
    sfm = SfmResult(reconstruction=None, n_models=0, matcher="sequential")
    turn = MotionPrecheck(n_frames_sampled=24, n_pairs=26, long_side_px=512, still_threshold_px=2.3, n_lost=0,
                          max_still_px=30.0, still_pair_fraction=0.0, still_frames=[], still_spans=[],
                          parallax_threshold_px=2.3, rotation_only_fraction=1.0, seconds=1.0)
    # median of 46, 58, 80 is 58 < 200 (twice COLMAP's 100 matches to start a model); masks hide 18 %
    detail, advice = registration_detail(None, sfm, turn, cfg, [58, 46, 80], 0.18)
    assert ("SIFT kept a median of 58 per frame (46 in the poorest) outside the object masks, which hide 18% of a "
            "frame on average") in detail and "turns on the spot" not in detail
    assert advice.startswith("film with more texture in view") and "`--matcher exhaustive`" in advice
    # masks over most of the view (84 %): the fix is to keep more of the static room in view
    _, advice = registration_detail(None, sfm, turn, cfg, [66, 17, 145], 0.84)
    assert advice.startswith("the moving objects fill most of the view")
    # a median of exactly 200 (150, 250) is not few: the turn on the spot is reported as before
    detail, advice = registration_detail(None, sfm, turn, cfg, [100, 150, 250, 300], None)
    assert "few features" not in detail and "the camera turns on the spot" in detail
    assert advice.startswith("move the camera through the room")


def test_a_run_that_passes_with_several_models_warns_with_the_frames_it_leaves_out():
    ordered = [f"frame_{i:05d}.png" for i in range(10)]
    assert split_model_warning(1, ordered[7:], ordered, "try X") is None  # one model: the gate said all there is
    assert split_model_warning(2, [], ordered, "try X") is None  # the kept model poses every frame: nothing lost
    line = split_model_warning(2, ordered[7:], ordered, "try X")
    assert "broke into 2 separate models" in line
    assert "the 3 frame(s) it does not pose (of the other models, or of none) are left out" in line
    assert "frame_00007..frame_00009 (3)" in line and line.endswith("To keep them, try X")


def test_the_blank_frames_note_reads_frames_json_and_names_only_unregistered_blank_ones(tmp_path: Path) -> None:
    assert blank_frames_note(tmp_path, ["frame_00001.png"]) == ""  # a plain folder: no frames.json
    (tmp_path / "frames.json").write_text(json.dumps({"blank_frames": ["frame_00001.png", "frame_00002.png"]}))
    assert blank_frames_note(tmp_path, ["frame_00003.png"]) == ""  # the blank frames registered
    assert blank_frames_note(tmp_path, ["frame_00002.png", "frame_00003.png"]).startswith(
        " (1 of them hold almost one grey level, as `livescene frames` warned: frame_00002;")
    (tmp_path / "frames.json").write_text("{not json")
    assert blank_frames_note(tmp_path, ["frame_00002.png"]) == ""
