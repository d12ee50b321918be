"""What every check gets through the ``ctx`` fixture: a scratch folder, the quick/full switch, the device
and thread count, and where the capture presets and the workflow checkout are (both given, never guessed
from the repository's layout, so that the checks run on an installed copy)."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path


@dataclass
class CaseContext:
    """Shared by the checks of one run (one ``livescene stability`` call or one pytest session)."""

    workdir: Path
    """Scratch folder; each check writes under its own sub-folders."""
    captures: Path
    """Folder of the capture presets (``stiff.yaml``, ...): the package's presets unless --captures names one."""
    quick: bool = False
    """Fewer steps and frames (the test suite and ``--quick``); the checks are the same."""
    device: str = "cpu"
    """Device of the training checks; the autocast checks also try CUDA when torch sees one."""
    threads: int = 1
    """torch CPU threads (1: the machines running this are shared, and 2 threads on a busy 2-core box are slower)."""
    workflow: Path | None = None
    """A checkout of the workflow (Snakefile, workflow/, config/), or None: the check that dry-runs it skips."""

    def __post_init__(self) -> None:
        self.workdir = Path(self.workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)

    @property
    def steps(self) -> int:
        """Training steps of a 'train briefly' check."""
        return 12 if self.quick else 60

    def folder(self, name: str) -> Path:
        """A fresh, empty folder under the workdir."""
        path = self.workdir / name
        if path.exists():
            shutil.rmtree(path)
        path.mkdir(parents=True)
        return path
