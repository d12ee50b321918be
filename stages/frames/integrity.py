"""Is a source image or video frame whole? Cheap structural checks plus the decoder's own complaints.

OpenCV keeps a truncated JPEG read with ``cv2.imread`` (the missing rows come
out grey) and a video frame FFmpeg had to conceal; the only sign is a line
that libjpeg, libpng or FFmpeg prints on the process's stderr. So:

- every image file is read once into memory and checked from its bytes
  before it is decoded: empty file; JPEG without its end-of-image marker
  (FFD9) after the scan data; PNG with a chunk that runs past the end of the
  file, a CRC mismatch, or no IEND chunk. These checks are one pass over the
  bytes at C speed (``bytes.find``, ``zlib.crc32``), far cheaper than a decode;
- the same bytes are then decoded once with ``cv2.imdecode`` (which returns
  None for a truncated JPEG held in memory instead of padding it grey), with
  file descriptor 2 captured for the duration, so that what the decoder prints
  is attributed to the file or frame it is about: damage reports drop the
  frame, other lines (a libpng ``iCCP`` warning) are passed on as a warning
  naming the file instead of passing by anonymously.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import IO, TypeVar

import cv2
import numpy as np

T = TypeVar("T")

JPEG_MAGIC = b"\xff\xd8\xff"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# words in a decoder's stderr line that mean the data is damaged (libjpeg: "Premature end of JPEG file",
# "Corrupt JPEG data: ..."; libpng: "libpng error: ..."; FFmpeg: "ac-tex damaged", "overread 2", ...)
_DAMAGE = re.compile(r"premature|corrupt|error|damaged|truncat|overread|invalid|bogus|broken|missing|concealing",
                     re.IGNORECASE)
# FFmpeg's log prefix: OpenCV lets through only lines at AV_LOG_ERROR or worse, so each one is a decoding error
_FFMPEG_LINE = re.compile(r"^\[[\w,.-]+ @ 0x[0-9a-fA-F]+\]")
_POINTER = re.compile(r" @ 0x[0-9a-fA-F]+\]")  # "[mpeg4 @ 0x55b1...]" -> "[mpeg4]": same text for every run


@dataclass(frozen=True)
class DecoderReport:
    """What the decoder printed while decoding one image or frame, sorted into damage and other remarks."""

    damage: tuple[str, ...] = ()
    """Lines that report damaged or missing data (the frame is dropped)."""
    remarks: tuple[str, ...] = ()
    """Other lines (passed on as a warning naming the file; the frame is kept)."""

    @classmethod
    def from_text(cls, text: str) -> DecoderReport:
        damage: list[str] = []
        remarks: list[str] = []
        for line in (s.strip() for s in text.splitlines()):
            if not line:
                continue
            bucket = damage if _FFMPEG_LINE.match(line) or _DAMAGE.search(line) else remarks
            bucket.append(_POINTER.sub("]", line))
        return cls(tuple(damage), tuple(remarks))

    def summary(self, lines: tuple[str, ...], limit: int = 2) -> str:
        """The first ``limit`` distinct lines, joined, with how many more there were."""
        distinct = list(dict.fromkeys(lines))
        text = " | ".join(f'"{s}"' for s in distinct[:limit])
        more = len(lines) - limit
        return text + (f" (+{more} more lines)" if more > 0 else "")


class StderrCapture:
    """Captures what C libraries write to file descriptor 2 during a call (libjpeg, libpng, FFmpeg print there).

    Use as a context manager around a loop, then ``call(fn)`` per image or frame. The text goes to an
    unnamed temporary file (no pipe that could fill up and block the decoder). When fd 2 cannot be
    duplicated (closed, exotic embedding), calls run uncaptured and report nothing.
    """

    def __init__(self) -> None:
        self._sink: IO[bytes] | None = None

    def __enter__(self) -> StderrCapture:
        try:
            os.fstat(2)
            self._sink = tempfile.TemporaryFile()
        except OSError:
            self._sink = None
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._sink is not None:
            self._sink.close()
            self._sink = None

    def call(self, fn: Callable[[], T]) -> tuple[T, str]:
        """``fn()`` with fd 2 redirected; returns its result and what was written to fd 2 meanwhile."""
        if self._sink is None:
            return fn(), ""
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(self._sink.fileno(), 2)
        try:
            result = fn()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        self._sink.seek(0)
        text = self._sink.read().decode("utf-8", errors="replace")
        self._sink.seek(0)
        self._sink.truncate()
        return result, text


def jpeg_problem(data: bytes) -> str | None:
    """Why a JPEG file is incomplete, from its markers alone (None: it looks whole, or is too odd to judge).

    The header segments are walked by their lengths up to the first start-of-scan; after it, an 0xFF byte in
    the entropy-coded data is always followed by 0x00 or a restart marker, so the first FFD9 found after the
    scan header is the real end-of-image marker (bytes after it, such as a phone's motion-photo video, are
    allowed). An embedded EXIF thumbnail has its own FFD9, but it sits before the scan and is skipped.
    """
    n = len(data)
    i = 2
    scan = -1
    while i + 1 < n:
        if data[i] != 0xFF:
            return None  # not where a marker should be: leave the verdict to the decoder
        while i + 1 < n and data[i + 1] == 0xFF:  # fill bytes
            i += 1
        if i + 1 >= n:
            break
        marker = data[i + 1]
        if marker == 0xD9:
            return "the JPEG ends before any image data (end marker right after the header)"
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # standalone markers, no length
            i += 2
            continue
        if i + 4 > n:
            break
        length = int.from_bytes(data[i + 2:i + 4], "big")
        if marker == 0xDA:
            scan = i + 2 + length
            break
        i += 2 + length
    if scan < 0 or scan > n:
        return f"the file ends inside the JPEG header after {n} bytes (truncated copy, no image data)"
    if data.find(b"\xff\xd9", scan) < 0:
        return f"no JPEG end marker (FFD9) after the image data: the file is cut off after {n} bytes"
    return None


def png_problem(data: bytes) -> str | None:
    """Why a PNG file is incomplete or damaged: a chunk past the end, a CRC mismatch, or no IEND chunk."""
    n = len(data)
    view = memoryview(data)
    i = len(PNG_MAGIC)
    while i + 8 <= n:
        length = int.from_bytes(data[i:i + 4], "big")
        kind = bytes(data[i + 4:i + 8]).decode("latin-1")
        end = i + 12 + length
        if end > n:
            return f"the {kind} chunk at byte {i} runs past the end of the file: cut off after {n} bytes"
        stored = int.from_bytes(data[end - 4:end], "big")
        if zlib.crc32(view[i + 4:end - 4]) != stored:
            return f"CRC mismatch in the {kind} chunk at byte {i} (damaged data)"
        if kind == "IEND":
            return None
        i = end
    return f"no IEND chunk: the PNG is cut off after {n} bytes"


def bytes_problem(data: bytes) -> str | None:
    """Structural problem of an image file's bytes (empty, truncated JPEG, damaged PNG), else None."""
    if not data:
        return "the file is empty (0 bytes)"
    if data.startswith(JPEG_MAGIC):
        return jpeg_problem(data)
    if data.startswith(PNG_MAGIC):
        return png_problem(data)
    return None


def decode_image(data: bytes, capture: StderrCapture) -> tuple[np.ndarray | None, str | None, tuple[str, ...]]:
    """Decode an image file's bytes once: (BGR image or None, why it is dropped or None, remarks to warn of).

    The structural check runs first, so a truncated file is never decoded. ``cv2.imdecode`` applies the EXIF
    orientation as ``cv2.imread`` does.
    """
    problem = bytes_problem(data)
    if problem is not None:
        return None, problem, ()
    buffer = np.frombuffer(data, dtype=np.uint8)
    image, text = capture.call(lambda: cv2.imdecode(buffer, cv2.IMREAD_COLOR))
    report = DecoderReport.from_text(text)
    if image is None:
        said = report.damage + report.remarks
        why = f" (the decoder said {report.summary(said)})" if said else ""
        return None, f"OpenCV cannot decode it: corrupt, truncated or not an image{why}", ()
    if report.damage:
        return None, f"the decoder reported damaged data: {report.summary(report.damage)}", ()
    return image, None, report.remarks
