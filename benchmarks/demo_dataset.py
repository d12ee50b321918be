"""The `demo` capture and its truth scene dataset, generated once and cached in a work folder.

Shared by the benchmark scripts (run as ``python benchmarks/<name>.py``, so this folder is on sys.path).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# this checkout's code ahead of the venv's editable install, which points at whichever checkout installed it: a
# benchmark started in another worktree (a before/after comparison) must run that worktree's stages
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def cached_demo_dataset(work: Path, capture: Path | None = None) -> tuple[Path, Path]:
    """(capture folder, truth dataset folder) under ``work``; ``capture`` reuses an existing capture."""
    from stages.capture import capture_to_dataset, generate_capture, load_spec

    if capture is None:
        capture = work / "capture"
        if not (capture / "truth" / "transforms.json").is_file():
            generate_capture(load_spec(ROOT / "config" / "captures" / "demo.yaml"), capture)
    ds_dir = work / "dataset"
    if not (ds_dir / "transforms.json").is_file():
        capture_to_dataset(capture, ds_dir, split="alternate")
    return capture, ds_dir
