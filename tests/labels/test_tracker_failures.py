"""The labels stage's warnings for the ways video object trackers fail (docs/labels-states.md, "Tracker failures"),
worked out by hand on 48 x 64 id maps of six neighbouring frames: a door and a drawer, 15 x 20 rectangles that move
1 px to the right per frame."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from labelset_writers import HEIGHT, WIDTH, write_frames

from stages.labels import LabelsConfig, ingest_labels
from stages.labels.mask_checks import between_id_edges

DOOR, DRAWER = 3, 5  # pixel values; canonical objects 1 and 2
N = 6  # frames 00000, 00002, ..., 00010 (write_frames numbers them 2 i)


def _frame(t: int, door: int | None = DOOR, drawer: int | None = DRAWER) -> np.ndarray:
    """Frame t's id map: the door at x 5+t..19+t, the drawer at x 35+t..49+t, both y 10..29 (300 pixels each); an
    object is drawn with the value given (None leaves it out)."""
    lab = np.zeros((HEIGHT, WIDTH), np.uint8)
    if door is not None:
        lab[10:30, 5 + t : 20 + t] = door
    if drawer is not None:
        lab[10:30, 35 + t : 50 + t] = drawer
    return lab


def _ingest(root: Path, maps: list[np.ndarray], capsys=None) -> tuple[dict, str]:
    folder = root / "masks"
    folder.mkdir()
    for t, lab in enumerate(maps):
        cv2.imwrite(str(folder / f"frame_{2 * t:05d}.png"), lab)
    (root / "mapping.yaml").write_text(f"{DOOR}: door\n{DRAWER}: drawer\n")
    ingest_labels(LabelsConfig(input=folder, frames=write_frames(root, N), out=root / "labels", progress=False))
    summary = json.loads((root / "labels" / "labels.json").read_text())
    return summary, "" if capsys is None else capsys.readouterr().err


def test_clean_masks_give_no_warning_and_no_key(tmp_path: Path) -> None:
    """Objects moving 1 px per frame keep 280 of their 300 pixels: nothing to say, and labels.json has no
    mask_warnings key (so clean masks write the same file as before the checks)."""
    summary, _ = _ingest(tmp_path, [_frame(t) for t in range(N)])
    assert "mask_warnings" not in summary


def test_an_identity_switch_is_named_where_it_starts_and_ends(tmp_path: Path, capsys) -> None:
    """Door and drawer ids swapped on frames 2 and 3 (00004, 00006): in 00004 the door's 300 pixels lie where the
    drawer's were in 00002 on 14 of 15 columns (280 / 300 = 0.933) and on none of the door's own; the same for the
    drawer, and again when the ids swap back in 00008."""
    maps = [_frame(t, DRAWER, DOOR) if t in (2, 3) else _frame(t) for t in range(N)]
    summary, err = _ingest(tmp_path, maps, capsys)
    found = [
        (w["kind"], w["frame"], w["previous"], w["object"], w["was"], w["share"], w["own_share"])
        for w in summary["mask_warnings"]
    ]
    assert found == [
        ("identity_switch", "00004", "00002", "door", "drawer", 0.933, 0.0),
        ("identity_switch", "00004", "00002", "drawer", "door", 0.933, 0.0),
        ("identity_switch", "00008", "00006", "door", "drawer", 0.933, 0.0),
        ("identity_switch", "00008", "00006", "drawer", "door", 0.933, 0.0),
    ]
    assert "4 warning(s) about the masks" in err
    assert "frame 00004: door's mask lies on drawer's pixels of frame 00002 (93% of it, 0% on its own)" in err


def test_one_id_on_two_objects_and_a_lost_object(tmp_path: Path) -> None:
    """The drawer's pixels take the door's id in frame 2 (00004): the door's 600 pixels lie 280 on its own pixels
    of 00002 and 280 on the drawer's (0.467, under half: no switch by itself), but the drawer vanishes from 300
    pixels, in the middle of the image; in 00006 it comes back (300 pixels) on pixels that were the door's (280 /
    300)."""
    maps = [_frame(t, DOOR, DOOR) if t == 2 else _frame(t) for t in range(N)]
    summary, _ = _ingest(tmp_path, maps)
    found = [(w["kind"], w["frame"], w["object"]) for w in summary["mask_warnings"]]
    assert found == [
        ("vanishes", "00004", "drawer"),
        ("appears", "00006", "drawer"),
        ("identity_switch", "00006", "drawer"),
    ]
    assert summary["mask_warnings"][0]["pixels_before"] == 300
    assert summary["mask_warnings"][2]["was"] == "door" and summary["mask_warnings"][2]["share"] == 0.933


def test_an_object_leaving_through_the_border_is_no_loss(tmp_path: Path) -> None:
    """The drawer slides out of the right border (x 44, 46, 48, 54, 59 of 64 columns): 300, 300, 300 pixels, then
    200 and 100, cut by the border and under its usual size (the median, 300), then none: it left, it was not lost.
    The door vanishes mid-image in 00010 after 300 pixels: lost."""
    maps = []
    for t, x in enumerate([44, 46, 48, 54, 59, None]):
        lab = _frame(t, DOOR if x is not None else None, None)
        if x is not None:
            lab[10:30, x : x + 15] = DRAWER
        maps.append(lab)
    assert [int((m == DRAWER).sum()) for m in maps] == [300, 300, 300, 200, 100, 0]
    summary, _ = _ingest(tmp_path, maps)
    found = [(w["kind"], w["frame"], w["object"], w["pixels_before"]) for w in summary["mask_warnings"]]
    assert found == [("vanishes", "00010", "door", 300)]


def test_an_object_entering_through_the_border_is_not_found_late(tmp_path: Path) -> None:
    """The reverse: nothing in 00000, then the drawer slides in from the right border (x 59, 54, 48, 46, 44): 100
    and 200 pixels cut by the border, under its usual size (300), then 300; it entered, it was not found late. The
    door appears mid-image in 00002 with 300 pixels: found late, or a ghost."""
    maps = [np.zeros((HEIGHT, WIDTH), np.uint8)]
    for t, x in enumerate([59, 54, 48, 46, 44], start=1):
        lab = _frame(t, DOOR, None)
        lab[10:30, x : x + 15] = DRAWER
        maps.append(lab)
    assert [int((m == DRAWER).sum()) for m in maps] == [0, 100, 200, 300, 300, 300]
    summary, _ = _ingest(tmp_path, maps)
    found = [(w["kind"], w["frame"], w["object"], w["pixels"]) for w in summary["mask_warnings"]]
    assert found == [("appears", "00002", "door", 300)]


def test_an_object_under_the_reliable_size_vanishes_unremarked(tmp_path: Path) -> None:
    """A door of 2 x 4 = 8 pixels in 00000-00004, gone in 00010: a quarter of its usual 8 pixels is 2, but it is
    under H*W/300 = 48 * 64 / 300 = 10.24 pixels, too small for its loss to mean anything."""
    maps = []
    for t in range(N):
        lab = _frame(t, None)
        if t < N - 1:
            lab[20:22, 10:14] = DOOR
        maps.append(lab)
    summary, _ = _ingest(tmp_path, maps)
    assert "mask_warnings" not in summary


def test_anti_aliased_edges_are_named(tmp_path: Path) -> None:
    """Ids 1 and 2: a 20 x 20 square of 2 whose edge was anti-aliased into a 1 px ring of 1 (84 pixels, each
    between a 0 and a 2 of its 3x3 window), and a 10 x 10 square of 1. Edge pixels (a window holding two values):
    the square's outer layer 76, the ring 84, the layer outside the ring 92, the small square's 36 + 44: 332."""
    lab = np.zeros((HEIGHT, WIDTH), np.uint8)
    lab[9:31, 9:31] = 1
    lab[10:30, 10:30] = 2
    lab[20:30, 45:55] = 1
    assert between_id_edges(lab) == (84, 332)
    lab[9:31, 9:31][lab[9:31, 9:31] == 1] = 0  # without the ring: no pixel between two ids
    assert between_id_edges(lab)[0] == 0


def test_an_anti_aliased_id_map_is_warned_about(tmp_path: Path, capsys) -> None:
    """The same ring in frames 00002 and 00004 of a PNG id map with ids 1 and 2: both frames are listed."""

    def ringed(t: int) -> np.ndarray:
        lab = _frame(t, 1, 2)
        if t in (1, 2):
            lab[9:31, 34 + t : 51 + t][lab[9:31, 34 + t : 51 + t] == 0] = 1  # a ring of 1 around the drawer (2)
        return lab

    folder = tmp_path / "masks"
    folder.mkdir()
    for t in range(N):
        cv2.imwrite(str(folder / f"frame_{2 * t:05d}.png"), ringed(t))
    (tmp_path / "mapping.yaml").write_text("1: door\n2: drawer\n")
    ingest_labels(LabelsConfig(input=folder, frames=write_frames(tmp_path, N), out=tmp_path / "labels", progress=False))
    warnings = json.loads((tmp_path / "labels" / "labels.json").read_text())["mask_warnings"]
    assert [(w["kind"], w["frames"]) for w in warnings] == [("anti_aliased", ["00002", "00004"])]
    assert "anti-aliased edges" in capsys.readouterr().err


def test_frames_that_are_no_neighbours_are_not_compared(tmp_path: Path) -> None:
    """Masks on every second frame only (00000, 00004, 00008; the others propagated): the swap in 00004 lies
    between annotations that are not neighbours in FRAMES, so no identity switch is claimed."""
    maps = {t: (_frame(t, DRAWER, DOOR) if t == 2 else _frame(t)) for t in range(0, N, 2)}
    folder = tmp_path / "masks"
    folder.mkdir()
    for t, lab in maps.items():
        cv2.imwrite(str(folder / f"frame_{2 * t:05d}.png"), lab)
    (tmp_path / "mapping.yaml").write_text(f"{DOOR}: door\n{DRAWER}: drawer\n")
    ingest_labels(
        LabelsConfig(
            input=folder,
            frames=write_frames(tmp_path, N),
            out=tmp_path / "labels",
            progress=False,
            missing_masks="leave",
        )
    )
    assert "mask_warnings" not in json.loads((tmp_path / "labels" / "labels.json").read_text())


def test_the_report_lists_the_warnings(tmp_path: Path) -> None:
    """The scene page's "Object masks" section names the switched frames and objects; clean masks add nothing."""
    from stages.report.inputs import ReportInputs
    from stages.report.labels_section import section_labels
    from stages.report.scene_data import SceneData

    def html(summary: dict, root: Path) -> str:
        return section_labels(
            SceneData(scene="s", plan={}, benchmarks={}, inputs=ReportInputs(labels=root / "labels"), labels=summary)
        )

    maps = [_frame(t, DRAWER, DOOR) if t in (2, 3) else _frame(t) for t in range(N)]
    (tmp_path / "a").mkdir()
    page = html(_ingest(tmp_path / "a", maps)[0], tmp_path / "a")
    assert "4 warning(s) about the masks" in page
    assert "frame 00008: drawer&#x27;s mask lies on door&#x27;s pixels of frame 00006" in page
    (tmp_path / "b").mkdir()
    assert "warning" not in html(_ingest(tmp_path / "b", [_frame(t) for t in range(N)])[0], tmp_path / "b")


def test_anti_aliased_values_that_are_no_id_are_refused_as_such(tmp_path: Path) -> None:
    """Ids 80 and 160: a square of 160 whose 1 px ring was anti-aliased to 120 (no id; each ring pixel between a 0
    and a 160 of its window) is refused as anti-aliased; with a 10 x 10 square of the unknown value 200 too, only 84 of
    the 184 pixels of unknown value lie between two values (under half): refused as ids missing from the name table."""
    from stages.labels import LabelError

    lab = np.zeros((HEIGHT, WIDTH), np.uint8)
    lab[9:31, 9:31] = 120
    lab[10:30, 10:30] = 160
    lab[35:45, 40:50] = 80
    for name, image, message in (
        ("aa", lab, r"pixel values \[120\] are no id of .*anti-aliased edges.*fix: export the id maps without"),
        (
            "id",
            np.where(lab == 80, 200, lab).astype(np.uint8),
            r"pixel values \[120, 200\] are no id of [^,]*; fix: add",
        ),
    ):
        folder = tmp_path / name / "masks"
        folder.mkdir(parents=True)
        cv2.imwrite(str(folder / "frame_00000.png"), image)
        (tmp_path / name / "mapping.yaml").write_text("80: door\n160: drawer\n")
        with pytest.raises(LabelError, match=message):
            ingest_labels(
                LabelsConfig(
                    input=folder,
                    frames=write_frames(tmp_path / name, 1),
                    out=tmp_path / name / "labels",
                    progress=False,
                )
            )
        assert not (tmp_path / name / "labels").exists()


def test_more_than_ten_unknown_values_are_listed_ten_and_counted(tmp_path: Path) -> None:
    """Twelve 4 x 4 blocks of the unknown values 100..111, apart from each other on a background of 0 (none lies
    between two values): the first ten are listed, and the two others counted."""
    from stages.labels import LabelError

    lab = np.zeros((HEIGHT, WIDTH), np.uint8)
    for k in range(12):
        lab[4:8, 5 * k : 5 * k + 4] = 100 + k
    folder = tmp_path / "masks"
    folder.mkdir()
    cv2.imwrite(str(folder / "frame_00000.png"), lab)
    (tmp_path / "mapping.yaml").write_text(f"{DOOR}: door\n{DRAWER}: drawer\n")
    with pytest.raises(LabelError, match=r"pixel values \[100, 101, 102, 103, 104, 105, 106, 107, 108, 109\] and 2 "
                                         r"more are no id of [^,]*; fix: add"):
        ingest_labels(LabelsConfig(input=folder, frames=write_frames(tmp_path, 1), out=tmp_path / "labels",
                                   progress=False))


def test_masks_numbered_from_1_are_said_to_be_one_late(tmp_path: Path, capsys) -> None:
    """Frames 0..3 and masks frame_00001..frame_00004 (frame t's mask numbered t + 1): frame_00004 matches no frame,
    and every mask's number less one is a frame, so stderr asks whether the masks were numbered from 1. Masks 0..3
    and 0..4 (one beyond the frames, but a mask numbered 0) get no such note."""
    frames = tmp_path / "frames"
    (frames / "images").mkdir(parents=True)
    rows = ["frame,source_index,timestamp,sharpness"]
    for i in range(4):
        cv2.imwrite(str(frames / "images" / f"frame_{i:05d}.png"), np.full((HEIGHT, WIDTH, 3), 40 * i, np.uint8))
        rows.append(f"frame_{i:05d}.png,{i},{0.1 * i},1.0")
    (frames / "frames.csv").write_text("\n".join(rows) + "\n")
    for name, numbers, late in (("late", range(1, 5), True), ("extra", range(0, 5), False)):
        folder = tmp_path / name / "masks"
        folder.mkdir(parents=True)
        for i in numbers:
            cv2.imwrite(str(folder / f"frame_{i:05d}.png"), _frame(i))
        (tmp_path / name / "mapping.yaml").write_text(f"{DOOR}: door\n{DRAWER}: drawer\n")
        ingest_labels(LabelsConfig(input=folder, frames=frames, out=tmp_path / name / "labels", progress=False))
        err = capsys.readouterr().err
        assert "1 label file(s) match no extracted frame" in err and "frame_00004.png" in err
        assert ("were the masks numbered from 1 while the frames start at 0?" in err) is late, name
