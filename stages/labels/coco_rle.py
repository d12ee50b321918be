"""COCO run-length encoding (RLE), compressed and uncompressed, without pycocotools.

COCO stores a mask as run lengths over the pixels in column-major (Fortran)
order, starting with a run of zeros. The compressed form packs each count into
5-bit groups written as printable characters (offset 48); from the fourth count
on (pycocotools: `i > 2`), the difference to the count two places back is stored instead, so long
alternating runs stay short. Both directions are here so tests can write RLE
that real COCO files would hold.
"""

from __future__ import annotations

import numpy as np


def decode_counts_string(text: str) -> list[int]:
    """Compressed RLE string -> run lengths."""
    counts: list[int] = []
    pos = 0
    while pos < len(text):
        value = 0
        shift = 0
        while True:
            c = ord(text[pos]) - 48
            if c < 0 or c > 63:
                raise ValueError(f"character {text[pos]!r} at {pos} is not part of a COCO RLE string")
            value |= (c & 0x1F) << shift
            pos += 1
            shift += 5
            if not c & 0x20:
                if c & 0x10:  # sign bit of the last group: negative number
                    value -= 1 << shift
                break
            if pos >= len(text):
                raise ValueError("RLE string ends in the middle of a count")
        if len(counts) > 2:
            value += counts[-2]
        counts.append(value)
    return counts


def encode_counts_string(counts: list[int]) -> str:
    """Run lengths -> compressed RLE string (inverse of :func:`decode_counts_string`)."""
    out: list[str] = []
    for i, count in enumerate(counts):
        x = int(count) - (int(counts[i - 2]) if i > 2 else 0)
        while True:
            c = x & 0x1F
            x >>= 5
            more = x != -1 if c & 0x10 else x != 0
            if more:
                c |= 0x20
            out.append(chr(c + 48))
            if not more:
                break
    return "".join(out)


def decode_rle(counts: list[int] | str, height: int, width: int) -> np.ndarray:
    """RLE (list of counts or compressed string) -> bool mask ``[height, width]``."""
    runs = decode_counts_string(counts) if isinstance(counts, str) else [int(c) for c in counts]
    if any(r < 0 for r in runs):
        raise ValueError("negative run length")
    total = sum(runs)
    if total != height * width:
        raise ValueError(f"run lengths add up to {total} pixels but the image has {height}x{width} = "
                         f"{height * width}")
    values = np.zeros(len(runs), dtype=bool)
    values[1::2] = True
    flat = np.repeat(values, runs)
    return flat.reshape((width, height)).T.copy()


def encode_rle(mask: np.ndarray) -> list[int]:
    """Bool mask ``[height, width]`` -> uncompressed run lengths (column-major, zeros first)."""
    flat = np.asarray(mask, dtype=bool).T.reshape(-1)
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate([[0], change, [flat.size]])
    runs = np.diff(bounds).tolist()
    if flat.size and flat[0]:
        runs = [0, *runs]
    return [int(r) for r in runs]
