"""The scene page's "Frames" section: what the frames stage kept, and its warnings, which reached only the rule's log
before (hand-written frames.json contents)."""

from __future__ import annotations

import re

from stages.report.frames_section import frames_notes, section_frames


def _cells(html: str) -> dict[str, str]:
    body = html.split("<tbody>", 1)[1].split("</tbody>", 1)[0]
    return dict(re.findall(r"<tr><td[^>]*>(.*?)</td><td[^>]*>(.*?)</td></tr>", body))


CLEAN = {"source": "/somewhere/results/demo/capture/video.mp4", "source_kind": "video", "fps": 10.0,
         "source_frame_count": 80, "decoded_frame_count": 80, "truncated": False, "dropped_frame_count": 0,
         "repeated_frame_count": 0, "kept_repeats": [], "skipped_files": [], "dropped": [], "width": 256,
         "height": 192, "source_width": 256, "source_height": 192, "rotation": 0, "max_side": None,
         "downscale_factor": 1, "n_frames": 80,
         "selection": {"rule": "every frame", "preferred": 0, "preferred_kept": 0}}


def test_a_clean_video_has_its_numbers_and_no_warning():
    html = section_frames(CLEAN)
    assert _cells(html) == {
        "source": "video.mp4 (video, 10.00 fps)",  # the name only: absolute paths differ between machines
        "frames kept": "80 of 80 decoded",
        "selection": "every frame",
        "size": "256x192",
        "dropped as damaged": "0",
        "repeats of the frame before": "0",
        "blank frames kept": "0",
    }
    assert "warning" not in html
    assert frames_notes(CLEAN) == []


def test_a_phone_video_with_every_problem_names_each():
    dropped = [{"frame": f"frame_{i:05d}", "problem": "damaged"} for i in range(12)]
    frames = {**CLEAN, "source": "/data/IMG_0042.MOV", "source_frame_count": 298, "decoded_frame_count": 300,
              "dropped_frame_count": 12, "dropped": dropped, "blank_frames": ["frame_00200"],
              "repeated_frame_count": 4, "kept_repeats": ["frame_00150", "frame_00151"],
              "skipped_files": ["IMG_0043.HEIC"], "source_width": 1920, "source_height": 1080, "width": 960,
              "height": 540, "downscale_factor": 2, "max_side": 960, "rotation": 90, "n_frames": 150,
              "selection": {"rule": "sharpest of 150 equal windows", "preferred": 15, "preferred_kept": 15}}
    html = section_frames(frames)
    cells = _cells(html)
    assert cells["frames kept"] == "150 of 300 decoded"
    assert cells["size"] == ("1920x1080 -> 960x540 (shrunk by 2: frames.max_side 960), turned 90 degrees as the "
                             "video's header says")
    assert cells["selection"] == "sharpest of 150 equal windows (frames with a mask annotation first: 15 of 15 kept)"
    assert cells["blank frames kept"] == "1"
    notes = frames_notes(frames)
    assert len(notes) == 5 and "5 warning(s) from the frames stage" in html
    assert notes[0] == "The video held 300 frames where its header declares 298: every one was read."
    assert notes[1].startswith("12 damaged frame(s) left out (frames_dropped.csv): frame_00000, ")
    assert notes[1].endswith("frame_00009 ... and 2 more.")  # ten named
    assert "frame_00200" in notes[2] and "frame_00150, frame_00151" in notes[3] and "IMG_0043.HEIC" in notes[4]


def test_a_truncated_video_says_so_and_a_ready_dataset_says_why_there_is_no_section():
    notes = frames_notes({**CLEAN, "truncated": True, "decoded_frame_count": 61})
    assert notes == ["The video ended after 61 of the 80 frames its header declares (--accept-truncated kept them)."]
    html = section_frames(None, "rule frames skipped for this scene: the dataset carries its frames")
    assert "rule frames skipped for this scene" in html and "<table" not in html


def test_a_photo_folder_names_its_dropped_photos_by_their_file_names():
    dropped = [{"frame": "frame_00012", "source_file": "/data/shots/IMG_0012.JPG", "problem": "truncated JPEG"}]
    photos = {**CLEAN, "source_kind": "images", "dropped": dropped, "dropped_frame_count": 1}
    assert frames_notes(photos) == ["1 damaged frame(s) left out (frames_dropped.csv): IMG_0012.JPG."]
    video = {**photos, "source_kind": "video"}  # one file for every frame: the frame names it
    assert frames_notes(video) == ["1 damaged frame(s) left out (frames_dropped.csv): frame_00012."]


def test_names_are_escaped():
    html = section_frames({**CLEAN, "skipped_files": ["<b>x</b>.heic"]})
    assert "&lt;b&gt;x&lt;/b&gt;.heic" in html and "<b>x</b>" not in html
