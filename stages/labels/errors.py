"""Errors of the labels stage: the file, the problem, the fix."""

from __future__ import annotations

from stages.scene.errors import InputError


class LabelError(InputError):
    """Object masks (or their name table) that cannot be ingested as given."""
