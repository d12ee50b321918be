"""Damaged frames (issue 17 item 7): truncated or corrupt images and video frames are dropped by name, never kept."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from frames_testdata import (
    SHARP,
    damage_middle,
    encoded,
    jpeg_with_corrupt_scan,
    make_frames,
    png_with_bad_crc,
    png_with_broken_tail,
    textured_frame,
    truncated_jpeg,
    write_video,
)

from stages.frames import DROPPED_CSV, bytes_problem, decode_image
from stages.frames.cli import main
from stages.frames.integrity import DecoderReport, StderrCapture
from stages.scene import STAGE_MARKER

# a folder of 12 frames, numbered 0..11: these five are damaged, each in its own way
DAMAGED = {
    2: ("frame_0002.jpg", truncated_jpeg, "no JPEG end marker (FFD9) after the image data: the file is cut off "
                                          "after 3000 bytes"),
    4: ("frame_0004.png", png_with_broken_tail, "the IEND chunk at byte"),
    6: ("frame_0006.jpg", lambda _: b"", "the file is empty (0 bytes)"),
    8: ("frame_0008.png", lambda _: b"not an image at all" * 20, "OpenCV cannot decode it"),
    9: ("frame_0009.jpg", jpeg_with_corrupt_scan, "the decoder reported damaged data: \"Corrupt JPEG data"),
}


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main([*argv, "--no-progress"])
    return code, capsys.readouterr().err


def damaged_folder(root: Path, damaged: dict = DAMAGED, n: int = 12) -> Path:
    """``n`` frames of one size, JPEG and PNG mixed; the frames in ``damaged`` written broken."""
    folder = root / "shots"
    folder.mkdir()
    frames = make_frames(n, set(range(n)))  # all sharp
    for i in range(n):
        if i in damaged:
            name, breaker, _ = damaged[i]
            (folder / name).write_bytes(breaker(frames[i]))
        else:
            ext = ".jpg" if i % 2 else ".png"
            (folder / f"frame_{i:04d}{ext}").write_bytes(encoded(frames[i], ext))
    return folder


def test_each_damaged_image_is_dropped_by_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = damaged_folder(tmp_path)
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out))
    assert code == 0, err
    whole = [i for i in range(12) if i not in DAMAGED]
    # frames.csv and images/ hold only the whole frames
    table = pd.read_csv(out / "frames.csv")
    assert list(table.columns) == ["frame", "source_index", "timestamp", "sharpness"]
    assert table["source_index"].tolist() == whole
    assert sorted(p.name for p in (out / "images").iterdir()) == [f"frame_{i:05d}.png" for i in whole]
    # each damaged one is listed by name with its problem ...
    dropped = pd.read_csv(out / DROPPED_CSV)
    assert dropped["source_index"].tolist() == sorted(DAMAGED)
    assert dropped["frame"].tolist() == [f"frame_{i:05d}.png" for i in sorted(DAMAGED)]
    for (_, row), i in zip(dropped.iterrows(), sorted(DAMAGED), strict=True):
        name, _, problem = DAMAGED[i]
        assert Path(row["source_file"]) == folder / name
        assert problem in row["problem"], (name, row["problem"])
        # ... and named in a warning on stderr, libjpeg's own line included (not left anonymous)
        assert f"warning: {folder / name}: {row['problem']}; dropped (listed in {DROPPED_CSV})" in err
    assert "Premature end of JPEG file" not in err  # the truncated JPEG was never handed to the decoder
    meta = json.loads((out / "frames.json").read_text())
    assert meta["dropped_frame_count"] == 5 and meta["n_frames"] == 7 and meta["decoded_frame_count"] == 12
    assert [d["source_index"] for d in meta["dropped"]] == sorted(DAMAGED)
    assert [d["problem"] for d in meta["dropped"]] == dropped["problem"].tolist()
    assert [s is None for s in meta["sharpness_all"]] == [i in DAMAGED for i in range(12)]


def test_summary_line_counts_the_dropped(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--video", str(damaged_folder(tmp_path)), "--out", str(tmp_path / "frames"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "kept 7 of 12 frames" in out and "dropped 5 damaged (frames_dropped.csv)" in out


def test_png_crc_mismatch_is_dropped(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    damaged = {1: ("frame_0001.png", png_with_bad_crc, "CRC mismatch in the IDAT chunk")}
    folder = damaged_folder(tmp_path, damaged, n=3)
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out))
    assert code == 0
    assert pd.read_csv(out / "frames.csv")["source_index"].tolist() == [0, 2]
    assert "frame_0001.png: CRC mismatch in the IDAT chunk at byte" in err


def test_window_falls_back_to_a_whole_frame(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # stride 4: windows [0-3] [4-7] [8-11]; the sharp frame of the first window (2) is truncated
    folder = tmp_path / "shots"
    folder.mkdir()
    frames = make_frames(12, {2, 5, 9})
    for i, frame in enumerate(frames):
        (folder / f"frame_{i:04d}.jpg").write_bytes(truncated_jpeg(frame) if i == 2 else encoded(frame, ".jpg"))
    out = tmp_path / "frames"
    code, _ = run_cli(capsys, "--video", str(folder), "--out", str(out), "--stride", "4")
    assert code == 0
    kept = pd.read_csv(out / "frames.csv")["source_index"].tolist()
    assert kept[1:] == [5, 9] and kept[0] in {0, 1, 3}  # a blurred but whole frame replaces the broken one


def test_downstream_readers_see_only_whole_frames(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from stages.dataset.assemble import list_images
    from stages.labels.frame_set import read_frame_set
    from stages.poses.frame_list import read_frame_list
    from stages.states.frame_table import read_frame_table

    out = tmp_path / "frames"
    assert run_cli(capsys, "--video", str(damaged_folder(tmp_path)), "--out", str(out))[0] == 0
    whole = [f"frame_{i:05d}.png" for i in range(12) if i not in DAMAGED]
    assert list(read_frame_table(out).names) == whole
    assert [f"frame_{fid}.png" for fid in read_frame_set(out).frame_ids] == whole
    assert read_frame_list(out).names == whole
    assert sorted(list_images(out)[2]) == whole


def test_too_many_damaged_images_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    damaged = {1: ("frame_0001.jpg", truncated_jpeg, ""), 2: ("frame_0002.png", png_with_broken_tail, ""),
               4: ("frame_0004.jpg", lambda _: b"", "")}
    folder = damaged_folder(tmp_path, damaged, n=5)  # 3 of 5 damaged: more than half
    out = tmp_path / "frames"
    out.mkdir()
    (out / STAGE_MARKER).write_text("frames\n")  # an earlier frames output, which a good run would replace
    (out / "earlier.txt").write_text("an earlier result")
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out))
    assert code == 2
    line = next(s for s in err.splitlines() if s.startswith("error:"))
    assert line.startswith(f"error: {folder}: 3 of the 5 images are damaged")
    for name, _, _ in damaged.values():
        assert name in line
    assert "fix: copy the images again" in line and "--max-dropped" in line
    assert sorted(p.name for p in out.iterdir()) == [STAGE_MARKER, "earlier.txt"]  # nothing written, old output kept
    # asked for, the whole ones are kept
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out), "--max-dropped", "1")
    assert code == 0 and pd.read_csv(out / "frames.csv")["source_index"].tolist() == [0, 3]
    # --max-dropped 0: the first damaged image already refuses
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(tmp_path / "strict"), "--max-dropped", "0")
    assert code == 2 and f"error: {folder / 'frame_0001.jpg'}: 1 of the 5 images are damaged" in err
    assert "stopped after checking 2" in err and not (tmp_path / "strict").exists()


def test_all_damaged_is_refused_naming_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "one"
    folder.mkdir()
    bad = folder / "IMG_0001.jpg"
    bad.write_bytes(truncated_jpeg(textured_frame(0)))
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out))
    assert code == 2
    assert f"error: {bad}: 1 of the 1 images are damaged" in err and "no JPEG end marker" in err
    assert "fix: copy the images again" in err and not out.exists()
    # even with every share allowed, a source with no whole frame left is refused
    (folder / "IMG_0002.png").write_bytes(b"")
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(out), "--max-dropped", "1")
    assert code == 2 and "none of the 2 images read is whole" in err
    assert "IMG_0001.jpg: no JPEG end marker" in err and "IMG_0002.png: the file is empty (0 bytes)" in err
    assert not out.exists()


def test_unreadable_file_is_dropped(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    folder = damaged_folder(tmp_path, {}, n=3)
    locked = folder / "frame_0001.jpg"
    if hasattr(os, "geteuid") and os.geteuid() != 0:
        locked.chmod(0)  # a real permission error
    else:  # root reads any file: make the read fail as it would for another user
        read_bytes = Path.read_bytes

        def refuse(self: Path) -> bytes:
            if self == locked:
                raise PermissionError(13, "Permission denied", str(self))
            return read_bytes(self)

        monkeypatch.setattr(Path, "read_bytes", refuse)
    try:
        code, err = run_cli(capsys, "--video", str(folder), "--out", str(tmp_path / "frames"))
    finally:
        locked.chmod(0o644)
    assert code == 0 and f"{locked}: the file cannot be read (Permission denied); dropped" in err
    assert pd.read_csv(tmp_path / "frames" / "frames.csv")["source_index"].tolist() == [0, 2]


def test_damaged_video_frames_are_dropped(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # MJPG: one frame's JPEG data overwritten; FFmpeg decodes it with concealment and only logs "overread"
    avi = write_video(tmp_path / "whole.avi", make_frames(20, SHARP), fourcc="MJPG")
    bad_avi = damage_middle(avi, tmp_path / "bad.avi", b"\xff")
    out = tmp_path / "a"
    code, err = run_cli(capsys, "--video", str(bad_avi), "--out", str(out))
    assert code == 0, err
    dropped = pd.read_csv(out / DROPPED_CSV)
    kept = pd.read_csv(out / "frames.csv")["source_index"].tolist()
    assert len(dropped) == 1 and "FFmpeg reported damaged data" in dropped["problem"][0]
    i = int(dropped["source_index"][0])
    assert kept == [k for k in range(20) if k != i]
    assert f"bad.avi: frame {i} (t={i / 10:.2f} s): FFmpeg reported damaged data" in err
    assert " @ 0x" not in dropped["problem"][0]  # FFmpeg's pointer is stripped: the same text on every run
    # mp4v: a damaged frame, then one OpenCV cannot decode at all; the frames after it still decode and are kept
    mp4 = write_video(tmp_path / "whole.mp4", make_frames(20, SHARP))
    bad_mp4 = damage_middle(mp4, tmp_path / "bad.mp4", b"\x00")
    out = tmp_path / "b"
    code, err = run_cli(capsys, "--video", str(bad_mp4), "--out", str(out))
    assert code == 0, err
    dropped = pd.read_csv(out / DROPPED_CSV)
    kept = pd.read_csv(out / "frames.csv")["source_index"].tolist()
    assert len(dropped) >= 1 and sorted(kept + dropped["source_index"].tolist()) == list(range(20))
    assert any("OpenCV could not decode this frame" in p for p in dropped["problem"])
    assert max(kept) == 19
    meta = json.loads((out / "frames.json").read_text())
    assert meta["decoded_frame_count"] == 20 and not meta["truncated"]
    # a whole video lists nothing
    code, _ = run_cli(capsys, "--video", str(mp4), "--out", str(tmp_path / "c"))
    assert code == 0 and pd.read_csv(tmp_path / "c" / DROPPED_CSV).empty


def test_checks_from_the_bytes() -> None:
    frame = textured_frame(0)
    jpg, png = encoded(frame, ".jpg"), encoded(frame, ".png")
    assert bytes_problem(jpg) is None and bytes_problem(png) is None
    # bytes after the end marker (a phone's motion photo appends its video) are not damage
    assert bytes_problem(jpg + b"\x00" * 100 + b"ftypmp42" * 50) is None
    # an EXIF thumbnail carries its own FFD9 before the scan: a cut main image is still caught
    thumb = encoded(cv2.resize(frame, (16, 12)), ".jpg")
    app1 = b"Exif\x00\x00" + thumb
    with_thumb = jpg[:2] + b"\xff\xe1" + (len(app1) + 2).to_bytes(2, "big") + app1 + jpg[2:]
    assert bytes_problem(with_thumb) is None
    assert "no JPEG end marker" in (bytes_problem(with_thumb[:-200]) or "")
    assert "ends inside the JPEG header" in (bytes_problem(jpg[:100]) or "")
    # a progressive JPEG has several scans with tables between them: whole is whole, cut is caught
    progressive = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1].tobytes()
    assert bytes_problem(progressive) is None
    assert "no JPEG end marker" in (bytes_problem(progressive[: len(progressive) * 2 // 3]) or "")
    assert "no IEND chunk" in (bytes_problem(png[:33]) or "")  # signature + IHDR only
    assert "the IDAT chunk at byte 33 runs past the end" in (bytes_problem(png[: len(png) // 2]) or "")
    assert bytes_problem(b"") == "the file is empty (0 bytes)"


def test_decoder_stderr_is_caught_and_attributed(capfd: pytest.CaptureFixture[str]) -> None:
    with StderrCapture() as capture:
        result, text = capture.call(lambda: os.write(2, b"Premature end of JPEG file\n") and 7)
        assert result == 7 and text == "Premature end of JPEG file\n"
        assert capture.call(lambda: None) == (None, "")  # nothing carried over to the next call
        image, problem, remarks = decode_image(jpeg_with_corrupt_scan(textured_frame(0)), capture)
    assert image is None and problem is not None and "Corrupt JPEG data" in problem and remarks == ()
    assert capfd.readouterr().err == ""  # the decoder's line did not leak to the real stderr unattributed
    report = DecoderReport.from_text("libpng warning: iCCP: known incorrect sRGB profile\n"
                                     "[mjpeg @ 0x55d0c0ffee00] overread 2\n\n")
    assert report.damage == ("[mjpeg] overread 2",)
    assert report.remarks == ("libpng warning: iCCP: known incorrect sRGB profile",)
    whole, problem, remarks = decode_image(encoded(textured_frame(0), ".png"), StderrCapture())
    assert whole is not None and whole.shape == (64, 96, 3) and problem is None and remarks == ()
    np.testing.assert_array_equal(whole, textured_frame(0))
