"""The viewer's shared settings without a browser: sliders are clamped, unknown objects refused, one render per
command, and a run's states outside [0, 1] start the sliders at their ends."""

from __future__ import annotations

import numpy as np
import pytest

from stages.scene import InputError


def test_set_states_clamps_to_the_slider_range_and_renders_once(live_viewer, monkeypatch):
    refreshed = []
    monkeypatch.setattr(live_viewer, "refresh", lambda: refreshed.append(1))
    live_viewer.set_states({"cabinet": 1.7, "drawer": -0.4})
    assert live_viewer.states == {"cabinet": 1.0, "drawer": 0.0}
    assert live_viewer.sliders["cabinet"].value == 1.0 and live_viewer.sliders["drawer"].value == 0.0
    assert live_viewer.settings()[0] == (1.0, 0.0)
    live_viewer.set_states({"cabinet": 0.31, "drawer": 0.42})  # two sliders move: one render, not one each
    assert refreshed == [1, 1]
    with pytest.raises(InputError, match=r"unknown objects \['toaster'\]"):
        live_viewer.set_states({"toaster": 1.0})
    assert live_viewer.states == {"cabinet": 0.31, "drawer": 0.42}
    live_viewer.set_states({"cabinet": 0.0, "drawer": 0.0})


def test_the_sliders_start_inside_0_to_1_whatever_the_run_says(viewer_scene):
    pytest.importorskip("viser")
    from stages.language.vocabulary import ObjectVocabulary
    from stages.viewer.language_controls import LanguageControls
    from stages.viewer.server import LiveViewer, ViewerOptions

    class Beyond:  # the tiny run, its learned states past both ends
        def state_vector(self, *args, **kwargs):
            return np.array([-0.3, 1.4])

        def __getattr__(self, name):
            return getattr(viewer_scene.run, name)

    ds = viewer_scene.dataset
    language = LanguageControls(ObjectVocabulary.from_prompts(ds.objects, ds.prompts), None)
    viewer = LiveViewer(Beyond(), ds, language, ViewerOptions(port=0, full_pixels=32 * 24, verbose=False))
    try:
        assert viewer.states == {"cabinet": 0.0, "drawer": 1.0}
        assert viewer.sliders["cabinet"].value == 0.0 and viewer.sliders["drawer"].value == 1.0
    finally:
        viewer.stop()
