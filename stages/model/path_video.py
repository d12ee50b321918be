"""Render a camera path to PNG frames (resumable) and encode them to an mp4 with OpenCV (docs/export.md).

Frames go to a folder next to the video (``<video stem>_frames/``), each written atomically, so a
rerun after an interruption renders only the missing ones. The folder keeps the resolved path
(``camera_path.json``: every frame's pose, fov and states) and a fingerprint of the run; when either
changed, the old frames are stale and are deleted before rendering.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from stages.scene import STAGE_MARKER, InputError, atomic_path, write_json

from .camera_path import CameraPath, path_to_json

CODECS = ("mp4v", "vp09", "avc1")
"""FourCCs tried with OpenCV's FFMPEG backend: mp4v (MPEG-4 part 2) always works with the pip wheels; vp09
plays in browsers but encodes ~30x slower on a CPU; avc1 (H.264) needs an OpenCV built with an H.264 encoder."""


def frames_dir_for(video: str | Path) -> Path:
    video = Path(video)
    return video.with_name(f"{video.stem}_frames")


def path_fingerprint(cp: CameraPath, run_id: dict[str, Any]) -> str:
    """Hash of what the frames depend on: poses, intrinsics, states, size, and the run's weights."""
    h = hashlib.sha256(json.dumps(run_id, sort_keys=True).encode())
    for fr in cp.frames:
        h.update(np.asarray(fr.c2w, dtype=np.float64).round(9).tobytes())
        h.update(json.dumps([fr.camera.fx, fr.camera.fy, fr.camera.cx, fr.camera.cy, fr.camera.width,
                             fr.camera.height, sorted(fr.states.items())]).encode())
    return h.hexdigest()


def _write_frame(path: Path, rgb: np.ndarray) -> None:
    arr = np.clip(np.asarray(rgb, dtype=np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)[..., ::-1]
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), arr):
            raise OSError(f"{path}: OpenCV could not write the frame")


def render_frames(run: Any, cp: CameraPath, frames_dir: Path, run_id: dict[str, Any],
                  progress: bool = True) -> dict[str, Any]:
    """Render every missing frame of ``cp`` into ``frames_dir``; returns counts and seconds."""
    check_frames_dir(frames_dir)
    frames_dir.mkdir(parents=True, exist_ok=True)
    fingerprint = path_fingerprint(cp, run_id)
    meta_path = frames_dir / "frames.json"
    stale = 0
    if meta_path.is_file():
        try:
            old = json.loads(meta_path.read_text()).get("fingerprint")
        except (OSError, json.JSONDecodeError):
            old = None
        if old != fingerprint:  # an earlier path's or run's frames (this folder is a video render's: checked)
            for png in frames_dir.glob("frame_*.png"):
                png.unlink()
                stale += 1
    (frames_dir / STAGE_MARKER).write_text(FRAMES_STAGE + "\n")
    write_json(frames_dir / "camera_path.json", path_to_json(cp))
    write_json(meta_path, {"fingerprint": fingerprint, "run": run_id, "n_frames": len(cp.frames)})
    rendered = skipped = 0
    seconds = 0.0
    bar = tqdm(list(enumerate(cp.frames)), desc="render path", unit="frame", disable=not progress)
    for j, fr in bar:
        png = frames_dir / f"frame_{j:05d}.png"
        if png.is_file():
            skipped += 1
            continue
        t = time.perf_counter()
        out = run.render(fr.camera, fr.c2w, fr.states, outputs=("rgb",))
        seconds += time.perf_counter() - t
        _write_frame(png, out["rgb"])
        rendered += 1
    return {"frames": len(cp.frames), "rendered": rendered, "skipped": skipped, "stale_deleted": stale,
            "render_seconds": round(seconds, 3), "fps": round(rendered / seconds, 3) if seconds > 0 else None}


VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".webm", ".mov")
"""Names a video ``--out`` may have (a typo such as ``--out run/model.pt`` is refused before any rendering)."""
FRAMES_STAGE = "render video"
"""The marker a video's frame folder carries (``STAGE_MARKER``): the only folder whose frames a render replaces."""


def check_frames_dir(frames_dir: Path) -> None:
    """Refuse a ``--frames-dir`` that holds anything but an earlier video render's frames: stale frames are deleted
    there, and a dataset's images or the frames stage's output (``frame_*.png`` too) must never be."""
    if not frames_dir.exists():
        return
    if not frames_dir.is_dir():
        raise InputError(frames_dir, "exists and is not a folder; a video's frames are written here",
                         "choose another --frames-dir")
    if not any(frames_dir.iterdir()):
        return
    marker = frames_dir / STAGE_MARKER
    ours = marker.is_file() and marker.read_text().strip() == FRAMES_STAGE
    if not ours and (frames_dir / "camera_path.json").is_file() and (frames_dir / "frames.json").is_file():
        try:  # written before the marker: a render's frames.json holds the path's fingerprint
            ours = "fingerprint" in json.loads((frames_dir / "frames.json").read_text())
        except (OSError, json.JSONDecodeError, AttributeError, TypeError):
            ours = False
    if not ours:
        raise InputError(frames_dir, "holds files that are not an earlier video render's frames; a render deletes "
                         "the frames it cannot reuse there", "choose another --frames-dir (an empty or new folder, "
                         "or the frames folder of an earlier video render)")


def check_video_codec(out: str | Path, codec: str) -> None:
    """Whether OpenCV can write ``codec`` into a file named like ``out``, tried on a tiny file beside it before any
    frame is rendered."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, trial = tempfile.mkstemp(prefix=f".{out.name}.{os.getpid()}.", suffix=out.suffix or ".tmp", dir=out.parent)
    os.close(fd)
    try:
        writer = cv2.VideoWriter(trial, cv2.VideoWriter_fourcc(*codec), 10.0, (16, 16))
        opened = writer.isOpened()
        writer.release()
    finally:
        Path(trial).unlink(missing_ok=True)
    if not opened:
        raise InputError(out, f"OpenCV cannot encode {codec!r} into {out.suffix or 'this file'}",
                         f"use --codec mp4v (always available) and an .mp4 name; codecs: {list(CODECS)}")


def encode_video(frames_dir: Path, n_frames: int, fps: float, out: str | Path, codec: str = "mp4v") -> int:
    """Encode ``frame_00000.png ..`` into ``out`` (atomically); returns its size in bytes."""
    out = Path(out)
    first = cv2.imread(str(frames_dir / "frame_00000.png"), cv2.IMREAD_COLOR)
    if first is None:
        raise InputError(frames_dir, "no frame_00000.png to encode", "render the frames first")
    h, w = first.shape[:2]
    with atomic_path(out) as tmp:
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*codec), float(fps), (w, h))
        if not writer.isOpened():
            raise InputError(out, f"OpenCV cannot encode {codec!r} into {out.suffix or 'this file'}",
                             f"use --codec mp4v (always available) and an .mp4 name; codecs: {list(CODECS)}")
        try:
            for j in range(n_frames):
                img = cv2.imread(str(frames_dir / f"frame_{j:05d}.png"), cv2.IMREAD_COLOR)
                if img is None or img.shape[:2] != (h, w):
                    raise InputError(frames_dir / f"frame_{j:05d}.png", "frame missing or of another size",
                                     "rerun the same command: missing frames are rendered again")
                writer.write(img)
        finally:
            writer.release()
    return out.stat().st_size
