"""Relevancy maps from rendered per-object probabilities and from rendered embeddings."""

from __future__ import annotations

import numpy as np

from stages.language import Grounder, ObjectVocabulary


def _probs(h: int = 6, w: int = 9, n: int = 4) -> tuple[np.ndarray, np.ndarray]:
    labels = np.zeros((h, w), dtype=int)
    labels[:, 3:6] = 1
    labels[:, 6:] = 4  # background is the last channel
    labels[0, :] = 3
    probs = np.eye(n + 1)[labels] * 0.9 + 0.1 / (n + 1)
    return probs, labels


def test_query_selects_its_object_channel(kitchen, encoder):
    grounder = Grounder(kitchen, encoder)
    probs, labels = _probs()
    for query, index in [("fridge", 0), ("refrigerator", 0), ("wall cupboard", 1), ("kitchen drawer", 3)]:
        weights = grounder.object_weights(query)
        assert weights.argmax() == index and weights.sum() == np.float64(weights.sum())
        assert abs(weights.sum() - 1) < 1e-9
        rel = grounder.relevancy_from_probs(probs, query)
        assert rel.shape == labels.shape
        np.testing.assert_array_equal(rel > 0.5, labels == index)


def test_language_relevancy_prefers_pixels_that_carry_the_query(kitchen, encoder):
    grounder = Grounder(kitchen, encoder)
    fridge, background = encoder.encode(["open fridge", "background"])
    lang = np.stack([np.tile(fridge, (2, 3, 1)), np.tile(background, (2, 3, 1))]) * 3.0  # unnormalised on purpose
    rel = grounder.relevancy_from_language(lang, "fridge")
    assert rel.shape == (2, 2, 3)
    assert rel[0].min() > 0.5 > rel[1].max()


def test_language_decoded_into_objects_separates_related_objects(kitchen, encoder):
    """A half-open drawer's embedding is LERF-relevant to "cabinet" words, but decodes to the drawer alone."""
    grounder = Grounder(kitchen, encoder)
    closed, opened, background = encoder.encode(["closed drawer", "open drawer", "background"])
    drawer = (closed + opened) / 2
    lang = np.stack([np.tile(drawer, (2, 3, 1)), np.tile(background, (2, 3, 1))])
    probs = grounder.probs_from_language(lang)
    assert probs.shape == (2, 2, 3, len(kitchen.entries) + 1)
    np.testing.assert_allclose(probs.sum(-1), 1.0)
    assert (probs[0].argmax(-1) == 3).all() and (probs[1].argmax(-1) == len(kitchen.entries)).all()
    rel = grounder.relevancy_from_language_objects(lang, "kitchen drawer")
    assert rel[0].min() > 0.5 > rel[1].max()
    assert grounder.relevancy_from_language_objects(lang, "refrigerator").max() < 0.5


def test_a_name_selects_its_object_even_among_similar_names(encoder):
    # three drawers whose names differ by one word: by the softmax alone "top drawer" weighs ~0.6, so a pixel the
    # model is sure of would score ~0.6 and its neighbours' pixels ~0.2; a name selects its object alone
    vocabulary = ObjectVocabulary.from_prompts(
        ["top drawer", "middle drawer", "bottom drawer"],
        {"top drawer": {"synonyms": ["upper file drawer"]}}, "prompts.yaml")
    grounder = Grounder(vocabulary, encoder)
    for query, index in [("top drawer", 0), ("The Top-Drawer", 0), ("upper file drawer", 0), ("bottom drawer", 2)]:
        np.testing.assert_array_equal(grounder.object_weights(query), np.eye(3)[index])
    soft = grounder.object_weights("drawer")  # in every name: no object is named, the weights spread
    assert soft.max() < 0.9 and abs(soft.sum() - 1) < 1e-9
    probs = np.zeros((1, 3, 4))
    probs[0, :, :3] = np.eye(3) * 0.8
    probs[0, :, 3] = 0.2
    np.testing.assert_allclose(grounder.relevancy_from_probs(probs, "middle drawer"), [[0.0, 0.8, 0.0]])
