"""Writers for the small key-frame and frame-table files the states tests feed to `livescene states`."""

from __future__ import annotations

from pathlib import Path


def write_frames_csv(path: Path, indices: list[int]) -> Path:
    rows = ["frame,source_index,timestamp,sharpness"]
    rows += [f"frame_{i:05d}.png,{i},{i / 10:.1f},1.0" for i in indices]
    path.write_text("\n".join(rows) + "\n")
    return path


def write_text(path: Path, text: str) -> Path:
    path.write_text(text.lstrip("\n"))
    return path
