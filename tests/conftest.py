"""Fixtures shared by every stage's tests: tiny scene datasets built at test time."""

from __future__ import annotations

import os

# Before anything loads torch: OpenMP threads sleep at barriers instead of spinning (docs/model.md), as in
# every `livescene` command; pytest shares its 2 cores with the subprocesses the tests start.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from chromium_page import Chromium

from stages.scene import Camera, Frame, SceneDataset, label_map_to_onehot, look_at, write_mask, write_scene


def make_tiny_dataset(root: Path, n_frames: int = 6, n_objects: int = 3, width: int = 16, height: int = 12,
                      seed: int = 0) -> SceneDataset:
    """A multi-object scene dataset with random images, masks and states (not a rendering)."""
    rng = np.random.default_rng(seed)
    names = [f"object{i}" for i in range(n_objects)]
    camera = Camera(fx=20.0, fy=21.0, cx=width / 2, cy=height / 2, width=width, height=height)
    frames = []
    (root / "images").mkdir(parents=True, exist_ok=True)
    for i in range(n_frames):
        angle = 2 * np.pi * i / n_frames
        c2w = look_at(np.array([3 * np.cos(angle), 3 * np.sin(angle), 1.0]), np.zeros(3))
        fid = f"{i:05d}"
        path = f"images/frame_{fid}.png"
        cv2.imwrite(str(root / path), rng.integers(0, 255, (height, width, 3), dtype=np.uint8))
        labels = rng.integers(0, n_objects + 1, (height, width))
        write_mask(root, fid, label_map_to_onehot(labels, n_objects))
        state = {n: float(rng.random()) for n in names}
        frames.append(Frame(file_path=path, c2w=c2w, state=state, split="test" if i % 2 == 0 else "train",
                            source_index=i))
    ds = SceneDataset(root=root, camera=camera, frames=frames, objects=names, object_ids=[1, 2, 3][:n_objects],
                      key_frames={"00000": {names[0]: 0.0}, "00004": {names[0]: 1.0}},
                      scene_box=np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]),
                      prompts={names[0]: {"synonyms": ["thing zero"], "description": "the first object"}},
                      meta={"units": "m"})
    write_scene(ds, root)
    return ds


@pytest.fixture
def tiny_dataset(tmp_path: Path) -> SceneDataset:
    return make_tiny_dataset(tmp_path / "scene")


@pytest.fixture
def chromium(tmp_path: Path):
    """A headless Chromium page (report pages are loaded in it); skipped where Debian's chromium is missing."""
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    if binary is None:
        pytest.skip("Debian chromium is not installed (apt-get install chromium)")
    browser = Chromium(binary, tmp_path / "chromium-profile")
    try:
        browser.open_page()
        yield browser
    finally:
        browser.close()


@pytest.fixture(scope="session")
def tiny_bench_work(tmp_path_factory):
    """One --work folder for the smoke runs of the stage benchmarks: the tiny capture, its frames and dataset are
    made once by the first of them and read by the others."""
    return tmp_path_factory.mktemp("bench-tiny")
