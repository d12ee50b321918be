"""The live viewer with a real client: viser's web page in headless Chromium, controls used like a user would.

What is checked is what the browser receives: a slider moved in the page brings a new image, equal to the
run's own render of that view and state; a language command typed into the page moves the slider; a relevancy
query replaces colour by the query's map.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from stages.viewer.frame_renderer import relevancy_colours, to_uint8

pytest.importorskip("viser")


class SentFrames:
    """Every frame the viewer sent, as the server rendered it (its request, image and size)."""

    def __init__(self, viewer) -> None:
        self.frames = []
        self._lock = threading.Lock()
        viewer.add_frame_listener(self._add)

    def _add(self, _client_id, frame) -> None:
        with self._lock:
            self.frames.append(frame)

    def finals(self, accept=lambda _f: True):
        with self._lock:
            return [f for f in self.frames if f.final and accept(f)]


@pytest.fixture(scope="module")
def sent(live_viewer):
    return SentFrames(live_viewer)


def _settle(viewer, page, sent, accept):
    """Wait until the still (full resolution) image of a request ``accept`` takes has reached the browser."""
    page.wait_until(lambda: bool(sent.finals(accept)), what="a full-resolution render of the new settings")
    frame = sent.finals(accept)[-1]
    page.wait_until(lambda: any(im.image.shape == frame.image.shape and np.array_equal(im.image, frame.image)
                                for im in page.images), what="the browser receiving that render")
    for session in viewer.sessions():
        assert session.loop.wait_idle(60)
    return frame


def _type(page, box, label: str, text: str) -> None:
    """Type into a text box and wait for the server to have it (viser's client sends text at most every 50 ms,
    a button click at once: a click right after the last key could reach the server first)."""
    page.type_text(label, text)
    page.wait_until(lambda: box.value == text, what=f"the server receiving {text!r}")


def _closed(viewer) -> dict[str, float]:
    return dict.fromkeys(viewer.objects, 0.0)


def test_moving_a_slider_in_the_page_brings_a_new_image(live_viewer, viser_page, viewer_scene, sent):
    viewer, page, name = live_viewer, viser_page, viewer_scene.visible
    j = viewer.objects.index(name)
    page.wait_for_control(name, "[role=slider]")
    viewer.show_colour()
    viewer.set_states(_closed(viewer))
    before = _settle(viewer, page, sent, lambda f: f.request.query is None and f.request.states[j] == 0.0)
    page.wait_until(lambda: page.slider_value(name) == 0.0, what="the page's slider at 0")

    page.slider_key(name, "End")  # the user drags the slider to "open"
    page.wait_until(lambda: viewer.states[name] == 1.0, what="the server seeing the slider at 1")
    after = _settle(viewer, page, sent, lambda f: f.request.query is None and f.request.states[j] == 1.0)

    assert after.resolution == before.resolution and after.resolution.pixels == 32 * 24
    received = next(im for im in page.images if np.array_equal(im.image, after.image))
    assert received.format == "png"  # the still image is sent lossless
    changed = np.abs(received.image.astype(int) - before.image.astype(int)).mean()
    assert changed > 2.0, f"the image barely changed ({changed:.2f} levels) when {name} opened"
    # the browser shows what the run API renders for that camera and state (docs/model.md)
    view = after.request.view
    expected = viewer_scene.run.render(view.camera(after.resolution.width, after.resolution.height), view.c2w,
                                       dict(zip(viewer.objects, after.request.states, strict=True)),
                                       outputs=("rgb",))["rgb"]
    assert np.abs(to_uint8(expected).astype(int) - received.image.astype(int)).max() <= 1


def test_a_language_command_typed_in_the_page_opens_the_object(live_viewer, viser_page, viewer_scene):
    viewer, page, name = live_viewer, viser_page, viewer_scene.visible
    viewer.set_states(_closed(viewer))
    page.wait_until(lambda: page.slider_value(name) == 0.0, what="the page's slider at 0")
    page.wait_for_control("Command", "input")

    _type(page, viewer.command_box, "Command", f"open the {name}")
    page.click_button("Apply command")
    page.wait_until(lambda: viewer.states[name] == 1.0, what=f'"open the {name}" reaching the slider')
    assert all(v == 0.0 for o, v in viewer.states.items() if o != name)
    page.wait_until(lambda: page.slider_value(name) == 1.0, what="the page's slider moving to 1")

    # a synonym from prompts.yaml, then everything closed
    _type(page, viewer.command_box, "Command", "open the cupboard")
    page.click_button("Apply command")
    page.wait_until(lambda: viewer.states["cabinet"] == 1.0, what='"open the cupboard" opening the cabinet')
    _type(page, viewer.command_box, "Command", "close everything")
    page.click_button("Apply command")
    page.wait_until(lambda: all(v == 0.0 for v in viewer.states.values()), what='"close everything"')

    # a command the grammar refuses leaves the states alone and says why
    _type(page, viewer.command_box, "Command", "open the toaster")
    page.click_button("Apply command")
    page.wait_until(lambda: "Not applied" in viewer.language_status.content, what="the refusal in the status line")
    assert "toaster" in viewer.language_status.content
    assert all(v == 0.0 for v in viewer.states.values())


def test_a_relevancy_query_shows_its_map_instead_of_colour(live_viewer, viser_page, viewer_scene, sent):
    viewer, page = live_viewer, viser_page
    viewer.set_states(_closed(viewer))
    page.wait_for_control("Relevancy query", "input")
    _type(page, viewer.query_box, "Relevancy query", "top drawer")
    page.click_button("Show relevancy")
    shown = _settle(viewer, page, sent, lambda f: f.request.query == "top drawer")

    size = shown.resolution
    rendered = viewer.renderer.render_outputs(shown.request, size)
    relevancy = viewer.language.relevancy("top drawer", "probs", rendered)
    assert relevancy.shape == (size.height, size.width)
    received = next(im for im in page.images if np.array_equal(im.image, shown.image))
    assert np.array_equal(received.image, relevancy_colours(relevancy))

    page.click_button("Show colour")
    colour = _settle(viewer, page, sent, lambda f: f.request.query is None and f.request.serial > shown.request.serial)
    assert np.abs(colour.image.astype(int) - shown.image.astype(int)).mean() > 2.0
