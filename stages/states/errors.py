"""Errors of the states stage: the file (and row), the problem, the fix."""

from __future__ import annotations

from stages.scene.errors import InputError


class StateError(InputError):
    """Key-frame annotations, frame tables or options that cannot give a state for every frame."""
