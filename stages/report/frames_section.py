"""The scene page's "Frames" section: what the frames stage kept of the video or photo folder, and what it warned of.

Reads frames.json (docs/poses.md, "`livescene frames`"). Its warnings (damaged frames dropped, repeats, blank
frames, files that are no images, a header that miscounts) went to stderr, which a workflow keeps in the rule's
log: here they are where a user looks.
"""

from __future__ import annotations

from html import escape
from pathlib import Path

from .html_parts import fmt, missing, note_list, table

LISTED = 10
"""Frames or files named in a row before '... and N more'."""


def _names(items: list) -> str:
    names = [str(i) for i in items]
    more = f" ... and {len(names) - LISTED} more" if len(names) > LISTED else ""
    return escape(", ".join(names[:LISTED]) + more)


def _plain(value: object) -> str:
    """A pixel count as written (fmt would group 1920 as 1,920)."""
    return "–" if value is None else escape(str(value))


def _size(width: object, height: object) -> str:
    return f"{_plain(width)}x{_plain(height)}"


def frames_notes(frames: dict) -> list[str]:
    """One sentence per thing the frames stage warned of, in the order a user would fix them."""
    notes = []
    declared, decoded = frames.get("source_frame_count"), frames.get("decoded_frame_count")
    if frames.get("truncated"):
        notes.append(f"The video ended after {decoded} of the {declared} frames its header declares "
                     "(--accept-truncated kept them).")
    elif isinstance(declared, int) and isinstance(decoded, int) and decoded > declared:
        notes.append(f"The video held {decoded} frames where its header declares {declared}: every one was read.")
    dropped = frames.get("dropped") or []
    if dropped:
        # a photo folder's dropped frames by the user's file names; a video's by frame (one file for all)
        names = [Path(str(d.get("source_file"))).name if frames.get("source_kind") == "images" and d.get("source_file")
                 else d.get("frame") for d in dropped]
        notes.append(f"{len(dropped)} damaged frame(s) left out (frames_dropped.csv): {_names(names)}.")
    blank = frames.get("blank_frames") or []
    if blank:
        notes.append(f"{len(blank)} kept frame(s) of almost one grey level (a lens cover, a plain surface filling the "
                     f"view), which COLMAP cannot register: {_names(blank)}.")
    repeats = frames.get("kept_repeats") or []
    if repeats:
        notes.append(f"{len(repeats)} kept frame(s) repeat the frame before them (a phone that stalls): "
                     f"{_names(repeats)}.")
    skipped = frames.get("skipped_files") or []
    if skipped:
        notes.append(f"{len(skipped)} file(s) of the folder are not images this stage reads and were left out: "
                     f"{_names(skipped)}.")
    return notes


def section_frames(frames: dict | None, skipped: str = "the frames rule did not run for this scene") -> str:
    """HTML of the section; ``skipped`` says why when there is no frames.json (a ready dataset)."""
    if frames is None:
        return missing(skipped)
    selection = frames.get("selection") or {}
    rule = str(selection.get("rule", "–"))
    if selection.get("preferred"):
        rule += f" (frames with a mask annotation first: {selection.get('preferred_kept')} of " \
                f"{selection.get('preferred')} kept)"
    size = _size(frames.get("source_width"), frames.get("source_height"))
    if frames.get("downscale_factor", 1) != 1:
        size += (f" -> {_size(frames.get('width'), frames.get('height'))} (shrunk by "
                 f"{frames.get('downscale_factor')}: frames.max_side {_plain(frames.get('max_side'))})")
    if frames.get("rotation"):
        size += f", turned {frames.get('rotation')} degrees as the video's header says"
    rows = [["source", f"{escape(Path(str(frames.get('source', '?'))).name)} ({escape(str(frames.get('source_kind')))}"
                       f", {fmt(frames.get('fps'), 2)} fps)"],
            ["frames kept", f"{fmt(frames.get('n_frames'))} of {fmt(frames.get('decoded_frame_count'))} decoded"],
            ["selection", escape(rule)],
            ["size", size],
            ["dropped as damaged", fmt(frames.get("dropped_frame_count"))],
            ["repeats of the frame before", fmt(frames.get("repeated_frame_count"))],
            ["blank frames kept", fmt(len(frames.get("blank_frames") or []))]]
    html = table(["frames", "value"], rows)
    notes = frames_notes(frames)
    if notes:
        html += note_list(f"{len(notes)} warning(s) from the frames stage (frames.json):", notes)
    return html
