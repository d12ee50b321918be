"""livescene frames on what phones give: date-time photo names, HEIC beside JPEGs, a stalled video, a truncated
video with --count, an undecodable codec, long sources."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from frames_testdata import SHARP, make_frames, textured_frame, write_video

from stages.frames import FramesConfig, extract_frames, frame_name
from stages.frames.cli import main
from stages.frames.frame_source import fourcc_text


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main([*argv, "--no-progress"])
    return code, capsys.readouterr().err


def photo_folder(root: Path, names: list[str]) -> Path:
    folder = root / "photos"
    folder.mkdir()
    for k, name in enumerate(names):
        cv2.imwrite(str(folder / name), textured_frame(k))
    return folder


@pytest.mark.parametrize("names", [
    # Samsung: date_time, a burst shot with a counter (its last number is 1: it would become the first frame)
    ["20231105_101010.jpg", "20231105_101011.jpg", "20231105_101011_1.jpg", "20231105_101012.jpg"],
    # Pixel: the last number is the time of day in ms, which starts again after midnight
    ["PXL_20231105_235958100.jpg", "PXL_20231105_235959300.jpg", "PXL_20231106_000000500.jpg"],
])
def test_photo_names_with_a_date_and_time_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      names: list[str]) -> None:
    code, err = run_cli(capsys, "--video", str(photo_folder(tmp_path, names)), "--out", str(tmp_path / "frames"))
    assert code == 2
    assert "image names carry a date and a time" in err and "not a frame number" in err
    assert "fix: rename the images in the order they were taken" in err
    assert not (tmp_path / "frames").exists()


def test_a_frame_number_against_the_name_order_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = photo_folder(tmp_path, ["take1_0005.jpg", "take2_0001.jpg"])  # a take number and a counter
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(tmp_path / "frames"))
    assert code == 2
    assert "take2_0001.jpg comes after take1_0005.jpg by name but carries the smaller frame number (1 < 5" in err
    # plain counters in any name form still read as before
    folder = tmp_path / "counters"
    folder.mkdir()
    for k, name in enumerate(["IMG_9.jpg", "IMG_10.jpg", "DSC-0011.jpg"]):
        cv2.imwrite(str(folder / name), textured_frame(k))
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(tmp_path / "ok"))
    assert code == 0, err
    assert pd.read_csv(tmp_path / "ok" / "frames.csv")["source_index"].tolist() == [9, 10, 11]


def test_files_the_stage_cannot_read_are_named_not_skipped_silently(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    folder = photo_folder(tmp_path, [f"IMG_{k}.jpg" for k in range(4)])
    (folder / "IMG_4.HEIC").write_bytes(b"\x00\x00\x00\x18ftypheic")
    (folder / "IMG_5.heic").write_bytes(b"\x00\x00\x00\x18ftypheic")
    (folder / ".DS_Store").write_bytes(b"\x00")
    (folder / "Thumbs.db").write_bytes(b"\x00")  # Windows' thumbnail cache: no frame, and nothing to convert
    (folder / "desktop.ini").write_text("[.ShellClassInfo]")
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out))
    assert code == 0
    assert "left out 2 other files (2 .heic: IMG_4.HEIC, IMG_5.heic)" in err and "convert" in err
    assert ".DS_Store" not in err and "Thumbs.db" not in err and "desktop.ini" not in err
    assert json.loads((out / "frames.json").read_text())["skipped_files"] == ["IMG_4.HEIC", "IMG_5.heic"]
    only = tmp_path / "heic"
    only.mkdir()
    (only / "IMG_1.HEIC").write_bytes(b"\x00")
    code, err = run_cli(capsys, "--video", str(only), "--out", str(tmp_path / "none"))
    assert code == 2 and "holds no images" in err and "1 other file (1 .heic" in err and "fix: convert" in err


def test_a_stalled_phone_keeps_new_pictures_first(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 12 frames, each shown 3 times (a phone that stalls): with --count 12 every window keeps its first copy,
    # never a repeat, and the repeats are counted
    frames = make_frames(12, set(range(12)))
    video = write_video(tmp_path / "stall.avi", [f for f in frames for _ in range(3)], fourcc="MJPG")
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(video), "--out", str(out), "--count", "12")
    assert code == 0
    meta = json.loads((out / "frames.json").read_text())
    assert meta["repeated_frame_count"] == 24 and meta["kept_repeats"] == []
    assert pd.read_csv(out / "frames.csv")["source_index"].tolist() == list(range(0, 36, 3))
    assert "24 frames repeat the frame before them exactly" in err
    # every frame kept: the repeats are kept too, and named
    code, err = run_cli(capsys, "--video", str(video), "--out", str(tmp_path / "all"))
    meta = json.loads((tmp_path / "all" / "frames.json").read_text())
    assert code == 0 and meta["n_frames"] == 36 and len(meta["kept_repeats"]) == 24
    assert meta["selection"]["rule"] == "every frame" and "(24 kept: frame_00001.png" in err


def test_a_truncated_video_keeps_the_count_asked_for(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    avi = write_video(tmp_path / "whole.avi", make_frames(20, SHARP), fourcc="MJPG")
    cut = tmp_path / "cut.avi"
    cut.write_bytes(avi.read_bytes()[: avi.stat().st_size // 2])
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(cut), "--out", str(out), "--accept-truncated", "--count", "5")
    assert code == 0
    meta = json.loads((out / "frames.json").read_text())
    decoded = meta["decoded_frame_count"]
    assert meta["truncated"] and meta["source_frame_count"] == 20 and 5 < decoded < 20
    assert meta["n_frames"] == 5, "the windows were cut over the declared length, not the decoded one"
    # the last frame read is cut in half and dropped: the windows span the frames before it
    assert [d["source_index"] for d in meta["dropped"]] == [decoded - 1]
    kept = pd.read_csv(out / "frames.csv")["source_index"].tolist()
    assert kept[-1] >= 4 * (decoded - 1) // 5  # the last window is the last fifth of the whole frames
    assert f"ends after {decoded} of the 20 frames it declares" in err and err.count("overread") == 1
    assert f"over {decoded - 1} frames (of 20 declared: the video ends early)" in meta["selection"]["rule"]


def test_codec_tags_read_as_text() -> None:
    assert fourcc_text(cv2.VideoWriter_fourcc(*"av01")) == "av01"
    assert fourcc_text(cv2.VideoWriter_fourcc(*"MJPG")) == "MJPG"
    assert fourcc_text(0) == "" and fourcc_text(float("nan")) == ""


def test_frame_names_sort_in_frame_order_past_five_digits(tmp_path: Path) -> None:
    folder = photo_folder(tmp_path, ["IMG_99998.png", "IMG_99999.png", "IMG_100000.png"])
    out = tmp_path / "frames"
    extract_frames(FramesConfig(source=folder, out_dir=out, progress=False))
    names = pd.read_csv(out / "frames.csv")["frame"].tolist()
    assert names == ["frame_099998.png", "frame_099999.png", "frame_100000.png"] == sorted(names)
    assert frame_name(12) == "frame_00012.png"  # the contract's width where the numbers fit
    np.testing.assert_array_equal(cv2.imread(str(out / "images" / names[2])), textured_frame(2))


def test_blank_frames_are_named_when_kept(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A lens cover at the start: frame 0 black, frame 1 a dark grey with sensor noise of 1 grey level (standard
    deviation 1 < 2), then the room's texture (tens of levels); frames.json names the two, a clean folder gets no
    warning and no key."""
    folder = photo_folder(tmp_path, [f"IMG_{k}.png" for k in range(5)])
    cv2.imwrite(str(folder / "IMG_0.png"), np.zeros_like(textured_frame(0)))
    noise = np.random.default_rng(0).normal(20.0, 1.0, textured_frame(0).shape[:2])
    cv2.imwrite(str(folder / "IMG_1.png"), np.clip(noise, 0, 255).astype(np.uint8))
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(tmp_path / "out"))
    assert code == 0, err
    names = [frame_name(0), frame_name(1)]
    assert f"2 kept frame(s) hold almost one grey level ({names[0]}, {names[1]}): a lens cover" in err
    assert json.loads((tmp_path / "out" / "frames.json").read_text())["blank_frames"] == names
    (tmp_path / "clean").mkdir()
    clean = photo_folder(tmp_path / "clean", [f"IMG_{k}.png" for k in range(5)])
    code, err = run_cli(capsys, "--video", str(clean), "--out", str(tmp_path / "clean_out"))
    assert code == 0 and "grey level" not in err
    assert "blank_frames" not in json.loads((tmp_path / "clean_out" / "frames.json").read_text())
