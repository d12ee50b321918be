"""Errors of the frames stage: each names the file, what is wrong with it and what to do."""

from __future__ import annotations

from stages.scene import InputError


class FrameSourceError(InputError):
    """A video or image folder that cannot give frames (missing, empty, unreadable, truncated)."""
