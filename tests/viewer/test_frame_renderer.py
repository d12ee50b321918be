"""FrameRenderer on a real (tiny) run: the image of the run API, cut short on request, relevancy in colour."""

from __future__ import annotations

import numpy as np
import pytest

from stages.language.vocabulary import ObjectVocabulary
from stages.viewer.frame_renderer import FrameRenderer, relevancy_colours, to_uint8
from stages.viewer.language_controls import LanguageControls
from stages.viewer.render_loop import RenderCancelled, RenderRequest
from stages.viewer.resolution import Resolution
from stages.viewer.view_camera import ViewPose, vertical_fov, viser_pose


class CountingRun:
    """The run, counting render_rays calls."""

    def __init__(self, run) -> None:
        self.run, self.calls = run, 0

    def render_rays(self, *args, **kwargs):
        self.calls += 1
        return self.run.render_rays(*args, **kwargs)


def _frame_view(scene) -> ViewPose:
    frame = scene.dataset.frames[1]
    camera = scene.dataset.camera_of(frame)
    wxyz, position = viser_pose(frame.c2w)  # as a client placed on the frustum reports it
    return ViewPose.from_viser(wxyz, position, vertical_fov(camera), camera.width / camera.height)


def test_the_image_is_the_run_apis_render_of_that_camera(viewer_scene):
    run, view = viewer_scene.run, _frame_view(viewer_scene)
    states = (0.3, 0.8)
    renderer = FrameRenderer(run, None, chunk_rays=100)  # chunks that do not divide the image
    size = Resolution(40, 30)
    image = renderer(RenderRequest(view=view, states=states), size, lambda: False)
    assert image.shape == (30, 40, 3) and image.dtype == np.uint8
    expected = run.render(view.camera(40, 30), view.c2w, dict(zip(run.objects, states, strict=True)),
                          outputs=("rgb",))["rgb"]
    assert np.abs(image.astype(int) - to_uint8(expected).astype(int)).max() <= 1
    # the states reach the model: the visible object's state changes the image
    j = run.objects.index(viewer_scene.visible)
    other = list(states)
    other[j] = 1.0 - states[j]
    changed = renderer(RenderRequest(view=view, states=tuple(other)), size, lambda: False)
    assert np.abs(changed.astype(int) - image.astype(int)).mean() > 1.0


def test_a_render_stops_between_chunks_when_told(viewer_scene):
    counting = CountingRun(viewer_scene.run)
    renderer = FrameRenderer(counting, None, chunk_rays=100)
    asked = []

    def stop_after_two_chunks() -> bool:
        asked.append(1)
        return len(asked) > 2

    with pytest.raises(RenderCancelled):
        renderer(RenderRequest(view=_frame_view(viewer_scene), states=(0.0, 0.0)), Resolution(40, 30),
                 stop_after_two_chunks)
    assert counting.calls == 2  # 12 chunks in all: the rest were never rendered


def test_a_relevancy_query_renders_its_map_in_the_turbo_colours(viewer_scene, bag_encoder):
    ds = viewer_scene.dataset
    language = LanguageControls(ObjectVocabulary.from_prompts(ds.objects, ds.prompts), lambda: bag_encoder)
    renderer = FrameRenderer(viewer_scene.run, language, chunk_rays=500)
    request = RenderRequest(view=_frame_view(viewer_scene), states=(0.0, 1.0), query="top drawer", source="probs")
    assert renderer.outputs_for(request) == ("probs",)
    image = renderer(request, Resolution(32, 24), lambda: False)
    probs = renderer.render_outputs(request, Resolution(32, 24))["probs"]
    relevancy = language.grounder().relevancy_from_probs(probs, "top drawer")
    assert np.array_equal(image, relevancy_colours(relevancy))
    # the map is the drawer's probability: the query names the drawer
    j = viewer_scene.run.objects.index("drawer")
    assert np.corrcoef(relevancy.ravel(), probs[..., j].ravel())[0, 1] > 0.99


def test_the_language_source_maps_the_rendered_embedding(viewer_scene, bag_encoder):
    ds, run = viewer_scene.dataset, viewer_scene.run
    assert run.language_encoder == bag_encoder.name  # the fixture's run has a language table
    language = LanguageControls(ObjectVocabulary.from_prompts(ds.objects, ds.prompts), lambda: bag_encoder,
                                renders_language=True, run_encoder=run.language_encoder)
    renderer = FrameRenderer(run, language, chunk_rays=500)
    request = RenderRequest(view=_frame_view(viewer_scene), states=(1.0, 0.0), query="cupboard", source="language")
    assert renderer.outputs_for(request) == ("language",)
    image = renderer(request, Resolution(32, 24), lambda: False)
    embedding = renderer.render_outputs(request, Resolution(32, 24))["language"]
    assert embedding.shape[:2] == (24, 32)
    assert np.array_equal(image, relevancy_colours(language.grounder().relevancy_from_language(embedding, "cupboard")))


def test_relevancy_colours_run_from_blue_to_red():
    colours = relevancy_colours(np.array([[0.0, 1.0]]))
    low, high = colours[0, 0].astype(int), colours[0, 1].astype(int)
    assert low[2] > low[0] and high[0] > high[2]


def test_colours_are_rounded_to_the_nearest_level():
    """As `livescene render` writes rgb.png: a still view is the run's render pixel for pixel."""
    levels = to_uint8(np.array([0.5, 0.999, 0.2, 1.5, -0.2, 1.0, 0.0], dtype=np.float32))
    assert levels.tolist() == [128, 255, 51, 255, 0, 255, 0]  # 127.5 -> 128, 254.7 -> 255
