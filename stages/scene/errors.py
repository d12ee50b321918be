"""Error types with messages a user can act on: the file, the problem, the fix."""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad input rejected at a stage boundary.

    The message always reads ``<file>: <problem>; <fix>`` so that a user sees
    which file to look at and what to do about it.
    """

    def __init__(self, path: str | Path, problem: str, fix: str) -> None:
        self.path = Path(path)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.path}: {problem}; fix: {fix}")


class SceneError(InputError):
    """A scene dataset that violates the contract of ``stages.scene``."""
