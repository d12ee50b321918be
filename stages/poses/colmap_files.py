"""Completeness checks of COLMAP model files, so that a damaged file is named.

COLMAP's binary reader does not check for a short read: a truncated cameras.bin loads as a 1x1 camera
with zero focal length, and a cut images.bin fails later with a message that names no file. Each file
states its counts, so walking its records tells whether it holds exactly what it declares (the layout
is that of COLMAP's ``reconstruction_io_binary.cc``, unchanged from 3.x to 4.x for these three files).
Text files state their counts in a header comment (``# Number of images: 50, ...``).
"""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import BinaryIO

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import pycolmap

_CAMERA = struct.Struct("<iiQQ")  # camera_id, model_id, width, height
_IMAGE = struct.Struct("<I7dI")  # image_id, qw qx qy qz, tx ty tz, camera_id
_POINT = struct.Struct("<Q3d3BdQ")  # point3D_id, xyz, rgb, error, track length
POINT2D_BYTES = 24  # x, y (double), point3D_id (int64)
TRACK_ELEMENT_BYTES = 8  # image_id, point2D_idx (uint32)


class Truncated(Exception):
    """The file ends before the records it declares."""


def _params_per_model(model_id: int) -> int:
    try:
        return len(pycolmap.Camera.create_from_model_id(1, model_id, 1.0, 1, 1).params)
    except (ValueError, RuntimeError, TypeError) as exc:
        raise Truncated(f"unknown camera model id {model_id}") from exc


def _read(f: BinaryIO, size: int, what: str) -> bytes:
    data = f.read(size)
    if len(data) != size:
        raise Truncated(f"it ends inside {what}")
    return data


def _skip(f: BinaryIO, size: int, end: int, what: str) -> None:
    if f.tell() + size > end:
        raise Truncated(f"it ends inside {what}")
    f.seek(size, 1)


def _walk(f: BinaryIO, name: str, end: int) -> int:
    """Walk the records of ``name`` (cameras, images, points3D); return how many it declares."""
    (count,) = struct.unpack("<Q", _read(f, 8, "the record count"))
    for k in range(count):
        what = f"record {k + 1} of the {count} it declares"
        if name == "cameras":
            _, model_id, _, _ = _CAMERA.unpack(_read(f, _CAMERA.size, what))
            _skip(f, 8 * _params_per_model(model_id), end, what)
        elif name == "images":
            _read(f, _IMAGE.size, what)
            while _read(f, 1, what) != b"\0":  # the image name, NUL-terminated
                pass
            (n_points,) = struct.unpack("<Q", _read(f, 8, what))
            _skip(f, POINT2D_BYTES * n_points, end, what)
        else:
            *_, track_length = _POINT.unpack(_read(f, _POINT.size, what))
            _skip(f, TRACK_ELEMENT_BYTES * track_length, end, what)
    return count


def binary_file_problem(path: Path) -> str | None:
    """Why ``path`` (cameras.bin, images.bin or points3D.bin) is not a whole COLMAP file, or None."""
    name = path.stem
    end = path.stat().st_size
    try:
        with path.open("rb") as f:
            count = _walk(f, name, end)
            extra = end - f.tell()
    except Truncated as exc:
        return f"{end} bytes, cut short or corrupt ({exc})"
    if extra:
        return f"{extra} bytes after the {count} records it declares: corrupt, or not a COLMAP {name}.bin"
    return None


TEXT_RECORDS = {"cameras": ("cameras", 1), "images": ("images", 2), "points3D": ("points", 1)}
"""Text file -> (the word of its header count, lines per record: an image has a pose line and a keypoint line,
the second empty when it has no keypoints)."""


def text_file_problem(path: Path, read_count: int | None = None) -> str | None:
    """Why ``path`` (cameras.txt, images.txt or points3D.txt) disagrees with its header count, or None.

    ``read_count``: what pycolmap read; without it the records are counted from the lines.
    """
    what, lines_per_record = TEXT_RECORDS[path.stem]
    declared = None
    data_lines = 0
    with path.open(errors="replace") as f:
        for line in f:
            if line.startswith("#"):
                m = re.search(rf"Number of {what}:\s*(\d+)", line)
                declared = int(m.group(1)) if m and declared is None else declared
            elif line.strip() or lines_per_record > 1:
                data_lines += 1
    if declared is None:
        return None  # written by hand or by another tool: nothing to compare with
    count = read_count if read_count is not None else -(-data_lines // lines_per_record)
    if count != declared:
        return f"the header says {declared} {what} but the file holds {count}: it is cut short or was edited"
    return None
