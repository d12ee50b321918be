"""Embedding matches, grounding weights and decoded probabilities with vectors chosen by the test (TableEncoder).

Every expected number is computed by hand from the chosen vectors: the embedding gates of object resolution
(cosine >= 0.6, softmax probability >= 0.7 at temperature 10, LERF relevancy > 0.5), and what a Grounder
weighs and decodes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stages.language import (
    AmbiguousObjectError,
    CommandParser,
    Grounder,
    ObjectVocabulary,
    UnknownObjectError,
    normalize_rows,
    softmax,
)
from tests.language.table_encoder import TableEncoder, unit


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


VOCABULARY = {"fridge": {"description": "cold box"}}
VECTORS = {
    "fridge": unit(1.0),
    "drawer": unit(0.0, 1.0),
    "cold box": unit(0.0, 0.0, 1.0),  # the fridge's description
    "icebox": unit(0.8, 0.0, 0.0, 0.6),  # cosine 0.8 to "fridge", 0 to "drawer"
    "chiller": unit(0.5, 0.0, 0.0, math.sqrt(0.75)),  # cosine 0.5 to "fridge": under the 0.6 a match needs
    "cool cupboard": unit(0.7, 0.65, 0.0, math.sqrt(1 - 0.7**2 - 0.65**2)),  # 0.7 and 0.65: probability 0.62
    "frosty": unit(0.0, 0.0, 1.0),  # the description's vector, no name's
}


def _parser(vectors=VECTORS) -> CommandParser:
    vocabulary = ObjectVocabulary.from_prompts(["fridge", "drawer"], VOCABULARY)
    return CommandParser(vocabulary, TableEncoder(vectors))


def test_a_meaning_match_passes_every_gate_and_scores_its_probability():
    result = _parser().parse("open the icebox")
    assert result.states == {"fridge": 1.0, "drawer": 0.0}
    # softmax over (0.8, 0) at temperature 10
    assert [(a.method, a.score) for a in result.actions] == [("embedding", pytest.approx(_sigmoid(8.0), rel=1e-9))]


def test_a_description_is_matched_by_meaning():
    assert _parser().parse("open the frosty").states == {"fridge": 1.0, "drawer": 0.0}


def test_a_cosine_under_the_least_similarity_is_unknown():
    with pytest.raises(UnknownObjectError, match=r'unknown object "chiller".*fridge \(spelling .*, cosine 0\.50'):
        _parser().parse("open the chiller")


def test_two_close_meanings_under_the_least_probability_are_ambiguous():
    with pytest.raises(AmbiguousObjectError, match=r"fridge \(0\.62, cosine 0\.70\), drawer \(0\.38, cosine 0\.65\)"):
        _parser().parse("open the cool cupboard")


def test_a_winner_no_more_relevant_than_a_canonical_negative_is_unknown():
    # "object" at cosine 0.9 to the fridge's name: relevancy sigmoid(10 (0.8 - 0.9)) = 0.27 < 0.5
    vectors = {**VECTORS, "object": unit(0.9, 0.0, 0.0, 0.0, math.sqrt(0.19))}
    vocabulary = ObjectVocabulary.from_prompts(["fridge", "drawer"], {})
    with pytest.raises(UnknownObjectError, match=r'unknown object "icebox".*fridge \(spelling .*, cosine 0\.80'):
        CommandParser(vocabulary, TableEncoder(vectors)).parse("open the icebox")


GROUNDING_VECTORS = {
    **VECTORS,
    "closed fridge": unit(0, 0, 0, 1.0),
    "open fridge": unit(0, 0, 0, 0, 1.0),
    "closed drawer": unit(0, 0, 0, 0, 0, 1.0),
    "open drawer": unit(0, 0, 0, 0, 0, 0, 1.0),
    "background": unit(0, 0, 0, 0, 0, 0, 0, 1.0),
}
"""Every phrase of the table on an axis of its own; unknown phrases (the negatives, "fridg") on the last axis."""


@pytest.fixture
def grounder() -> Grounder:
    vectors = {k: np.r_[v, 0.0, 0.0] for k, v in GROUNDING_VECTORS.items()}  # 10 dims: axis 9 is the unknown's
    return Grounder(ObjectVocabulary.from_prompts(["fridge", "drawer"], VOCABULARY), TableEncoder(vectors, dim=10))


def test_a_misspelt_name_is_weighed_by_meaning_not_selected(grounder):
    # "fridg" is no name in words: its vector (orthogonal to every phrase) is equally near both objects
    np.testing.assert_allclose(grounder.object_weights("fridg"), [0.5, 0.5], rtol=1e-12)


def test_a_description_weighs_its_object_and_query_match_names_it(grounder):
    # cosine 1 to the fridge's description, 0 to every drawer phrase: softmax of (10, 0)
    expected = [_sigmoid(10.0), 1 - _sigmoid(10.0)]
    np.testing.assert_allclose(grounder.object_weights("frosty"), expected, rtol=1e-12)
    match = grounder.query_match("frosty")
    assert (match["object"], match["by"], match["best_cosine"]) == ("fridge", "meaning", 1.0)


def test_probabilities_are_renormalised_and_need_the_background_channel(grounder):
    probs = np.array([[[2.0, 0.0, 2.0], [0.0, 1.0, 3.0]]])  # fridge, drawer, background: sums 4 and 4
    np.testing.assert_allclose(grounder.relevancy_from_probs(probs, "fridge"), [[0.5, 0.0]], rtol=1e-12)
    with pytest.raises(ValueError, match="expected 2 objects \\+ background"):
        grounder.relevancy_from_probs(probs[..., :2], "fridge")


def test_an_embedding_decodes_to_the_object_of_its_state_phrase(grounder):
    # a closed drawer's phrase, three times too long: renormalised, cosine 1 to "closed drawer", 0 elsewhere
    closed_drawer = 3.0 * np.r_[GROUNDING_VECTORS["closed drawer"], 0.0, 0.0]
    probs = grounder.probs_from_language(closed_drawer[None, None])
    e = math.exp(10.0)
    np.testing.assert_allclose(probs[0, 0], [1 / (e + 2), e / (e + 2), 1 / (e + 2)], rtol=1e-9)


def test_softmax_is_stable_and_zero_rows_stay_zero():
    np.testing.assert_array_equal(softmax(np.array([100.0, 0.0])), [1.0, 0.0])  # exp(1000) would overflow
    np.testing.assert_allclose(normalize_rows(np.array([[0.0, 0.0], [3.0, 4.0]])), [[0.0, 0.0], [0.6, 0.8]], rtol=1e-6)


def test_a_runner_up_farther_than_the_gap_leaves_the_phrase_unknown_not_ambiguous():
    # cosines 0.7, 0.58, 0.58: probability 1 / (1 + 2 exp(-1.2)) = 0.62 < 0.7, and the others 0.12 behind (gap 0.1)
    vectors = {
        "fridge": unit(0.7, math.sqrt(1 - 0.7**2)),
        "drawer": unit(0.58, 0.0, math.sqrt(1 - 0.58**2)),
        "oven": unit(0.58, 0.0, 0.0, math.sqrt(1 - 0.58**2)),
        "cold": unit(1.0),
    }
    vocabulary = ObjectVocabulary.from_prompts(["fridge", "drawer", "oven"], {})
    with pytest.raises(
        UnknownObjectError,
        match=r'unknown object "cold".*fridge \(spelling .*, cosine 0\.70, '
        r"probability 0\.62\)",
    ):
        CommandParser(vocabulary, TableEncoder(vectors)).parse("open the cold")
