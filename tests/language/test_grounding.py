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


def test_unit_language_normalises_each_pixel_in_blocks(monkeypatch):
    """Each pixel's embedding to unit length in float64 (a zero one stays zero), block by block: the float64 copy,
    its squares and the quotient of a whole 960x540x384 view had been 4.8 GB at once (docs/language.md)."""
    import tracemalloc

    import stages.language.grounding as grounding

    monkeypatch.setattr(grounding, "UNIT_BLOCK", 64)
    lang = np.zeros((64, 64, 384), dtype=np.float32)
    lang[..., 0], lang[..., 1] = 3.0, 4.0  # |(3, 4)| = 5
    lang[0, 0] = 0.0
    tracemalloc.start()
    try:
        unit = Grounder.unit_language(lang)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert unit.dtype == np.float64 and unit.shape == (64, 64, 384)
    assert np.all(unit[..., 0].ravel()[1:] == 0.6) and np.all(unit[..., 1].ravel()[1:] == 0.8)
    assert not unit[0, 0].any() and not unit[..., 2:].any()
    # the result (64 x 64 x 384 float64: 12.6 MB) and a few blocks of 64 pixels; the whole-view way held three
    # arrays of the result's size at once
    assert peak < 1.5 * unit.nbytes, peak / unit.nbytes
