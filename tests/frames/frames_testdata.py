"""Test data for the frames stage: small textured frames, some blurred, written as video or images."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

WIDTH, HEIGHT, FPS = 96, 64, 10.0


def textured_frame(k: int) -> np.ndarray:
    """A fine random texture, shifted a little per frame (fine detail: a high Laplacian variance)."""
    rng = np.random.default_rng(1234)
    big = (rng.random((HEIGHT + 40, WIDTH + 40)) * 255).astype(np.uint8)
    big = cv2.GaussianBlur(big, (0, 0), 0.8)
    y, x = k % 20, (2 * k) % 40
    grey = big[y:y + HEIGHT, x:x + WIDTH]
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)


def blurred(image: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(image, (0, 0), sigma)


def make_frames(n: int, sharp: set[int]) -> list[np.ndarray]:
    """``n`` frames: those in ``sharp`` unblurred, the others blurred by an amount varying per frame."""
    return [textured_frame(k) if k in sharp else blurred(textured_frame(k), 1.5 + 0.3 * (k % 3))
            for k in range(n)]


def write_video(path: Path, frames: list[np.ndarray], fourcc: str = "mp4v", fps: float = FPS) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (WIDTH, HEIGHT))
    assert writer.isOpened(), f"OpenCV cannot write {fourcc} here"
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def avi_declaring(avi: bytes, n_frames: int) -> bytes:
    """An AVI file's bytes whose headers declare ``n_frames`` (the main header's total frames, the stream header's
    length) whatever it holds: a header written wrong, or a length estimated from a duration and a frame rate."""
    data = bytearray(avi)
    main = data.find(b"avih") + 8  # dwMicroSecPerFrame, dwMaxBytesPerSec, dwPaddingGranularity, dwFlags, dwTotalFrames
    data[main + 16:main + 20] = n_frames.to_bytes(4, "little")
    stream = data.find(b"strh") + 8  # fccType, fccHandler, dwFlags, wPriority, wLanguage, dwInitialFrames, dwScale,
    data[stream + 32:stream + 36] = n_frames.to_bytes(4, "little")  # dwRate, dwStart, dwLength
    return bytes(data)


# stride 5 over 20 frames: windows [0-4], [5-9], [10-14], [15-19]; one sharp frame in each, not at a window edge
SHARP = {3, 6, 12, 19}


def encoded(image: np.ndarray, ext: str) -> bytes:
    """A real image file's bytes (``.jpg`` or ``.png``), as cv2.imwrite would write them."""
    ok, buf = cv2.imencode(ext, image)
    assert ok
    return buf.tobytes()


def truncated_jpeg(image: np.ndarray, keep: int = 3000) -> bytes:
    """The first ``keep`` bytes of a whole JPEG: a copy cut off mid-transfer (the case measured in issue 17)."""
    data = encoded(image, ".jpg")
    assert len(data) > keep + 500, "the test JPEG must be larger than the cut"
    return data[:keep]


def jpeg_with_corrupt_scan(image: np.ndarray) -> bytes:
    """A JPEG whose entropy-coded data is overwritten in the middle but which keeps its end marker:
    libjpeg decodes it and only prints "Corrupt JPEG data" on stderr."""
    data = bytearray(encoded(image, ".jpg"))
    mid = len(data) // 2
    data[mid:mid + 40] = b"\xff" * 40
    return bytes(data)


def png_with_broken_tail(image: np.ndarray) -> bytes:
    """A whole PNG less the last 3 bytes of its IEND chunk's CRC: the chunk runs past the end of the file."""
    return encoded(image, ".png")[:-3]


def png_with_bad_crc(image: np.ndarray) -> bytes:
    """A whole-length PNG with one byte of its image data flipped: the IDAT chunk's CRC no longer matches."""
    data = bytearray(encoded(image, ".png"))
    idat = data.find(b"IDAT")
    data[idat + 4 + 20] ^= 0x5A
    return bytes(data)


def damage_middle(path: Path, out: Path, fill: bytes, length: int = 200) -> Path:
    """A copy of a video with ``length`` bytes in the middle of the file overwritten by ``fill``."""
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid:mid + length] = fill * length
    out.write_bytes(bytes(data))
    return out
