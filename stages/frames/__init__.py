"""Frames from a video or image folder: source index kept, sharpest frame per window, downscaled copies."""

from .config import FramesConfig
from .errors import FrameSourceError
from .extraction import extract_frames, frame_name
from .frame_source import ImageFolderSource, SourceFrame, VideoSource, open_source
from .selection import WindowRule, sharpest_per_window
from .sharpness import laplacian_variance

__all__ = [
    "FrameSourceError",
    "FramesConfig",
    "ImageFolderSource",
    "SourceFrame",
    "VideoSource",
    "WindowRule",
    "extract_frames",
    "frame_name",
    "laplacian_variance",
    "open_source",
    "sharpest_per_window",
]
