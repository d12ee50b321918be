"""Fixtures of the viewer tests: a tiny trained run, a live viewer on a free port, the viser page in Chromium.

The run and the viewer are shared by a module's tests (training and starting Chromium take seconds on two
busy cores); each test sets the states it starts from.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_language_run import BagOfWordsEncoder
from viewer_fakes import make_viewer_run

from stages.language.vocabulary import ObjectVocabulary
from stages.model import load_run
from stages.scene import SceneDataset, read_scene


@dataclass
class ViewerScene:
    data: Path
    run_dir: Path
    dataset: SceneDataset
    run: object
    visible: str
    """The object whose state changes the start view the most (the one the tests move)."""


@pytest.fixture(scope="session")
def viewer_scene(tmp_path_factory) -> ViewerScene:
    data, run_dir = make_viewer_run(tmp_path_factory.mktemp("viewer"))
    run = load_run(run_dir)
    ds = read_scene(data)
    frame = ds.frames[0]
    closed = run.render(ds.camera, frame.c2w, [0.0] * len(run.objects), outputs=("rgb",))["rgb"]
    change = {}
    for name in run.objects:
        opened = run.render(ds.camera, frame.c2w, {name: 1.0}, outputs=("rgb",))["rgb"]
        change[name] = float(np.abs(opened - closed).mean() * 255)
    visible = max(change, key=change.get)
    assert change[visible] > 2.0, f"no object state changes the tiny run's image visibly: {change}"
    return ViewerScene(data, run_dir, ds, run, visible)


@pytest.fixture
def bag_encoder() -> BagOfWordsEncoder:
    return BagOfWordsEncoder()


@pytest.fixture(scope="module")
def live_viewer(viewer_scene):
    """A LiveViewer of the tiny run on a free port (32x24 renders), with the bag-of-words encoder."""
    pytest.importorskip("viser")
    from stages.viewer.language_controls import LanguageControls
    from stages.viewer.server import LiveViewer, ViewerOptions

    torch.set_num_threads(1)
    ds = viewer_scene.dataset
    language = LanguageControls(ObjectVocabulary.from_prompts(ds.objects, ds.prompts), BagOfWordsEncoder)
    viewer = LiveViewer(viewer_scene.run, ds, language,
                        ViewerOptions(port=0, full_pixels=32 * 24, settle_s=0.2, chunk_rays=256, thumbnails=True,
                                      verbose=False))
    try:
        yield viewer
    finally:
        viewer.stop()


@pytest.fixture(scope="module")
def viser_page(live_viewer, tmp_path_factory):
    """The viewer's page in headless Chromium at 640x480 (a 4:3 canvas: full renders are 32x24)."""
    from chromium_page import Chromium
    from viser_browser import ViserPage

    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    if binary is None:
        pytest.skip("Debian chromium is not installed (apt-get install chromium)")
    browser = Chromium(binary, tmp_path_factory.mktemp("chromium-profile"))
    try:
        browser.open_page()
        page = ViserPage(browser, live_viewer.url)
        # pumping DevTools events lets the paused websocket worker start (see ViserPage)
        page.wait_until(lambda: len(live_viewer.sessions()) >= 1, timeout=90, what="the page connecting")
        yield page
    finally:
        browser.close()
