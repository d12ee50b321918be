"""The `demo` capture and its truth scene dataset, generated once and cached in a work folder.

Shared by the benchmark scripts (run as ``python benchmarks/<name>.py``, so this folder is on sys.path).
"""

from __future__ import annotations

from pathlib import Path

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)

ROOT = Path(__file__).resolve().parents[1]


DEMO_SPEC = ROOT / "config" / "captures" / "demo.yaml"


def cached_demo_dataset(work: Path, capture: Path | None = None, spec: Path = DEMO_SPEC) -> tuple[Path, Path]:
    """(capture folder, truth dataset folder) under ``work``; ``capture`` reuses an existing capture, else
    ``spec`` (the demo's by default) is rendered once into ``work``. A folder that already holds both needs no
    renderer (the GPU machine has no open3d: the work folder travels there ready)."""
    if capture is None:
        capture = work / "capture"
        if not (capture / "truth" / "transforms.json").is_file():
            from stages.capture import generate_capture, load_spec

            generate_capture(load_spec(spec), capture)
    ds_dir = work / "dataset"
    if not (ds_dir / "transforms.json").is_file():
        from stages.capture import capture_to_dataset

        capture_to_dataset(capture, ds_dir, split="alternate")
    return capture, ds_dir
