"""Frames from a video or image folder: source index kept, sharpest frame per window, downscaled copies."""

from .config import FramesConfig
from .errors import FrameSourceError
from .extraction import DROPPED_CSV, extract_frames, frame_name
from .frame_source import DroppedFrame, ImageFolderSource, SourceFrame, VideoSource, open_source
from .integrity import bytes_problem, decode_image
from .selection import WindowRule, sharpest_per_window
from .sharpness import laplacian_variance

__all__ = [
    "DROPPED_CSV",
    "DroppedFrame",
    "FrameSourceError",
    "FramesConfig",
    "ImageFolderSource",
    "SourceFrame",
    "VideoSource",
    "WindowRule",
    "bytes_problem",
    "decode_image",
    "extract_frames",
    "frame_name",
    "laplacian_variance",
    "open_source",
    "sharpest_per_window",
]
