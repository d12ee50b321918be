"""``frames.csv`` of the frames stage: which source video frames were extracted, under which names."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import StateError


@dataclass(frozen=True)
class FrameTable:
    """Extracted frames in source order."""

    names: tuple[str, ...]
    """Image file names (``frame_00012.png``)."""
    source_index: np.ndarray
    """``int64 [n]`` index of each frame in the source video, strictly increasing."""
    path: Path
    source_frame_count: int | None = None
    """Frames the source video holds (frames.json of the frames stage), when known."""

    def in_source(self, index: int) -> bool:
        """Whether ``index`` is a frame of the source video, extracted or not."""
        if self.source_frame_count is None:
            return bool((self.source_index == index).any())
        return 0 <= index < self.source_frame_count

    def stem_of(self, index: int) -> str:
        """The image stem of the frame with this source index (``frame_{i:05d}`` when not extracted)."""
        where = np.flatnonzero(self.source_index == index)
        return Path(self.names[int(where[0])]).stem if where.size else f"frame_{index:05d}"


def read_frame_table(path: str | Path) -> FrameTable:
    path = Path(path)
    if path.is_dir():
        path = path / "frames.csv"
    if not path.is_file():
        raise StateError(path, "frames.csv not found", "run `livescene frames` first and pass FRAMES/frames.csv")
    try:
        table = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise StateError(path, f"not a readable CSV ({exc})", "regenerate it with `livescene frames`") from exc
    missing = [c for c in ("frame", "source_index") if c not in table.columns]
    if missing:
        raise StateError(path, f"columns {missing} missing (has {list(table.columns)})",
                         "regenerate it with `livescene frames` (columns frame, source_index, timestamp, sharpness)")
    if table.empty:
        raise StateError(path, "no frames listed", "extract frames with `livescene frames`")
    index = pd.to_numeric(table["source_index"], errors="coerce")
    bad = np.flatnonzero(index.isna().to_numpy() | (index.to_numpy() % 1 != 0) | (index.to_numpy() < 0))
    if bad.size:
        raise StateError(path, f"row {int(bad[0]) + 2}: source_index {table['source_index'].iloc[bad[0]]!r} is not "
                         "a non-negative integer", "regenerate it with `livescene frames`")
    order = np.argsort(index.to_numpy(), kind="stable")
    src = index.to_numpy()[order].astype(np.int64)
    dup = np.flatnonzero(np.diff(src) == 0)
    if dup.size:
        raise StateError(path, f"source_index {int(src[dup[0]])} appears twice", "list every source frame once")
    names = tuple(str(table["frame"].iloc[i]) for i in order)
    return FrameTable(names=names, source_index=src, path=path, source_frame_count=_source_frame_count(path))


def _source_frame_count(frames_csv: Path) -> int | None:
    """Decoded frame count from frames.json beside frames.csv: key frames between extracted frames are valid."""
    summary = frames_csv.with_name("frames.json")
    if not summary.is_file():
        return None
    try:
        count = json.loads(summary.read_text()).get("decoded_frame_count")
    except (json.JSONDecodeError, AttributeError):
        return None
    return int(count) if isinstance(count, int) and count > 0 else None
