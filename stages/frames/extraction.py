"""The frames stage end to end: source -> sharpest frame per window -> FRAMES folder."""

from __future__ import annotations

import math
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from tqdm import tqdm

from stages.scene import atomic_dir, write_json

from .config import FramesConfig
from .errors import FrameSourceError
from .frame_source import (
    CONVERT_FIX,
    IMAGE_SUFFIXES,
    RECOPY_FIX,
    REENCODE,
    REENCODE_FIX,
    DroppedFrame,
    ImageFolderSource,
    SourceFrame,
    VideoSource,
    open_source,
    skipped_summary,
)
from .selection import WindowRule, downscale_factor, scaled_size
from .sharpness import laplacian_variance

STAGE_VERSION = "2"
DROPPED_CSV = "frames_dropped.csv"
"""Frames left out as damaged, one row each (frames.csv lists only the frames written to images/)."""
DROPPED_COLUMNS = ["frame", "source_index", "timestamp", "source_file", "problem"]


def frame_name(source_index: int, width: int = 5) -> str:
    """File name of an extracted frame: the contract's ``frame_{source index:05d}.png``, padded wider when a source
    has more frames, so that names sort in frame order (COLMAP's sequential matching pairs images by name)."""
    return f"frame_{source_index:0{width}d}.png"


def name_width(source: VideoSource | ImageFolderSource) -> int:
    """Digits of the source's largest index, at least 5: one width for every frame name of the source."""
    largest = max(source.indices) if isinstance(source, ImageFolderSource) else source.n_declared - 1
    return max(5, len(str(largest)))


def _write_png(path: Path, image: np.ndarray) -> None:
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")


def _warn(message: str) -> None:
    tqdm.write(f"warning: {message}", file=sys.stderr)


def _label(source: VideoSource | ImageFolderSource, frame: DroppedFrame) -> str:
    """How a dropped frame is named inside a message about the whole source."""
    return frame.source_file.name if frame.source_file != source.path else f"frame {frame.source_index}"


def _refusal(source: VideoSource | ImageFolderSource, dropped: list[DroppedFrame], n_read: int, n_total: int,
             cfg: FramesConfig, none_left: bool) -> FrameSourceError:
    """The error for a source with too many damaged frames (or none whole), naming them."""
    unit = "images" if source.kind == "images" else "video frames"
    shown = "; ".join(f"{_label(source, d)}: {d.problem}" for d in dropped[:5])
    more = f"; and {len(dropped) - 5} more" if len(dropped) > 5 else ""
    checked = "" if n_read >= n_total else f" (stopped after checking {n_read})"
    if none_left:
        problem = f"none of the {n_read} {unit} read is whole, all {len(dropped)} are damaged: {shown}{more}"
    else:
        problem = (f"{len(dropped)} of the {n_total} {unit} are damaged{checked}, more than the "
                   f"{cfg.max_dropped:.0%} that --max-dropped allows: {shown}{more}")
    fix = RECOPY_FIX if source.kind == "images" else REENCODE_FIX
    if not none_left:
        fix += f"; or raise --max-dropped (now {cfg.max_dropped:g}) to go on with the whole ones"
    path = dropped[0].source_file if len(dropped) == 1 else source.path
    return FrameSourceError(path, problem, fix)


@dataclass
class _Selection:
    """What one pass over the source kept."""

    rows: list[dict[str, Any]] = field(default_factory=list)
    dropped: list[DroppedFrame] = field(default_factory=list)
    sharpness: list[float | None] = field(default_factory=list)
    size: tuple[int, int] | None = None
    n_read: int = 0
    repeats: int = 0
    """Frames identical to the frame before them in the source."""
    last_whole: int = -1
    """Position of the last frame that decoded whole."""
    blank: list[str] = field(default_factory=list)
    """Kept frames of (almost) one grey level: a lens cover, a blank screen, a plain wall filling the view."""
    overran: bool = False
    """The source held a frame past the windows' end (a video holding more frames than its header declares)."""


BLANK_STD = 2.0
"""Standard deviation of a kept frame's grey levels (0-255) below which it is called blank: a lens cover or a black
screen, sensor noise and codec included, stays near 1; a room's view, even a dark one, has tens."""


def _select(source: VideoSource | ImageFolderSource, rule: WindowRule, cfg: FramesConfig,
            image_dirs: dict[int, Path], width: int, warn_from: float = 0) -> _Selection:
    """One streaming pass: every source frame decoded once and scored; the best frame of the current window held
    in memory until the window closes, then written (the folders are emptied first: a pass may be repeated, then
    warning only of the frames from position ``warn_from`` on: the others' warnings were given)."""
    for d in image_dirs.values():
        if d.exists():
            shutil.rmtree(d)
        d.mkdir()
    picked = _Selection()
    allowed = math.floor(cfg.max_dropped * rule.n_total + 1e-9)

    def shrink(image: np.ndarray, factor: int) -> np.ndarray:
        return cv2.resize(image, scaled_size(image.shape[1], image.shape[0], factor), interpolation=cv2.INTER_AREA)

    def keep(frame: SourceFrame, rank: tuple[bool, bool, float]) -> None:
        _, fresh, score = rank  # (preferred, not a repeat, sharpness)
        name = frame_name(frame.source_index, width)
        factor = downscale_factor(frame.image.shape[1], frame.image.shape[0], cfg.max_side)
        image = shrink(frame.image, factor) if factor > 1 else frame.image
        _write_png(image_dirs[1] / name, image)
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        if float(cv2.meanStdDev(grey)[1][0, 0]) < BLANK_STD:
            picked.blank.append(name)
        for f in cfg.downscale:
            _write_png(image_dirs[f] / name, shrink(image, f))
        # timestamps rounded to the nanosecond: index / fps leaves float noise (0.30000000000000004)
        stamp = round(frame.timestamp, 9) if math.isfinite(frame.timestamp) else frame.timestamp
        picked.rows.append({"frame": name, "source_index": frame.source_index, "timestamp": stamp,
                            "sharpness": score, "repeat": not fresh})

    best: tuple[int, tuple[bool, bool, float], SourceFrame] | None = None  # (window, rank, frame)
    # the frame before, to tell a repeated frame: compared pixel for pixel, which stops at the first difference
    # (a hash of every frame cost 50 ms a 4K frame)
    previous: np.ndarray | None = None
    with tqdm(total=rule.n_total, desc="frames", unit="frame", disable=not cfg.progress) as bar:
        for frame in source:
            if frame.position >= rule.n_total:  # more frames than the container declared (or a replanned pass)
                picked.overran = True
                break
            warn = frame.position >= warn_from
            picked.n_read += 1
            bar.update()
            if isinstance(frame, DroppedFrame):
                picked.dropped.append(frame)
                picked.sharpness.append(None)
                previous = None
                if warn:
                    _warn(f"{frame.where()}: {frame.problem}; dropped (listed in {DROPPED_CSV})")
                if len(picked.dropped) > allowed:
                    raise _refusal(source, picked.dropped, picked.n_read, rule.n_total, cfg, none_left=False)
                continue
            if frame.remarks and warn:
                _warn(f"{frame.where}: the decoder printed {' | '.join(frame.remarks[:3])!r}; kept")
            picked.last_whole = frame.position
            score = laplacian_variance(frame.image)
            repeat = previous is not None and np.array_equal(frame.image, previous)
            previous = frame.image
            picked.repeats += repeat
            picked.sharpness.append(score)
            picked.size = (frame.image.shape[1], frame.image.shape[0])
            window = rule.window(frame.position)
            if best is not None and window != best[0]:
                keep(best[2], best[1])
                best = None
            # a frame with a mask annotation wins its window (the labels stage needs it), then a frame that is not
            # a copy of the one before (a stalled phone's), then the sharpest
            rank = (frame.source_index in cfg.prefer, not repeat, score)
            if best is None or rank > best[1]:
                best = (window, rank, frame)
    if best is not None:
        keep(best[2], best[1])
    return picked


def extract_frames(cfg: FramesConfig) -> dict[str, Any]:
    """Write ``cfg.out_dir`` atomically and return the content of frames.json.

    One streaming pass: every source frame is decoded once and scored; the
    best frame of the current window is held in memory until the window
    closes (and the frame before is kept to tell a repeat), so memory stays
    at three frames whatever the video length.

    A damaged frame (truncated or corrupt image file, video frame FFmpeg
    reports damaged or cannot decode) is left out with a warning naming it
    and listed in frames_dropped.csv and frames.json; more than
    ``cfg.max_dropped`` of the source damaged, or no whole frame at all, is
    an error naming them.
    """
    t_start = time.perf_counter()
    source = open_source(cfg.source, cfg.fps)
    rule = WindowRule.from_options(source.n_declared, cfg.count, cfg.stride)
    if source.remarks:
        _warn(f"{source.path}: FFmpeg printed while opening it (or counting its frames): "
              f"{' | '.join(source.remarks[:3])}")
    skipped = getattr(source, "skipped", [])
    if skipped:
        _warn(f"{source.path}: left out {skipped_summary(skipped)}, which are not images this stage reads "
              f"({', '.join(IMAGE_SUFFIXES)}); {CONVERT_FIX}")
    width = name_width(source)
    # the source's length as declared (counted when a video holds more; a truncated video's windows are cut again)
    n_total = rule.n_total

    with atomic_dir(cfg.out_dir, "frames", inputs=[cfg.source], legacy=["frames.json"]) as out:
        image_dirs = {1: out / "images", **{f: out / f"images_{f}" for f in cfg.downscale}}
        picked = _select(source, rule, cfg, image_dirs, width)
        if picked.overran and isinstance(source, VideoSource):
            # the header declares fewer frames than the video holds (its length estimated from a duration and a
            # frame rate, or written wrong): count them and cut the windows again over all of them, rather than
            # leave the rest of the video out unsaid
            n_total = max(source.count_frames(), n_total + 1)
            _warn(f"{source.path}: the video holds {n_total} frames, more than the {source.n_declared} its header "
                  f"declares; choosing the frames again over all {n_total}")
            rule = WindowRule.from_options(n_total, cfg.count, cfg.stride)
            width = max(width, len(str(n_total - 1)))
            picked = _select(source, rule, cfg, image_dirs, width, warn_from=source.n_declared)
        whole = picked.last_whole + 1
        if picked.n_read < n_total and cfg.accept_truncated and cfg.count is not None \
                and len(picked.rows) < min(cfg.count, whole):
            # the windows were cut over the declared length: cut them again up to the last whole frame (the second
            # pass stops there; what the first one read after it, and its warnings, stand)
            _warn(f"{source.path}: the video ends after {picked.n_read} of the {n_total} frames it declares; "
                  f"choosing the {cfg.count} frames again over the first {whole}")
            rule = WindowRule.from_options(whole, cfg.count, None, of_declared=n_total)
            first = picked
            picked = _select(source, rule, cfg, image_dirs, width, warn_from=math.inf)
            picked.dropped += [d for d in first.dropped if d.position >= whole]
            picked.sharpness, picked.n_read = first.sharpness, first.n_read
        rows, dropped, all_sharpness, size, n_read = (picked.rows, picked.dropped, picked.sharpness, picked.size,
                                                      picked.n_read)
        kept_repeats = [r["frame"] for r in rows if r.pop("repeat")]
        if picked.blank:
            shown = ", ".join(picked.blank[:4]) + (", ..." if len(picked.blank) > 4 else "")
            _warn(f"{source.path}: {len(picked.blank)} kept frame(s) hold almost one grey level ({shown}): a lens "
                  "cover, a blank screen or a plain surface filling the view; COLMAP cannot register them (cut them "
                  "from the video, or film some texture)")
        if picked.repeats:
            _warn(f"{source.path}: {picked.repeats} frames repeat the frame before them exactly (a phone that "
                  "stalled, or a still start or end); a window keeps such a frame only when it has no other"
                  + (f" ({len(kept_repeats)} kept: {', '.join(kept_repeats[:4])}"
                     f"{', ...' if len(kept_repeats) > 4 else ''})" if kept_repeats else ""))
        if n_read == 0:
            codec = getattr(source, "codec", "")
            raise FrameSourceError(source.path, "no frame could be decoded" + (
                f" (codec '{codec}': this OpenCV build may have no decoder for it)" if codec else ""),
                REENCODE if codec else REENCODE_FIX)
        if not rows:
            raise _refusal(source, dropped, n_read, rule.n_total, cfg, none_left=True)
        if n_read < n_total and not cfg.accept_truncated:
            raise FrameSourceError(
                source.path,
                f"decoding stopped after {n_read} of the {n_total} frames the video declares "
                f"(truncated or corrupt from frame {n_read} on)",
                REENCODE_FIX + f", or pass --accept-truncated to keep what the first {n_read} frames give")

        factor = downscale_factor(*size, cfg.max_side) if size else 1
        written = scaled_size(*size, factor) if size else None
        table = pd.DataFrame(rows, columns=["frame", "source_index", "timestamp", "sharpness"])
        table.to_csv(out / "frames.csv", index=False)
        dropped_rows = [{"frame": frame_name(d.source_index, width), "source_index": d.source_index,
                         "timestamp": d.timestamp, "source_file": str(d.source_file), "problem": d.problem}
                        for d in dropped]
        pd.DataFrame(dropped_rows, columns=DROPPED_COLUMNS).to_csv(out / DROPPED_CSV, index=False)
        summary = {
            "stage": "frames",
            "stage_version": STAGE_VERSION,
            "source": str(Path(cfg.source).resolve()),
            "source_kind": source.kind,
            "fps": None if math.isnan(source.fps) else source.fps,
            "source_frame_count": source.n_declared,
            # an image folder's frames are the numbers in its names (IMG_4501 ...), not 0..count-1 as a video's
            "source_indices": list(source.indices) if source.kind == "images" else None,
            "decoded_frame_count": n_read,
            "truncated": n_read < n_total,
            "dropped_frame_count": len(dropped),
            "repeated_frame_count": picked.repeats,
            "kept_repeats": kept_repeats,
            **({"blank_frames": picked.blank} if picked.blank else {}),  # written only when found (docs/poses.md)
            "skipped_files": [p.name for p in skipped],
            "max_dropped": cfg.max_dropped,
            "dropped": [{k: v for k, v in r.items() if k != "timestamp"} for r in dropped_rows],
            "width": written[0] if written else None,
            "height": written[1] if written else None,
            "source_width": size[0] if size else None,
            "source_height": size[1] if size else None,
            "rotation": getattr(source, "rotation", None),  # a video's display rotation, applied to its frames
            "max_side": cfg.max_side,
            "downscale_factor": factor,
            "n_frames": len(rows),
            "selection": {"count": cfg.count, "stride": cfg.stride, "rule": rule.describe(),
                          "score": "variance of the Laplacian of the grey image",
                          "preferred": len(cfg.prefer), "preferred_kept": sum(
                              int(r["source_index"]) in cfg.prefer for r in rows)},
            "downscale": {f"images_{f}": f for f in cfg.downscale},
            "sharpness_all": [None if s is None else round(s, 4) for s in all_sharpness],
            "timings": {"total": time.perf_counter() - t_start},
        }
        write_json(out / "frames.json", summary)
    return summary
