"""Commands and relevancy sources in the viewer: the project's grammar, the encoder only when needed."""

from __future__ import annotations

import pytest

from stages.language.object_resolution import UnknownObjectError
from stages.language.vocabulary import ObjectVocabulary
from stages.scene import InputError
from stages.viewer.language_controls import LanguageControls

PROMPTS = {"fridge": {"synonyms": ["refrigerator"], "description": "a tall white refrigerator"},
           "drawer": {"synonyms": ["top drawer"], "description": "the top drawer of a chest of drawers"}}


def _vocabulary() -> ObjectVocabulary:
    return ObjectVocabulary.from_prompts(["fridge", "drawer"], PROMPTS)


class CountingFactory:
    def __init__(self, encoder) -> None:
        self.encoder, self.calls = encoder, 0

    def __call__(self):
        self.calls += 1
        return self.encoder


def test_open_the_object_sets_its_slider_to_one_without_loading_a_text_model(bag_encoder):
    factory = CountingFactory(bag_encoder)
    controls = LanguageControls(_vocabulary(), factory)
    result = controls.command("open the fridge", {"fridge": 0.0, "drawer": 0.25})
    assert result.states == {"fridge": 1.0, "drawer": 0.25}
    assert controls.command("half open the refrigerator", result.states).states["fridge"] == 0.5
    assert controls.command("close everything", result.states).states == {"fridge": 0.0, "drawer": 0.0}
    assert factory.calls == 0 and not controls.encoder_loaded


def test_meaning_is_tried_only_when_names_fail_and_needs_an_encoder(bag_encoder):
    with pytest.raises(UnknownObjectError, match="chest of drawers"):
        LanguageControls(_vocabulary(), None).command("open the chest of drawers", {})
    factory = CountingFactory(bag_encoder)
    controls = LanguageControls(_vocabulary(), factory)
    result = controls.command("open the chest of drawers", {})
    assert result.states == {"fridge": 0.0, "drawer": 1.0} and result.actions[0].method == "embedding"
    controls.command("open the chest of drawers", {})
    assert factory.calls == 1  # built once
    with pytest.raises(UnknownObjectError, match="toaster"):
        controls.command("open the toaster", {})


def test_relevancy_sources_follow_what_the_run_renders(bag_encoder):
    plain = LanguageControls(_vocabulary(), lambda: bag_encoder)
    assert plain.sources() == ["probs"]
    plain.check_source("probs")
    with pytest.raises(InputError, match=r"renders no language embedding.*--language-targets"):
        plain.check_source("language")
    with pytest.raises(InputError, match="unknown source"):
        plain.check_source("colour")
    trained = LanguageControls(_vocabulary(), lambda: bag_encoder, renders_language=True, run_encoder="minilm")
    assert trained.sources() == ["probs", "language", "language_objects"]
    with pytest.raises(InputError, match=r"trained with encoder 'minilm'.*--encoder"):
        trained.check_source("language")
    same = LanguageControls(_vocabulary(), lambda: bag_encoder, renders_language=True, run_encoder=bag_encoder.name)
    same.check_source("language_objects")


def test_without_an_encoder_a_relevancy_query_says_how_to_get_one():
    with pytest.raises(InputError, match="--no-encoder"):
        LanguageControls(_vocabulary(), None).grounder()


def test_each_language_source_reaches_its_own_map(bag_encoder):
    """``language_objects`` decodes the embedding into object probabilities first; ``language`` is LERF's map."""
    import numpy as np

    controls = LanguageControls(_vocabulary(), lambda: bag_encoder, renders_language=True,
                                run_encoder=bag_encoder.name)
    fridge, drawer = bag_encoder.encode([PROMPTS["fridge"]["description"], PROMPTS["drawer"]["description"]])
    embedding = np.stack([np.tile(fridge, (2, 1)), np.tile(drawer, (2, 1))])  # [2, 2, D]: fridge row, drawer row
    grounder = controls.grounder()
    objects = controls.relevancy("refrigerator", "language_objects", {"language": embedding})
    lerf = controls.relevancy("refrigerator", "language", {"language": embedding})
    assert np.array_equal(objects, grounder.relevancy_from_language_objects(embedding, "refrigerator"))
    assert np.array_equal(lerf, grounder.relevancy_from_language(embedding, "refrigerator"))
    assert not np.allclose(objects, lerf)
    assert objects[0].min() > objects[1].max()  # the fridge's pixels are the refrigerator's
