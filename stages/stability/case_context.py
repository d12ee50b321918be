"""What every case gets: a scratch folder, the quick/full switch, the device, and tiny scenes built once."""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch


@dataclass
class CaseContext:
    """Shared by the cases of one run (one ``livescene stability`` call or one pytest session)."""

    workdir: Path
    """Scratch folder; each case writes under its own sub-folder."""
    quick: bool = False
    """Fewer steps and frames (the pytest suite and ``--quick``); the checks are the same."""
    device: str = "cpu"
    """Device of the training cases; autocast cases also try CUDA when torch sees one."""
    threads: int = 1
    """torch CPU threads (1: the machines running this are shared, and 2 threads on a busy 2-core box are slower)."""
    _cache: dict[str, Any] = field(default_factory=dict)
    """Results of ``cached`` by key (scenes and runs several cases share)."""

    def __post_init__(self) -> None:
        self.workdir = Path(self.workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        torch.set_num_threads(max(self.threads, 1))

    @property
    def steps(self) -> int:
        """Training steps of a 'train briefly' case."""
        return 12 if self.quick else 60

    def folder(self, name: str) -> Path:
        """A fresh, empty folder under the workdir."""
        path = self.workdir / name
        if path.exists():
            shutil.rmtree(path)
        path.mkdir(parents=True)
        return path

    def cached(self, key: str, build: Any) -> Any:
        """``build()`` once per run; later cases reuse the result (they must copy before changing files)."""
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]

    def copy_of(self, src: Path, name: str) -> Path:
        """A private copy of a folder that a case may modify."""
        dst = self.workdir / name
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(src, dst)
        return dst
