"""Settings of the frames stage, one field per knob the CLI exposes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class FramesConfig:
    """Which frames to take from a video (or image folder) and where to write them."""

    source: Path
    """An OpenCV-readable video file, or a folder of images in playback order."""
    out_dir: Path
    """FRAMES folder to write (images/, optional images_2/ images_4/, frames.csv, frames.json)."""
    count: int | None = None
    """Keep about this many frames: the source is cut into ``count`` equal windows, one frame per window."""
    stride: int | None = None
    """Keep one frame per window of ``stride`` consecutive source frames (default 1 = every frame)."""
    downscale: tuple[int, ...] = field(default_factory=tuple)
    """Also write ``images_<f>/`` copies downscaled by each factor f (nerfstudio layout)."""
    max_side: int | None = None
    """Write the kept frames downscaled by the smallest integer factor that brings their longer side to at most
    this many pixels (integer, so masks and intrinsics of the full size map exactly); None keeps the size."""
    prefer: frozenset[int] = frozenset()
    """Source indices kept in their window over sharper frames (frames that carry a mask annotation)."""
    fps: float | None = None
    """Frame rate of an image folder (for timestamps); ignored for videos, which carry their own."""
    accept_truncated: bool = False
    """Keep the frames that decode when a video ends before its declared frame count (else an error)."""
    max_dropped: float = 0.5
    """Largest share of the source's frames that may be dropped as damaged (truncated or corrupt image files,
    video frames FFmpeg reports damaged); more is refused, and so is a source with no whole frame left."""
    progress: bool = True
    """Show a tqdm progress bar over the source frames."""
