"""The frames labels are ingested for: a FRAMES folder (``images/`` + ``frames.csv``) or a plain image folder."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import pandas as pd

from stages.scene import frame_id_of, frame_number_of

from .errors import LabelError

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}


@dataclass
class FrameSet:
    """Frame ids and the image size every mask must have."""

    frame_ids: tuple[str, ...]
    """Frame ids (last ``_`` token of the image stem) in frame order."""
    height: int
    """Image height in pixels."""
    width: int
    """Image width in pixels."""
    root: Path
    """The folder the images were listed from."""
    image_names: tuple[str, ...] = ()
    """Image file names in frame order (aligned with ``frame_ids``)."""

    def __post_init__(self) -> None:
        self._ids = set(self.frame_ids)
        self._by_number = {int(f): f for f in self.frame_ids if f.isdigit()}

    @property
    def images(self) -> list[Path]:
        """Image paths in frame order."""
        return [self.root / n for n in self.image_names]

    def match(self, label_id: str) -> str | None:
        """The frame a label's id refers to: same id, or the same number (``frame_number_of``) when zero padding or
        the name's form differs (``IMG_4``, ``img4``, ``0004`` all name frame 4)."""
        if label_id in self._ids:
            return label_id
        number = frame_number_of(label_id)
        return None if number is None else self._by_number.get(number)


def read_frame_set(frames_dir: str | Path) -> FrameSet:
    """List the frames of a FRAMES folder; the size is read from its first image."""
    frames_dir = Path(frames_dir)
    image_dir = frames_dir / "images" if (frames_dir / "images").is_dir() else frames_dir
    if not image_dir.is_dir():
        raise LabelError(frames_dir, "frames folder not found", "pass the FRAMES folder of `livescene frames`")
    csv = frames_dir / "frames.csv"
    if csv.is_file():
        table = pd.read_csv(csv)
        if "frame" not in table.columns:
            raise LabelError(csv, "no 'frame' column", "write frames.csv with `livescene frames`")
        names = [str(n) for n in table["frame"]]
    else:
        names = sorted(p.name for p in image_dir.iterdir()
                       if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))
    if not names:
        raise LabelError(image_dir, "no images (.png/.jpg) found", "extract frames with `livescene frames` first")
    first = image_dir / names[0]
    img = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise LabelError(first, "image missing or unreadable", "re-extract the frames")
    ids = tuple(frame_id_of(Path(n).stem) for n in names)
    return FrameSet(frame_ids=ids, height=int(img.shape[0]), width=int(img.shape[1]), root=image_dir,
                    image_names=tuple(names))
