"""Which source frames to keep: one per window, the sharpest.

Windows are consecutive runs of source indices, so the kept frames stay
spread over the whole capture (even coverage for structure from motion)
while a blurred frame is replaced by a sharper neighbour.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from stages.scene import frame_number_of


@dataclass(frozen=True)
class WindowRule:
    """Maps a source position (0 .. n_total-1) to its window number."""

    n_total: int
    """Frames in the source."""
    n_windows: int
    """Windows the source is cut into (= frames kept)."""
    stride: int | None
    """Window length for the stride rule; None for the count rule (equal split of n_total)."""
    of_declared: int | None = None
    """A truncated video's declared length, when the windows were cut again over the frames that decode."""

    @classmethod
    def from_options(cls, n_total: int, count: int | None, stride: int | None,
                     of_declared: int | None = None) -> WindowRule:
        if count is not None and stride is not None:
            raise ValueError("give either count or stride, not both")
        if count is not None:
            if count < 1:
                raise ValueError(f"count must be >= 1, got {count}")
            return cls(n_total=n_total, n_windows=min(count, n_total), stride=None, of_declared=of_declared)
        stride = 1 if stride is None else stride
        if stride < 1:
            raise ValueError(f"stride must be >= 1, got {stride}")
        return cls(n_total=n_total, n_windows=-(-n_total // stride), stride=stride)

    def window(self, position: int) -> int:
        """Window of the frame at ``position`` (its rank in playback order)."""
        if self.stride is not None:
            return position // self.stride
        return position * self.n_windows // self.n_total

    def describe(self) -> str:
        if self.stride == 1:
            return "every frame"
        if self.stride is not None:
            return f"sharpest frame in each window of {self.stride} consecutive frames"
        decoded = f" (of {self.of_declared} declared: the video ends early)" if self.of_declared else ""
        return f"sharpest frame in each of {self.n_windows} equal windows over {self.n_total} frames{decoded}"


def sharpest_per_window(sharpness: list[float], rule: WindowRule) -> list[int]:
    """Positions kept by ``rule``: in each window the sharpest frame (the earliest on ties)."""
    best: dict[int, int] = {}
    for position, score in enumerate(sharpness):
        w = rule.window(position)
        if w not in best or score > sharpness[best[w]]:
            best[w] = position
    return [best[w] for w in sorted(best)]


def downscale_factor(width: int, height: int, max_side: int | None) -> int:
    """Smallest integer factor that brings the longer side to at most ``max_side`` (1 without a limit)."""
    if not max_side:
        return 1
    return max(1, -(-max(width, height) // max_side))


def scaled_size(width: int, height: int, factor: int) -> tuple[int, int]:
    """(width, height) of an image downscaled by ``factor`` (OpenCV's order; at least one pixel)."""
    return max(1, round(width / factor)), max(1, round(height / factor))


def indices_named_in(annotations: Path) -> frozenset[int]:
    """Source indices that mask annotations name, as the labels stage reads them (``frame_number_of``): the files
    of a mask folder (frame_00012.png, 0012.npy, IMG_0012.png, img12.png, LabelMe's one .json per image), those of
    its ``masks/`` subfolder or of one folder per object, or the images of a COCO file; hidden files left out."""
    annotations = Path(annotations)
    if annotations.is_file():
        return _image_numbers(_read_json(annotations))
    folders = [annotations, annotations / "masks", *(d for d in annotations.iterdir()
                                                      if d.is_dir() and not d.name.startswith("."))]
    numbers = set()
    for folder in (f for f in folders if f.is_dir()):
        files = [p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")]
        jsons = [p for p in files if p.suffix.lower() == ".json"]
        data = _read_json(jsons[0]) if folder == annotations and len(jsons) == 1 else None
        if isinstance(data, dict) and isinstance(data.get("images"), list):  # a COCO file in its folder
            numbers |= _image_numbers(data)
            files.remove(jsons[0])
        numbers |= {n for n in (frame_number_of(p.stem) for p in files) if n is not None}
    return frozenset(numbers)


def _read_json(path: Path) -> Any:
    """The content of a JSON file, or None when unreadable (the labels stage then names the problem)."""
    try:
        return json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None


def _image_numbers(data: Any) -> frozenset[int]:
    """Frame numbers of the images a COCO file's content annotates (a LabelMe file's: of its image)."""
    if not isinstance(data, dict):
        return frozenset()
    names = [img.get("file_name") for img in data.get("images", []) if isinstance(img, dict)]
    if isinstance(data.get("imagePath"), str):  # LabelMe
        names.append(data["imagePath"])
    numbers = (frame_number_of(Path(str(n)).stem) for n in names if n)
    return frozenset(n for n in numbers if n is not None)
