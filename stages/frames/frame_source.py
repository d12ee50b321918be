"""Frames in playback order from a video file or an image folder, with source index and timestamp.

The source index is what later stages key on (states, key frames, masks), so
it is the frame's position in the *source*: its decode position in a video,
or the number in an image's name (``frame_00012.png`` -> 12) for a folder.

A frame that is damaged (a truncated or corrupt image file, a video frame
FFmpeg reports as damaged or cannot decode) comes out as a ``DroppedFrame``
at its place in the sequence, so the caller can list it by name and the
windows and source indices of the other frames stay where they were.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from stages.scene import frame_number_of

from .errors import FrameSourceError
from .folder_numbering import check_numbering, natural_key
from .integrity import JPEG_MAGIC, PNG_MAGIC, DecoderReport, StderrCapture, decode_image

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
REENCODE = ("re-encode it (`ffmpeg -i VIDEO -c:v libx264 -pix_fmt yuv420p fixed.mp4`) or extract its frames into an "
            "image folder and pass that folder as --video")
REENCODE_FIX = f"check that the file plays and was copied completely; {REENCODE}"
CONVERT_FIX = ("convert photos the stage cannot read (HEIC, RAW such as DNG) to JPEG or PNG, or pass a video file; "
               "a video belongs in --video by itself, not in a folder of frames")
RECOPY_FIX = ("copy the images again from the camera or phone (these copies are incomplete or damaged), "
              "or delete the broken ones")
SYSTEM_FILES = {"thumbs.db", "ehthumbs.db", "desktop.ini"}
"""Files an operating system writes into a folder of photos (lower case): no frames, and not worth a warning."""
MAX_CONSECUTIVE_FAILURES = 16
"""A video read that fails is retried this many times in a row before the rest of the video counts as missing."""


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
    remarks: tuple[str, ...] = ()
    """What the decoder printed about this frame without calling it damaged (passed on as a warning)."""
    where: str = ""
    """The image file, or ``video: frame N``, for messages."""


@dataclass
class DroppedFrame:
    """A source frame that is damaged or cannot be decoded: listed by name, never kept."""

    position: int
    """Rank in playback order (0-based)."""
    source_index: int
    """Index of the frame in the source (the name it would have had: ``frame_<index>.png``)."""
    timestamp: float
    """Seconds from the start (NaN when unknown)."""
    source_file: Path
    """The image file, or the video file the frame belongs to."""
    problem: str
    """What is wrong with it, in words."""
    in_video: bool = False
    """A frame of a video (``source_file`` is the video), not an image file of a folder."""

    def where(self) -> str:
        """``path`` for an image; ``path: frame N (t=S s)`` for a video frame."""
        if not self.in_video:
            return str(self.source_file)
        stamp = f" (t={self.timestamp:.2f} s)" if math.isfinite(self.timestamp) else ""
        return f"{self.source_file}: frame {self.source_index}{stamp}"


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
        with self.path.open("rb") as handle:
            head = handle.read(len(PNG_MAGIC))
        # a file that starts as a JPEG or PNG is a photo when it holds one frame (FFmpeg opens a photo as a video
        # of one frame, which no later stage can use), but a camera's raw MJPEG stream (JPEGs one after another,
        # `ffmpeg -f mjpeg`) or an animated PNG is a video
        still = "JPEG" if head.startswith(JPEG_MAGIC) else "PNG" if head.startswith(PNG_MAGIC) else None
        with StderrCapture() as stderr:
            capture, text = stderr.call(lambda: cv2.VideoCapture(str(self.path)))
        said = DecoderReport.from_text(text)
        lines = tuple(dict.fromkeys(said.damage + said.remarks))  # FFmpeg repeats a line per probe
        self.remarks: tuple[str, ...] = lines  # what FFmpeg printed while opening it (warned of, naming the video)
        if not capture.isOpened() and still:
            raise self._photo_error(still)
        if not capture.isOpened():
            raise FrameSourceError(self.path, "OpenCV cannot open it as a video (unknown format, corrupt data, "
                                   "or an mp4 cut off before its index)"
                                   + (f"; FFmpeg said {said.summary(lines)}" if lines else ""), REENCODE_FIX)
        self.codec = fourcc_text(capture.get(cv2.CAP_PROP_FOURCC))
        """The stream's codec tag (``avc1``, ``hvc1``, ``av01``, ``mp4v``, ``MJPG``), '' when OpenCV gives none."""
        self.fps = float(capture.get(cv2.CAP_PROP_FPS))
        if not (math.isfinite(self.fps) and self.fps > 0):
            self.fps = float("nan")
        meta = float(capture.get(cv2.CAP_PROP_ORIENTATION_META))
        self.rotation = int(meta) % 360 if math.isfinite(meta) else 0
        """Display rotation (degrees) of the video's metadata: a phone held upright films landscape pixels and
        says 90. Frames are decoded turned by it (``CAP_PROP_ORIENTATION_AUTO``), as a player shows them and as
        masks drawn on them are."""
        declared = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        capture.release()
        # some streams do not declare a length: count by grabbing (no decoding) so windows can be planned
        self.n_declared = declared if declared > 0 else self.count_frames()
        if still and self.n_declared <= 1:
            raise self._photo_error(still)
        if self.n_declared <= 0:
            raise FrameSourceError(self.path, "the video holds no frames that OpenCV can read", REENCODE_FIX)

    def _photo_error(self, kind: str) -> FrameSourceError:
        return FrameSourceError(self.path, f"the file is a {kind} photo, not a video (whatever its name says)",
                                "pass the video file itself, or put the photos of the capture in a folder and pass "
                                "that folder as --video")

    def count_frames(self) -> int:
        """Frames of a stream that declares no length, or more than it declares; what FFmpeg prints meanwhile
        joins ``self.remarks`` (the frames it is about are told apart when they are decoded)."""

        def count() -> int:
            capture = cv2.VideoCapture(str(self.path))
            n = 0
            while capture.grab():
                n += 1
            capture.release()
            return n

        with StderrCapture() as stderr:
            n, text = stderr.call(count)
        said = DecoderReport.from_text(text)
        self.remarks = tuple(dict.fromkeys(self.remarks + said.damage + said.remarks))
        return n

    def _open_for_decoding(self) -> cv2.VideoCapture:
        """One decoding thread, so that what FFmpeg prints while a frame is read is about that frame (with
        frame threads, a damaged frame is reported while the one before it is returned)."""
        n_threads = getattr(cv2, "CAP_PROP_N_THREADS", None)
        with StderrCapture() as stderr:  # what opening prints was already said (self.remarks) when checked
            capture = None
            if n_threads is not None:
                capture, _ = stderr.call(lambda: cv2.VideoCapture(str(self.path), cv2.CAP_ANY, [n_threads, 1]))
                if not capture.isOpened():
                    capture.release()
                    capture = None
            if capture is None:
                capture = stderr.call(lambda: cv2.VideoCapture(str(self.path)))[0]
        # OpenCV's default, set so that no build differs (FFmpeg's open() refuses it as an open parameter)
        capture.set(cv2.CAP_PROP_ORIENTATION_AUTO, 1)
        return capture

    def __iter__(self) -> Iterator[SourceFrame | DroppedFrame]:
        """Frames in decode order. A read that fails is retried; when a later read succeeds, the failed
        positions are dropped frames; when reads keep failing, the video ends there (the caller compares the
        count with the declared length). A frame FFmpeg reports damaged data for is dropped too."""
        capture = self._open_for_decoding()
        previous = -1.0
        position = 0
        failed: list[tuple[int, str]] = []  # (position, what FFmpeg said) of reads not yet followed by a success
        try:
            with StderrCapture() as stderr:
                while True:
                    (ok, image), text = stderr.call(capture.read)
                    report = DecoderReport.from_text(text)
                    if not ok or image is None:
                        failed.append((position, report.summary(report.damage + report.remarks)))
                        position += 1
                        if len(failed) >= MAX_CONSECUTIVE_FAILURES or position >= self.n_declared:
                            return
                        continue
                    for pos, said in failed:
                        yield DroppedFrame(position=pos, source_index=pos, timestamp=self._clock(pos),
                                           source_file=self.path, in_video=True,
                                           problem="OpenCV could not decode this frame"
                                                   + (f" (FFmpeg said {said})" if said else ""))
                    failed = []
                    stamp = capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
                    # the container's clock when it is sane (variable frame rate phones), else index / fps
                    if not (math.isfinite(stamp) and stamp >= 0 and stamp > previous):
                        stamp = self._clock(position)
                    previous = stamp
                    if report.damage:
                        yield DroppedFrame(position=position, source_index=position, timestamp=stamp,
                                           source_file=self.path, in_video=True,
                                           problem=f"FFmpeg reported damaged data while decoding it: "
                                                   f"{report.summary(report.damage)}")
                    else:
                        if image.ndim == 2:
                            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
                        yield SourceFrame(position=position, source_index=position, timestamp=stamp, image=image,
                                          remarks=report.remarks, where=f"{self.path}: frame {position}")
                    position += 1
        finally:
            capture.release()

    def _clock(self, position: int) -> float:
        return position / self.fps if math.isfinite(self.fps) else float("nan")


class ImageFolderSource:
    """Images of a folder in frame-number order (or name order when names carry no number)."""

    kind = "images"

    def __init__(self, path: Path, fps: float | None = None) -> None:
        self.path = Path(path)
        # hidden files are no frames: macOS leaves ``._IMG_0001.jpg`` (its metadata) beside every photo it copies;
        # nor are the thumbnail caches and folder settings Windows writes into a folder of photos
        visible = [p for p in self.path.iterdir()
                   if p.is_file() and not p.name.startswith(".") and p.name.lower() not in SYSTEM_FILES]
        files = [p for p in visible if p.suffix.lower() in IMAGE_SUFFIXES]
        self.skipped = sorted((p for p in visible if p.suffix.lower() not in IMAGE_SUFFIXES), key=natural_key)
        """Files of the folder that are not images this stage reads (HEIC, RAW, sidecars): warned of by name."""
        if not files:
            raise FrameSourceError(self.path, f"the folder holds no images ({', '.join(IMAGE_SUFFIXES)})"
                                   + (f"; it holds {skipped_summary(self.skipped)}" if self.skipped else ""),
                                   CONVERT_FIX if self.skipped else "pass a video file or a folder of frames")
        numbers = [frame_number_of(p.stem) for p in files]
        numbered = all(n is not None for n in numbers)
        if numbered:
            first: dict[int, Path] = {}
            for n, p in zip(numbers, files, strict=True):
                if n in first:
                    a, b = sorted((first[n].name, p.name))
                    raise FrameSourceError(self.path, f"two images carry frame number {n} ({a}, {b}; the number "
                                           "is the last `_`-separated token of a name, else its last run of digits)",
                                           "keep one image per frame number (the number in a name orders the "
                                           "frames)")
                first[n] = p
            check_numbering(self.path, files, numbers)  # type: ignore[arg-type]
            pairs = sorted(zip(numbers, files, strict=True))
            self.files = [p for _, p in pairs]
            self.indices = [n for n, _ in pairs]
        else:  # some names carry no number: playback order = name order, numbers in names compared as numbers
            self.files = sorted(files, key=natural_key)
            self.indices = list(range(len(files)))
        self.numbered = numbered
        self.remarks: tuple[str, ...] = ()
        self.fps = float(fps) if fps else float("nan")
        self.n_declared = len(self.files)

    def __iter__(self) -> Iterator[SourceFrame | DroppedFrame]:
        """Each file is read once, checked from its bytes (empty, truncated JPEG, damaged PNG) and decoded
        once with the decoder's stderr captured; a file that fails any of this is a DroppedFrame."""
        shape, first, read = None, None, 0
        with StderrCapture() as stderr:
            for position, (path, index) in enumerate(zip(self.files, self.indices, strict=True)):
                stamp = index / self.fps
                try:
                    data = path.read_bytes()
                except OSError as exc:
                    yield DroppedFrame(position, index, stamp, path, f"the file cannot be read ({exc.strerror})")
                    continue
                image, problem, remarks = decode_image(data, stderr)
                if image is None:
                    yield DroppedFrame(position, index, stamp, path, problem or "the image cannot be decoded")
                    continue
                if shape is None:
                    shape, first = image.shape, path
                elif image.shape != shape:
                    raise _size_mismatch(path, image.shape, shape, first if read == 1 else None)
                read += 1
                yield SourceFrame(position=position, source_index=index, timestamp=stamp, image=image,
                                  remarks=remarks, where=str(path))


def _size_mismatch(path: Path, size: tuple[int, ...], first: tuple[int, ...],
                   only_earlier: Path | None = None) -> FrameSourceError:
    """A photo of another size than the folder's first: turned (portrait among landscape), or another camera or a
    resized copy. COLMAP shares one camera among the frames, so neither can be mixed in. ``only_earlier``: the one
    frame read before this one, when there is just one: then either of the two may be the odd one."""
    (h, w), (h0, w0) = size[:2], first[:2]
    problem = f"the image is {w}x{h} but earlier frames are {w0}x{h0}"

    def also(what: str) -> str:  # the fix for the folder's first photo, when it alone was read before
        return "" if only_earlier is None else f"; if the folder's first photo {only_earlier.name} is {what}"

    if (w, h) == (h0, w0):
        return FrameSourceError(path, problem + ": it is turned by 90 degrees against them (a photo held the other "
                                "way, or a viewer that stored the turn in the pixels)",
                                f"turn it back to {w0}x{h0} in an image editor, or leave it out of the folder"
                                + also(f"the one held the other way, turn that one to {w}x{h} instead"))
    if w * h0 == h * w0:  # the same shape at another scale
        return FrameSourceError(path, problem + " (a resized copy?)",
                                f"resize it to {w0}x{h0} if it is a scaled copy of a photo from the same lens, else "
                                "leave it out of the folder (frames must come from one camera at one size)"
                                + also(f"the odd one, resize that one to {w}x{h} instead"))
    if w * w0 == h * h0:  # the other orientation at another scale
        return FrameSourceError(path, problem + ": it is turned by 90 degrees against them and of another scale",
                                f"turn it and resize it to {w0}x{h0} if it is a photo from the same lens, else leave "
                                "it out of the folder"
                                + also(f"the odd one, turn and resize that one to {w}x{h} instead"))
    return FrameSourceError(path, problem + " (another camera, or a crop)",
                            "leave it out of the folder: frames must come from one camera at one size"
                            + also("the odd one, leave that one out instead"))


def fourcc_text(value: float) -> str:
    """OpenCV's CAP_PROP_FOURCC (four bytes, low byte first) as text; '' when unset or not printable."""
    code = int(value) if value == value and value > 0 else 0
    text = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip("\x00 ")
    return text if text.isprintable() else ""


def skipped_summary(files: list[Path]) -> str:
    """``3 other files (2 .heic, 1 .mov: IMG_15.HEIC, IMG_16.heic, ...)`` for a message."""
    kinds: dict[str, int] = {}
    for p in files:
        kinds[p.suffix.lower() or "no extension"] = kinds.get(p.suffix.lower() or "no extension", 0) + 1
    counts = ", ".join(f"{n} {k}" for k, n in sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0])))
    names = ", ".join(p.name for p in files[:4]) + (", ..." if len(files) > 4 else "")
    return f"{len(files)} other file{'s' if len(files) != 1 else ''} ({counts}: {names})"


def open_source(path: Path, fps: float | None = None) -> VideoSource | ImageFolderSource:
    """A video file or an image folder, checked for existence and content."""
    path = Path(path)
    if path.is_dir():
        return ImageFolderSource(path, fps)
    return VideoSource(path)
