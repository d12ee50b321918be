"""Which frame a window keeps, how frames are named, which names are refused: rules stated in the code's own
docstrings (docs/poses.md), each checked on a case small enough to work out by hand."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import cv2
import pandas as pd
import pytest
from frames_testdata import blurred, textured_frame

from stages.frames import FramesConfig, FrameSourceError, extract_frames
from stages.frames.extraction import name_width
from stages.frames.selection import indices_named_in


def _folder(root: Path, images: dict[str, object]) -> Path:
    folder = root / "shots"
    folder.mkdir()
    for name, image in images.items():
        assert cv2.imwrite(str(folder / name), image)
    return folder


def _kept(folder: Path, out: Path, **options) -> list[int]:
    extract_frames(FramesConfig(source=folder, out_dir=out, progress=False, **options))
    return pd.read_csv(out / "frames.csv")["source_index"].tolist()


def test_a_tie_in_a_window_keeps_the_earliest_frame(tmp_path: Path) -> None:
    """Frames 0 and 2 are the same picture (lossless PNG: the same pixels, the same score), frame 1 a blur between
    them, so neither copy is a repeat of the frame before it: the window of 3 keeps the earliest, as
    ``sharpest_per_window`` does."""
    sharp = textured_frame(0)
    folder = _folder(tmp_path, {"frame_0000.png": sharp, "frame_0001.png": blurred(textured_frame(1), 2.0),
                                "frame_0002.png": sharp})
    assert _kept(folder, tmp_path / "frames", stride=3) == [0]


def test_an_annotated_frame_is_matched_by_its_source_index_in_a_folder_with_gaps(tmp_path: Path) -> None:
    """IMG_0010, IMG_0012, IMG_0013: source indices 10, 12, 13 at playback positions 0, 1, 2. The annotation names
    frame 13 (blurred): the window keeps 13, not the sharper 10 or 12."""
    folder = _folder(tmp_path, {"IMG_0010.png": textured_frame(0), "IMG_0012.png": textured_frame(1),
                                "IMG_0013.png": blurred(textured_frame(2), 2.0)})
    assert _kept(folder, tmp_path / "frames", stride=3, prefer=frozenset({13})) == [13]
    # an index that is a playback position here (2) but names no frame of the folder changes nothing
    assert _kept(folder, tmp_path / "other", stride=3, prefer=frozenset({2})) != [13]


def test_masks_in_a_masks_subfolder_name_their_frames(tmp_path: Path) -> None:
    """``--prefer-masked`` reads what the labels stage reads, a ``masks/`` subfolder included."""
    annotations = tmp_path / "annotations"
    (annotations / "masks").mkdir(parents=True)
    (annotations / "mapping.yaml").write_text("1: door\n")
    for name in ("frame_00012.png", "frame_00040.png", ".frame_00099.png"):  # hidden: no frame
        (annotations / "masks" / name).write_bytes(b"")
    assert indices_named_in(annotations) == {12, 40}


@pytest.mark.parametrize(("n_frames", "width"), [(99_999, 5), (100_000, 5), (100_001, 6)])
def test_a_video_names_its_frames_by_the_digits_of_its_largest_index(n_frames: int, width: int) -> None:
    """A video of 100 000 frames has indices 0 .. 99 999: five digits are enough; one more frame needs six."""
    assert name_width(SimpleNamespace(n_declared=n_frames)) == width


@pytest.mark.parametrize("names", [["take1_0002.jpg", "take2_0001.jpg"],  # numbers one apart
                                   ["Take1_0005.jpg", "take2_0001.jpg"]])  # one name form, spelled in two cases
def test_numbers_against_the_name_order_are_refused(tmp_path: Path, names: list[str]) -> None:
    folder = _folder(tmp_path, {name: textured_frame(k) for k, name in enumerate(names)})
    with pytest.raises(FrameSourceError, match=rf"{names[1]} comes after {names[0]} by name but carries the smaller "
                                               r"frame number"):
        extract_frames(FramesConfig(source=folder, out_dir=tmp_path / "frames", progress=False))
    assert not (tmp_path / "frames").exists()


def test_a_single_labelme_file_names_its_image(tmp_path: Path) -> None:
    """LabelMe's file names the image it annotates (imagePath); its own name may carry no number."""
    path = tmp_path / "annotation.json"
    path.write_text('{"shapes": [], "imagePath": "../rgb/IMG_14.jpg", "imageHeight": 4, "imageWidth": 6}')
    assert indices_named_in(path) == {14}


def test_a_frame_after_a_damaged_one_is_no_repeat(tmp_path: Path) -> None:
    """A, (damaged), A: a repeat is a frame identical to the frame before it, and the frame before the second A
    is the damaged one."""
    folder = _folder(tmp_path, {"frame_0000.png": textured_frame(0), "frame_0002.png": textured_frame(0)})
    (folder / "frame_0001.png").write_bytes(b"")
    summary = extract_frames(FramesConfig(source=folder, out_dir=tmp_path / "frames", progress=False))
    assert summary["dropped_frame_count"] == 1 and summary["repeated_frame_count"] == 0
    assert summary["kept_repeats"] == []


def test_a_repeat_is_the_frame_before_to_the_last_pixel(tmp_path: Path) -> None:
    """A, A, A' (A with its last pixel changed), A: only the second A repeats the frame before it; the frame before
    the last A is A', and one changed pixel makes a new picture."""
    a = textured_frame(0)
    changed = a.copy()
    changed[-1, -1] = 255 - changed[-1, -1]
    folder = _folder(tmp_path, {"frame_0000.png": a, "frame_0001.png": a, "frame_0002.png": changed,
                                "frame_0003.png": a})
    summary = extract_frames(FramesConfig(source=folder, out_dir=tmp_path / "frames", progress=False))
    assert summary["repeated_frame_count"] == 1 and summary["kept_repeats"] == ["frame_00001.png"]


@pytest.mark.parametrize(("odd", "said", "fix"), [
    ((48, 64), "it is turned by 90 degrees against them", "turn it back to 64x48"),
    ((96, 72), r"\(a resized copy\?\)", "resize it to 64x48 if it is a scaled copy"),
    ((96, 128), "it is turned by 90 degrees against them and of another scale", "turn it and resize it to 64x48"),
    ((64, 64), r"\(another camera, or a crop\)", "leave it out of the folder"),
])
def test_a_photo_of_another_size_is_refused_with_the_likely_cause(tmp_path: Path, odd, said, fix) -> None:
    """The folder's first photo is 64x48 (width x height); the second is turned, scaled or of another shape."""
    first = textured_frame(0)[:48, :64]
    w, h = odd
    second = cv2.resize(textured_frame(1), (w, h))
    folder = _folder(tmp_path, {"IMG_0001.png": first, "IMG_0002.png": second})
    with pytest.raises(FrameSourceError, match=rf"the image is {w}x{h} but earlier frames are 64x48.*{said}") as err:
        extract_frames(FramesConfig(source=folder, out_dir=tmp_path / "frames", progress=False))
    assert fix in err.value.fix and err.value.path.name == "IMG_0002.png"
    assert not (tmp_path / "frames").exists()


@pytest.mark.parametrize(("odd", "fix"), [
    ((48, 64), "if the folder's first photo IMG_0001.png is the one held the other way, turn that one to 64x48"),
    ((96, 72), "if the folder's first photo IMG_0001.png is the odd one, resize that one to 64x48"),
    ((64, 64), "if the folder's first photo IMG_0001.png is the odd one, leave that one out"),
])
def test_a_first_photo_of_another_size_is_named_as_the_possible_odd_one(tmp_path: Path, odd, fix) -> None:
    """The folder's first photo is the odd one (w x h = ODD) among three of 64x48: the refusal comes at the second
    photo, after one frame only, so the fix names the first as what may be wrong, not only the second."""
    w, h = odd
    photos = {"IMG_0001.png": cv2.resize(textured_frame(0), (w, h))}
    photos |= {f"IMG_000{i}.png": textured_frame(i)[:48, :64] for i in (2, 3, 4)}
    with pytest.raises(FrameSourceError, match=rf"the image is 64x48 but earlier frames are {w}x{h}") as err:
        extract_frames(FramesConfig(source=_folder(tmp_path, photos), out_dir=tmp_path / "frames", progress=False))
    assert err.value.path.name == "IMG_0002.png" and fix in err.value.fix
    # from the third photo on, two earlier frames agree: the one read now is the odd one, and only it is named
    photos = {f"IMG_000{i}.png": textured_frame(i)[:48, :64] for i in (1, 2)} | {"IMG_0003.png": photos["IMG_0001.png"]}
    (tmp_path / "b").mkdir()
    with pytest.raises(FrameSourceError) as err:
        extract_frames(FramesConfig(source=_folder(tmp_path / "b", photos), out_dir=tmp_path / "f", progress=False))
    assert err.value.path.name == "IMG_0003.png" and "first photo" not in err.value.fix
