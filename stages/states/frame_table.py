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
    source_indices: frozenset[int] | None = None
    """An image folder's frame numbers (frames.json), extracted or not; None for a video (0 .. count - 1)."""

    def in_source(self, index: int) -> bool:
        """Whether ``index`` is a frame of the source, extracted or not."""
        if self.source_indices is not None:
            return index in self.source_indices
        if self.source_frame_count is None:
            return bool((self.source_index == index).any())
        return 0 <= index < self.source_frame_count

    def describe_source(self) -> str:
        """What ``in_source`` accepts, for a message."""
        if self.source_indices is not None:
            return (f"the image folder's names number its {len(self.source_indices)} images "
                    f"{min(self.source_indices)}..{max(self.source_indices)}")
        if self.source_frame_count:
            return f"the source video has frames 0..{self.source_frame_count - 1}"
        return f"source indices {int(self.source_index[0])}..{int(self.source_index[-1])}"

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
    count, indices = _source_frames(path)
    return FrameTable(names=names, source_index=src, path=path, source_frame_count=count, source_indices=indices)


def _source_frames(frames_csv: Path) -> tuple[int | None, frozenset[int] | None]:
    """(decoded frame count, an image folder's frame numbers) from frames.json beside frames.csv: key frames
    between extracted frames are valid."""
    summary = frames_csv.with_name("frames.json")
    if not summary.is_file():
        return None, None
    try:
        data = json.loads(summary.read_text())
        count, numbers = data.get("decoded_frame_count"), data.get("source_indices")
    except (json.JSONDecodeError, AttributeError):
        return None, None
    indices = frozenset(int(i) for i in numbers) if isinstance(numbers, list) and numbers else None
    if data.get("source_kind") == "images" and indices is None:
        return None, None  # written before frames.json listed an image folder's numbers: the extracted frames
    return (int(count) if isinstance(count, int) and count > 0 else None), indices
