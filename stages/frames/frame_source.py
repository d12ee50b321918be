"""Frames in playback order from a video file or an image folder, with source index and timestamp.

The source index is what later stages key on (states, key frames, masks), so
it is the frame's position in the *source*: its decode position in a video,
or the number in an image's name (``frame_00012.png`` -> 12) for a folder.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from stages.scene import frame_id_of

from .errors import FrameSourceError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
REENCODE_FIX = ("check that the file plays and was copied completely; re-encode it "
                "(`ffmpeg -i VIDEO -c:v libx264 -pix_fmt yuv420p fixed.mp4`) or extract its frames into an "
                "image folder and pass that folder as --video")


@dataclass
class SourceFrame:
    """One decoded frame."""

    position: int
    """Rank in playback order (0-based)."""
    source_index: int
    """Index of the frame in the source (what the output file is named after)."""
    timestamp: float
    """Seconds from the start of the video (NaN for an image folder without --fps)."""
    image: np.ndarray
    """BGR uint8 H x W x 3."""


class VideoSource:
    """Decodes a video with OpenCV, frame by frame (never the whole video in memory)."""

    kind = "video"

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FrameSourceError(self.path, "video file not found", "check the path given to --video")
        if self.path.stat().st_size == 0:
            raise FrameSourceError(self.path, "the video file is empty (0 bytes)",
                                   "copy the video again from the recording device")
        capture = cv2.VideoCapture(str(self.path))
        if not capture.isOpened():
            raise FrameSourceError(self.path, "OpenCV cannot open it as a video (unknown format, corrupt data, "
                                   "or an mp4 cut off before its index)", REENCODE_FIX)
        self.fps = float(capture.get(cv2.CAP_PROP_FPS))
        if not (math.isfinite(self.fps) and self.fps > 0):
            self.fps = float("nan")
        declared = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        capture.release()
        # some streams do not declare a length: count by grabbing (no decoding) so windows can be planned
        self.n_declared = declared if declared > 0 else self._count_frames()
        if self.n_declared <= 0:
            raise FrameSourceError(self.path, "the video holds no frames that OpenCV can read", REENCODE_FIX)

    def _count_frames(self) -> int:
        capture = cv2.VideoCapture(str(self.path))
        n = 0
        while capture.grab():
            n += 1
        capture.release()
        return n

    def __iter__(self) -> Iterator[SourceFrame]:
        capture = cv2.VideoCapture(str(self.path))
        previous = -1.0
        position = 0
        try:
            while True:
                ok, image = capture.read()
                if not ok or image is None:
                    return
                stamp = capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
                # the container's clock when it is sane (variable frame rate phones), else index / fps
                if not (math.isfinite(stamp) and stamp >= 0 and stamp > previous):
                    stamp = position / self.fps if math.isfinite(self.fps) else float("nan")
                previous = stamp
                if image.ndim == 2:
                    image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
                yield SourceFrame(position=position, source_index=position, timestamp=stamp, image=image)
                position += 1
        finally:
            capture.release()


class ImageFolderSource:
    """Images of a folder in frame-number order (or name order when names carry no number)."""

    kind = "images"

    def __init__(self, path: Path, fps: float | None = None) -> None:
        self.path = Path(path)
        files = [p for p in self.path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]
        if not files:
            raise FrameSourceError(self.path, f"the folder holds no images ({', '.join(IMAGE_SUFFIXES)})",
                                   "pass a video file or a folder of frames")
        ids = [frame_id_of(p.stem) for p in files]
        numbered = all(i.isdigit() for i in ids) and len({int(i) for i in ids}) == len(ids)
        if numbered:
            pairs = sorted(zip((int(i) for i in ids), files, strict=True))
            self.files = [p for _, p in pairs]
            self.indices = [i for i, _ in pairs]
        else:  # no usable number in the names: playback order = name order
            self.files = sorted(files)
            self.indices = list(range(len(files)))
        self.numbered = numbered
        self.fps = float(fps) if fps else float("nan")
        self.n_declared = len(self.files)

    def __iter__(self) -> Iterator[SourceFrame]:
        shape = None
        for position, (path, index) in enumerate(zip(self.files, self.indices, strict=True)):
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                raise FrameSourceError(path, "the image cannot be read (corrupt or not an image)",
                                       "replace or delete this file")
            if shape is None:
                shape = image.shape
            elif image.shape != shape:
                raise FrameSourceError(path, f"the image is {image.shape[1]}x{image.shape[0]} but earlier frames "
                                       f"are {shape[1]}x{shape[0]}", "give frames of one camera at one size")
            yield SourceFrame(position=position, source_index=index, timestamp=index / self.fps, image=image)


def open_source(path: Path, fps: float | None = None) -> VideoSource | ImageFolderSource:
    """A video file or an image folder, checked for existence and content."""
    path = Path(path)
    if path.is_dir():
        return ImageFolderSource(path, fps)
    return VideoSource(path)
