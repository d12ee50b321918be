"""livescene frames: source index kept, sharpest frame per window, downscaled copies, errors."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from frames_testdata import FPS, HEIGHT, SHARP, WIDTH, avi_declaring, make_frames, textured_frame, write_video
from hypothesis import given
from hypothesis import strategies as st

from stages.frames import FramesConfig, WindowRule, extract_frames, sharpest_per_window
from stages.frames.cli import main


def read_table(out: Path) -> pd.DataFrame:
    return pd.read_csv(out / "frames.csv")


def test_every_frame_with_timestamps(blur_video: Path, tmp_path: Path) -> None:
    out = tmp_path / "frames"
    summary = extract_frames(FramesConfig(source=blur_video, out_dir=out, progress=False))
    table = read_table(out)
    assert list(table.columns) == ["frame", "source_index", "timestamp", "sharpness"]
    assert table["source_index"].tolist() == list(range(20))
    assert table["frame"].tolist() == [f"frame_{i:05d}.png" for i in range(20)]
    np.testing.assert_allclose(table["timestamp"], np.arange(20) / FPS, atol=1e-6)
    assert sorted(p.name for p in (out / "images").iterdir()) == table["frame"].tolist()
    # the decoded content is the source frame (mp4v is lossy, so compare loosely)
    first = cv2.imread(str(out / "images" / "frame_00003.png")).astype(float)
    assert np.abs(first - textured_frame(3)).mean() < 12
    meta = json.loads((out / "frames.json").read_text())
    assert meta["fps"] == pytest.approx(FPS)
    assert meta["source_frame_count"] == 20 and meta["decoded_frame_count"] == 20
    assert summary["n_frames"] == 20 and not meta["truncated"]


@pytest.mark.parametrize("option", [{"stride": 5}, {"count": 4}])
def test_subsampling_keeps_source_index_and_sharpest(blur_video: Path, tmp_path: Path, option: dict) -> None:
    out = tmp_path / "frames"
    summary = extract_frames(FramesConfig(source=blur_video, out_dir=out, progress=False, **option))
    table = read_table(out)
    assert table["source_index"].tolist() == sorted(SHARP)  # the one sharp frame of each window of 5
    assert table["frame"].tolist() == [f"frame_{i:05d}.png" for i in sorted(SHARP)]
    np.testing.assert_allclose(table["timestamp"], np.array(sorted(SHARP)) / FPS, atol=1e-6)
    # the streaming choice agrees with the reference rule applied to every frame's score
    rule = WindowRule.from_options(20, option.get("count"), option.get("stride"))
    assert sharpest_per_window(summary["sharpness_all"], rule) == sorted(SHARP)
    # the sharpness column is the score of the kept frame, and it beats its window
    scores = np.array(summary["sharpness_all"])
    for _, row in table.iterrows():
        i = int(row["source_index"])
        window = scores[(i // 5) * 5:(i // 5) * 5 + 5]
        assert row["sharpness"] == pytest.approx(window.max(), rel=1e-3)


def test_image_folder_with_gaps_and_downscale(tmp_path: Path) -> None:
    folder = tmp_path / "shots"
    folder.mkdir()
    indices = [10, 12, 13, 17, 20, 21, 30]
    frames = make_frames(8, {1, 4})  # sharp: index 12 (position 1) and 20 (position 4)
    for pos, i in enumerate(indices):
        cv2.imwrite(str(folder / f"IMG_{i:04d}.png"), frames[pos])
    out = tmp_path / "frames"
    assert main(["--video", str(folder), "--out", str(out), "--stride", "3", "--downscale", "2", "4",
                 "--fps", "30", "--no-progress"]) == 0
    table = read_table(out)
    # windows by playback position: [10 12 13] [17 20 21] [30]
    assert table["source_index"].tolist() == [12, 20, 30]
    assert table["frame"].tolist() == ["frame_00012.png", "frame_00020.png", "frame_00030.png"]
    np.testing.assert_allclose(table["timestamp"], [12 / 30, 20 / 30, 1.0])
    for factor in (2, 4):
        img = cv2.imread(str(out / f"images_{factor}" / "frame_00020.png"))
        assert img.shape[:2] == (round(HEIGHT / factor), round(WIDTH / factor))
    assert not (folder / "frames.csv").exists()  # the input folder is left alone


@pytest.mark.parametrize("name", ["img{}.jpg", "IMG_{}.JPG", "frame-{}.png", "DSC-{:04d}.jpg"])
def test_image_folder_numbers_are_read_from_any_name_form(tmp_path: Path, name: str) -> None:
    """``img1 .. img12`` are frames 1 .. 12 in that order (not 1, 10, 11, 12, 2, ...); macOS's ``._`` copies are
    no frames."""
    folder = tmp_path / "shots"
    folder.mkdir()
    frames = make_frames(12, set())
    for i in range(1, 13):
        cv2.imwrite(str(folder / name.format(i)), frames[i - 1])
    (folder / ("._" + name.format(1))).write_bytes(b"Mac OS X        ")  # AppleDouble metadata
    out = tmp_path / "frames"
    assert main(["--video", str(folder), "--out", str(out), "--no-progress"]) == 0
    table = read_table(out)
    assert table["source_index"].tolist() == list(range(1, 13))
    for i in (1, 2, 10, 12):  # each written frame is the photo of its number
        got = cv2.imread(str(out / "images" / f"frame_{i:05d}.png")).astype(float)
        errors = [np.abs(got - f).mean() for f in frames]
        assert int(np.argmin(errors)) == i - 1, (i, errors)
    assert not (out / "frames_dropped.csv").exists() or "._" not in (out / "frames_dropped.csv").read_text()


def test_image_folder_names_without_numbers_are_taken_in_natural_order(tmp_path: Path) -> None:
    folder = tmp_path / "shots"
    folder.mkdir()
    frames = make_frames(4, set())
    for pos, stem in enumerate(["a9", "a10", "b", "c"]):  # "a10" sorts before "a9" as text
        cv2.imwrite(str(folder / f"{stem}.png"), frames[pos])
    out = tmp_path / "frames"
    assert main(["--video", str(folder), "--out", str(out), "--no-progress"]) == 0
    assert read_table(out)["source_index"].tolist() == [0, 1, 2, 3]
    got = cv2.imread(str(out / "images" / "frame_00001.png")).astype(float)
    assert int(np.argmin([np.abs(got - f).mean() for f in frames])) == 1  # a10 second


def test_two_images_with_one_frame_number_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "shots"
    folder.mkdir()
    frames = make_frames(2, set())
    cv2.imwrite(str(folder / "IMG_1.jpg"), frames[0])
    cv2.imwrite(str(folder / "IMG_1.png"), frames[0])
    cv2.imwrite(str(folder / "IMG_2.jpg"), frames[1])
    code, err = run_cli(capsys, "--video", str(folder), "--out", str(tmp_path / "frames"))
    assert code == 2
    assert "two images carry frame number 1 (IMG_1.jpg, IMG_1.png; the number is the last" in err
    assert "fix: keep one image" in err
    assert not (tmp_path / "frames").exists()


@given(n=st.integers(1, 300), k=st.integers(1, 60), by_count=st.booleans())
def test_windows_cover_the_source_in_order(n: int, k: int, by_count: bool) -> None:
    rule = WindowRule.from_options(n, k if by_count else None, None if by_count else k)
    windows = [rule.window(p) for p in range(n)]
    assert windows[0] == 0 and windows[-1] == rule.n_windows - 1
    assert all(0 <= b - a <= 1 for a, b in itertools.pairwise(windows))  # consecutive, none empty
    assert rule.n_windows == (min(k, n) if by_count else -(-n // k))


def test_ties_keep_the_earliest_frame() -> None:
    rule = WindowRule.from_options(6, None, 3)
    assert sharpest_per_window([1.0, 5.0, 5.0, 2.0, 2.0, 1.0], rule) == [1, 3]


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    code = main([*argv, "--no-progress"])
    return code, capsys.readouterr().err


def test_missing_empty_and_garbage_videos(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(tmp_path / "nope.mp4"), "--out", str(out))
    assert code == 2 and "nope.mp4: video file not found" in err
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    code, err = run_cli(capsys, "--video", str(empty), "--out", str(out))
    assert code == 2 and "empty.mp4: the video file is empty (0 bytes)" in err and "fix:" in err
    garbage = tmp_path / "garbage.mp4"
    garbage.write_bytes(b"this is not a video" * 50)
    code, err = run_cli(capsys, "--video", str(garbage), "--out", str(out))
    assert code == 2 and "garbage.mp4: OpenCV cannot open it as a video" in err and "ffmpeg" in err
    for ext in (".jpg", ".png"):  # a photo named as a video: FFmpeg opens it as a video of one frame
        photo = tmp_path / f"photo{ext}.mp4"
        photo.write_bytes(cv2.imencode(ext, textured_frame(0))[1].tobytes())
        code, err = run_cli(capsys, "--video", str(photo), "--out", str(out))
        kind = "JPEG" if ext == ".jpg" else "PNG"
        assert code == 2 and f"photo{ext}.mp4: the file is a {kind} photo, not a video" in err and "folder" in err
    no_frames = write_video(tmp_path / "no_frames.avi", [], fourcc="MJPG")  # a valid container, zero frames
    code, err = run_cli(capsys, "--video", str(no_frames), "--out", str(out))
    assert code == 2 and "no_frames.avi: the video holds no frames" in err
    assert not out.exists()


def test_truncated_video(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # an mp4 cut short loses its index (written last) and does not open at all
    whole = write_video(tmp_path / "whole.mp4", make_frames(20, SHARP))
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    code, err = run_cli(capsys, "--video", str(cut), "--out", str(tmp_path / "a"))
    assert code == 2 and "cut.mp4" in err and "cut off before its index" in err
    assert "FFmpeg said \"[mov,mp4,m4a,3gp,3g2,mj2] moov atom not found\"" in err  # its own words, attributed
    # an MJPG avi cut short still opens and declares 20 frames, but decoding stops early
    avi = write_video(tmp_path / "whole.avi", make_frames(20, SHARP), fourcc="MJPG")
    cut_avi = tmp_path / "cut.avi"
    cut_avi.write_bytes(avi.read_bytes()[: avi.stat().st_size // 2])
    out = tmp_path / "b"
    code, err = run_cli(capsys, "--video", str(cut_avi), "--out", str(out))
    assert code == 2 and "cut.avi: decoding stopped after" in err and "of the 20 frames" in err
    assert "--accept-truncated" in err and not out.exists()
    code, err = run_cli(capsys, "--video", str(cut_avi), "--out", str(out), "--accept-truncated")
    assert code == 0
    meta = json.loads((out / "frames.json").read_text())
    assert meta["truncated"] and 0 < meta["decoded_frame_count"] < 20
    # the last frame is cut in half: FFmpeg reports it ("overread"), so it is dropped by name, not kept grey
    dropped = pd.read_csv(out / "frames_dropped.csv")
    last = meta["decoded_frame_count"] - 1
    assert dropped["source_index"].tolist() == [last] and "FFmpeg reported damaged data" in dropped["problem"][0]
    assert f"cut.avi: frame {last}" in err and "dropped" in err
    assert read_table(out)["source_index"].tolist() == list(range(last))


def test_a_raw_mjpeg_stream_is_a_video_not_a_photo(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # a camera's raw MJPEG stream (`ffmpeg -f mjpeg`): 12 JPEGs one after another, starting as a JPEG photo does
    stream = tmp_path / "cam.mjpeg"
    stream.write_bytes(b"".join(cv2.imencode(".jpg", textured_frame(k))[1].tobytes() for k in range(12)))
    out = tmp_path / "frames"
    code, err = run_cli(capsys, "--video", str(stream), "--out", str(out))
    assert code == 0 and "photo" not in err
    assert read_table(out)["source_index"].tolist() == list(range(12))


def test_a_video_holding_more_frames_than_it_declares_is_read_to_its_end(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 20 frames whose headers declare 10: the frames after the tenth were left out unsaid
    whole = write_video(tmp_path / "whole.avi", make_frames(20, SHARP), fourcc="MJPG")
    short = tmp_path / "short.avi"
    short.write_bytes(avi_declaring(whole.read_bytes(), 10))
    assert cv2.VideoCapture(str(short)).get(cv2.CAP_PROP_FRAME_COUNT) == 10
    out = tmp_path / "every"
    code, err = run_cli(capsys, "--video", str(short), "--out", str(out))
    assert code == 0 and "short.avi: the video holds 20 frames, more than the 10 its header declares" in err
    assert read_table(out)["source_index"].tolist() == list(range(20))
    meta = json.loads((out / "frames.json").read_text())
    assert (meta["source_frame_count"], meta["decoded_frame_count"], meta["truncated"]) == (10, 20, False)
    # --count cuts its windows over all 20: [0-4], [5-9], [10-14], [15-19], the sharp frame of each
    out = tmp_path / "four"
    code, err = run_cli(capsys, "--video", str(short), "--out", str(out), "--count", "4")
    assert code == 0 and read_table(out)["source_index"].tolist() == sorted(SHARP)


def test_a_damaged_frame_before_the_declared_end_is_warned_of_once(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # 20 frames declaring 10, one of them (before the tenth) cut short by an end marker in its middle: the video is
    # read twice (to its declared end, then over all 20), and the damaged frame is named once, not once a pass
    data = bytearray(write_video(tmp_path / "whole.avi", make_frames(20, SHARP), fourcc="MJPG").read_bytes())
    chunk = data.find(b"00dc", data.find(b"movi"))  # the first frame's chunk: 00dc, its size, its JPEG
    chunk = data.find(b"00dc", chunk + 1)  # the second's
    size = int.from_bytes(data[chunk + 4:chunk + 8], "little")
    data[chunk + 8 + size // 2:chunk + 10 + size // 2] = b"\xff\xd9"
    damaged = tmp_path / "damaged.avi"
    damaged.write_bytes(avi_declaring(bytes(data), 10))
    code, err = run_cli(capsys, "--video", str(damaged), "--out", str(tmp_path / "out"))
    assert code == 0 and "the video holds 20 frames, more than the 10 its header declares" in err
    assert err.count("damaged.avi: frame 1 (t=0.10 s):") == 1, err


def test_bad_options(tmp_path: Path, blur_video: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = run_cli(capsys, "--video", str(blur_video), "--out", str(tmp_path / "o"), "--count", "0")
    assert code == 2 and "--count" in err
    code, err = run_cli(capsys, "--video", str(blur_video), "--out", str(tmp_path / "o"), "--downscale", "1")
    assert code == 2 and "--downscale" in err
    for share in ("-0.1", "1.5"):
        code, err = run_cli(capsys, "--video", str(blur_video), "--out", str(tmp_path / "o"), "--max-dropped", share)
        assert code == 2 and "--max-dropped" in err and "fix:" in err
    assert not (tmp_path / "o").exists()


def test_max_side_writes_an_integer_downscale(blur_video: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "frames"
    code = main(["--video", str(blur_video), "--out", str(out), "--max-side", "40", "--downscale", "2",
                 "--no-progress"])
    assert code == 0 and "1/3 of 96x64" in capsys.readouterr().out
    meta = json.loads((out / "frames.json").read_text())
    # 96 px / 40 -> factor 3 (the smallest integer that fits), so 32x21 and masks of 96x64 map exactly
    assert (meta["downscale_factor"], meta["width"], meta["height"]) == (3, 32, 21)
    assert (meta["source_width"], meta["source_height"], meta["max_side"]) == (96, 64, 40)
    image = cv2.imread(str(out / "images" / "frame_00003.png"))
    assert image.shape[:2] == (21, 32)
    assert cv2.imread(str(out / "images_2" / "frame_00003.png")).shape[:2] == (10, 16)  # copies from the written size
    expected = cv2.resize(textured_frame(3), (32, 21),
                          interpolation=cv2.INTER_AREA)
    assert np.abs(image.astype(float) - expected).mean() < 12  # the frame itself, area-averaged
    # a limit above the size keeps it
    same = extract_frames(FramesConfig(source=blur_video, out_dir=tmp_path / "same", max_side=96, progress=False))
    assert (same["downscale_factor"], same["width"]) == (1, 96)


def test_annotated_frames_win_their_window(blur_video: Path, tmp_path: Path) -> None:
    masks = tmp_path / "masks"
    masks.mkdir()
    for i in (1, 8, 14):  # blurred frames that carry a mask annotation (SHARP is 3, 6, 12, 19)
        (masks / f"frame_{i:05d}.png").write_bytes(b"")
    (masks / "mapping.yaml").write_text("1: door\n")  # no digits: names no frame
    out = tmp_path / "frames"
    assert main(["--video", str(blur_video), "--out", str(out), "--stride", "5", "--prefer-masked", str(masks),
                 "--no-progress"]) == 0
    # windows [0-4] [5-9] [10-14] [15-19]: the annotated frame, else the sharpest
    assert read_table(out)["source_index"].tolist() == [1, 8, 14, 19]
    selection = json.loads((out / "frames.json").read_text())["selection"]
    assert (selection["preferred"], selection["preferred_kept"]) == (3, 3)
    assert main(["--video", str(blur_video), "--out", str(out), "--prefer-masked", str(tmp_path / "none"),
                 "--no-progress"]) == 2


def test_annotated_frames_of_a_coco_file_or_object_folders_win_their_window(blur_video: Path, tmp_path: Path) -> None:
    """What the labels stage reads names the frames kept first, whatever its format: a COCO file's images, one folder
    of masks per object (each naming its frames its own way), LabelMe's one file per image."""
    coco = tmp_path / "coco.json"
    coco.write_text(json.dumps({"images": [{"id": 1, "file_name": f"images/IMG_{i}.jpg"} for i in (1, 8, 14)],
                                "annotations": [], "categories": []}))
    objects = tmp_path / "objects"
    (objects / "door").mkdir(parents=True)
    (objects / "drawer").mkdir()
    for i in (1, 8):
        (objects / "door" / f"frame_{i:05d}.png").write_bytes(b"")
    (objects / "drawer" / "IMG_14.png").write_bytes(b"")
    labelme = tmp_path / "labelme"
    labelme.mkdir()
    for i in (1, 8, 14):
        (labelme / f"img{i}.json").write_text(json.dumps({"shapes": [], "imagePath": f"img{i}.jpg"}))
    for name, source in (("coco", coco), ("objects", objects), ("labelme", labelme)):
        out = tmp_path / f"frames_{name}"
        assert main(["--video", str(blur_video), "--out", str(out), "--stride", "5", "--prefer-masked",
                     str(source), "--no-progress"]) == 0
        assert read_table(out)["source_index"].tolist() == [1, 8, 14, 19], name


def _rotated_in_track_header(video: Path, out: Path) -> Path:
    """A copy of an MP4 whose track header says "display turned 90 degrees", as a phone filming upright writes it
    (the pixels stay landscape; players and OpenCV turn them)."""
    import struct

    data = bytearray(video.read_bytes())
    box = data.find(b"tkhd")
    assert box > 0 and data[box + 4] == 0  # version 0: 32-bit times
    matrix = box + 4 + 4 + 20 + 8 + 8  # version/flags, times + track id + reserved + duration, reserved, layer...
    assert struct.unpack(">9i", data[matrix:matrix + 36]) == (0x10000, 0, 0, 0, 0x10000, 0, 0, 0, 0x40000000)
    data[matrix:matrix + 36] = struct.pack(">9i", 0, 0x10000, 0, -0x10000, 0, 0, 0, 0, 0x40000000)
    out.write_bytes(bytes(data))
    return out


def test_a_portrait_phone_video_comes_out_upright(blur_video: Path, tmp_path: Path) -> None:
    """The frames are the displayed picture (turned by the track's rotation), and frames.json gives its size:
    masks drawn on the video as a player shows it, and the poses, fit the frames."""
    portrait = _rotated_in_track_header(blur_video, tmp_path / "portrait.mp4")
    out = tmp_path / "frames"
    extract_frames(FramesConfig(source=portrait, out_dir=out, progress=False))
    meta = json.loads((out / "frames.json").read_text())
    assert (meta["width"], meta["height"]) == (HEIGHT, WIDTH) and meta["rotation"] == 90
    extract_frames(FramesConfig(source=blur_video, out_dir=tmp_path / "plain", progress=False))
    assert json.loads((tmp_path / "plain" / "frames.json").read_text())["rotation"] == 0
    frame = cv2.imread(str(out / "images" / "frame_00003.png")).astype(float)
    assert frame.shape == (WIDTH, HEIGHT, 3)
    right, wrong = (np.abs(frame - cv2.rotate(textured_frame(3), turn)).mean()
                    for turn in (cv2.ROTATE_90_CLOCKWISE, cv2.ROTATE_90_COUNTERCLOCKWISE))
    assert right < 12 and wrong > 2 * right  # turned clockwise, as a player shows it (mp4v is lossy)
