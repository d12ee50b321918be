"""Find the dataset a run was trained on: its config's ``data`` may be relative to where training ran.

The workflow trains from the repository root (``data: results/demo/dataset``), so a run opened from
elsewhere, or a results folder moved as a whole, must look for the path relative to the run's own
ancestors too (docs/export.md).
"""

from __future__ import annotations

from pathlib import Path

from stages.scene import InputError, SceneDataset, read_scene


def find_run_dataset(run_dir: str | Path, data: str | Path | None, override: str | Path | None = None) -> Path:
    """The dataset folder: ``override`` if given, else ``data`` as written, relative to the cwd or an ancestor."""
    if override:
        path = Path(override)
        if not (path / "transforms.json").is_file():
            raise InputError(path, "no transforms.json in the dataset given with --data",
                             "pass the scene dataset folder the run was trained on")
        return path
    if not data:
        raise InputError(Path(run_dir) / "config.yaml", "the run names no dataset", "pass --data DATASET")
    written = Path(data)
    candidates = [written] if written.is_absolute() else [
        written, *(parent / written for parent in Path(run_dir).resolve().parents)]
    for path in candidates:
        if (path / "transforms.json").is_file():
            return path
    raise InputError(Path(run_dir) / "config.yaml", f"the run's dataset {str(data)!r} is not found here "
                     "(nor relative to the run folder's parents)", "pass --data DATASET")


def read_run_dataset(run_dir: str | Path, data: str | Path | None, override: str | Path | None = None
                     ) -> SceneDataset:
    return read_scene(find_run_dataset(run_dir, data, override), validate=False)
