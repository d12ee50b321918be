"""Pair the frames of two pose files of the same capture, however each side named its images.

The frames stage writes ``images/frame_00012.png``; a reference made elsewhere may
call the same image ``0012.jpg``, ``IMG_0012.JPG`` or ``cam0/0012.jpg`` (a COLMAP
image name), or carry no file name at all. Three name keys are tried and the
one that pairs the most frames wins (docs/poses.md, "livescene poses compare"):

- ``frame id``: the last ``_`` token of the stem, as a number when it is one
  (``0001`` = ``frame_00001`` = ``00001``); a frame without a file name but
  with a ``source_index`` uses that number;
- ``image stem``: the whole stem, case-insensitive;
- ``image path``: the path without suffix, below any leading ``.``/``..``/``images*``
  folder (tells ``cam0/0001`` from ``cam1/0001``).

A key that two frames of one side share pairs neither of them. Pairing by
position (``order``) is never guessed: it needs ``--match order``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePosixPath

from stages.scene import InputError, frame_id_of

from .pose_sources import PoseEntry, PoseSet

MIN_MATCHED = 3
"""A similarity needs three cameras."""
MATCH_MODES = ("id", "order")
SHOWN_LABELS = 5
"""How many frame names of each side an error message shows."""


def _frame_id_key(entry: PoseEntry) -> str | None:
    if entry.file_path:
        fid = frame_id_of(PurePosixPath(entry.file_path.replace("\\", "/")).stem)
        return str(int(fid)) if fid.isdigit() else fid.lower()
    return str(entry.source_index) if entry.source_index is not None else None


def _stem_key(entry: PoseEntry) -> str | None:
    return PurePosixPath(entry.file_path.replace("\\", "/")).stem.lower() if entry.file_path else None


def _path_key(entry: PoseEntry) -> str | None:
    if not entry.file_path:
        return None
    parts = list(PurePosixPath(entry.file_path.replace("\\", "/")).with_suffix("").parts)
    while len(parts) > 1 and (parts[0] in (".", "..", "/") or parts[0].lower().startswith("images")):
        parts.pop(0)
    return "/".join(parts).lower()


KEYS: dict[str, Callable[[PoseEntry], str | None]] = {
    "frame id": _frame_id_key, "image stem": _stem_key, "image path": _path_key}
"""Name keys in order of preference (a tie goes to the earlier one)."""


@dataclass
class FrameMatch:
    """Which frame of the prediction goes with which frame of the reference."""

    pairs: list[tuple[PoseEntry, PoseEntry]]
    """(prediction, reference) in reference order."""
    matched_by: str
    """The key that paired them (``frame id``, ``image stem``, ``image path``) or ``order``."""
    unmatched_truth: list[PoseEntry]
    """Reference frames without a partner."""
    counts: dict[str, int]
    """Frames each key would pair (the error message shows them)."""


def _unique_keys(entries: list[PoseEntry], key: Callable[[PoseEntry], str | None]) -> dict[str, PoseEntry]:
    keys = [(key(e), e) for e in entries]
    seen = Counter(k for k, _ in keys if k is not None)
    return {k: e for k, e in keys if k is not None and seen[k] == 1}


def _shown(entries: list[PoseEntry]) -> str:
    labels = [e.label for e in entries[:SHOWN_LABELS]]
    more = ", ..." if len(entries) > SHOWN_LABELS else ""
    return f"{', '.join(labels)}{more} ({len(entries)} frames)"


def _time_order(entries: list[PoseEntry]) -> list[PoseEntry]:
    """Numeric frame id order when every frame has one, else the order of the file."""
    ids = [_frame_id_key(e) for e in entries]
    if all(i is not None and i.isdigit() for i in ids):
        return [e for _, e in sorted(zip((int(i) for i in ids), entries, strict=True), key=lambda t: t[0])]  # type: ignore[arg-type]
    return list(entries)


def match_frames(pred: PoseSet, truth: PoseSet, mode: str = "id") -> FrameMatch:
    """Pair frames by the best name key (``id``) or by position in time order (``order``)."""
    if mode == "order":
        return _match_by_order(pred, truth)
    if mode != "id":
        raise ValueError(f"unknown match mode {mode!r}; use one of {MATCH_MODES}")
    counts: dict[str, int] = {}
    best: tuple[str, dict[str, PoseEntry], dict[str, PoseEntry]] | None = None
    for name, key in KEYS.items():
        p, t = _unique_keys(pred.entries, key), _unique_keys(truth.entries, key)
        counts[name] = len(p.keys() & t.keys())
        if best is None or counts[name] > counts[best[0]]:
            best = (name, p, t)
    assert best is not None
    name, p, t = best
    if counts[name] < MIN_MATCHED:
        raise InputError(pred.path, _no_match_problem(pred, truth, counts), _no_match_fix(pred, truth))
    pairs = [(p[k], e) for k, e in t.items() if k in p]
    pairs.sort(key=lambda pair: pair[1].position)
    matched = {id(e) for _, e in pairs}
    return FrameMatch(pairs=pairs, matched_by=name, counts=counts,
                      unmatched_truth=[e for e in truth.entries if id(e) not in matched])


def _no_match_problem(pred: PoseSet, truth: PoseSet, counts: dict[str, int]) -> str:
    tried = ", ".join(f"{n}: {c}" for n, c in counts.items())
    problem = (f"only {max(counts.values())} frames match the reference {truth.path} by name ({tried}); "
               f"frames seen in the prediction: {_shown(pred.entries)}; in the reference: {_shown(truth.entries)}")
    for side, poses in (("prediction", pred), ("reference", truth)):
        if not any(e.file_path for e in poses.entries):
            problem += f"; the {side}'s frames carry no file_path, so they have no name to match"
    return problem


def _no_match_fix(pred: PoseSet, truth: PoseSet) -> str:
    same_count = len(pred.entries) == len(truth.entries)
    return ("compare poses of the same capture (frames are matched by the number in their names, their stems or "
            "their COLMAP image names)" + (", or pass --match order if both files list the same frames in the "
                                           "same order" if same_count else
                                           f"; --match order needs both files to list the same frames "
                                           f"({len(pred.entries)} vs {len(truth.entries)} here)"))


def _match_by_order(pred: PoseSet, truth: PoseSet) -> FrameMatch:
    if len(pred.entries) != len(truth.entries):
        raise InputError(pred.path, f"--match order pairs frames by position, but the prediction has "
                                    f"{len(pred.entries)} frames and the reference {truth.path} has "
                                    f"{len(truth.entries)}",
                         "pass files that list the same frames (a prediction that lost unregistered frames "
                         "can only be matched by name: give both sides file names)")
    p, t = _time_order(pred.entries), _time_order(truth.entries)
    if len(p) < MIN_MATCHED:
        raise InputError(pred.path, f"only {len(p)} frames to pair", "compare at least 3 posed frames")
    return FrameMatch(pairs=list(zip(p, t, strict=True)), matched_by="order", unmatched_truth=[],
                      counts={"order": len(p)})
