"""Grounding: a text query -> a relevancy map over a rendered view.

Two sources of evidence, after docs/method.md section 7:

- ``probs`` (every run): a query that names one object in words (its name or a
  synonym, also inside a longer phrase: "the fridge door") selects that object
  (weight 1, as ``livescene control`` resolves it); any other query
  is scored against each object's phrases (name, synonyms, description, state
  phrases) and a softmax over objects with temperature 10 gives the weights
  ``w``. The map is ``sum_i w_i p_i(pixel)`` with ``p`` the model's rendered
  per-object interaction probability: for a name, that object's probability, as
  in the reference; otherwise it spreads over the plausible objects. (By the
  softmax alone, "top drawer" among a middle and a bottom drawer weighs only
  0.56, and the map scores how alike the names are, not the model.)
- ``language`` (runs trained with language targets): LERF relevancy of the
  rendered embedding of each pixel against the query, with the canonical
  negatives "object", "things", "stuff", "texture" and temperature 10. This is
  the open-vocabulary map; with a text-only table it also lights up objects
  whose phrases are merely related ("drawer" vs "cabinet").
- ``language_objects`` (same runs): the rendered embedding is decoded into
  per-object probabilities against the table's own phrases (each object's
  state phrases and the background phrase, softmax with temperature 10), then
  weighted by the query's object weights as for ``probs``. The closed-set map,
  like the reference's softmax over the table entries.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .encoder import TextEncoder
from .object_resolution import CommandError, ObjectResolver, ResolverConfig
from .relevancy import CANONICAL_NEGATIVES, TEMPERATURE, lerf_relevancy, object_similarities, softmax
from .targets import BACKGROUND_PHRASE
from .vocabulary import ObjectVocabulary, normalize_phrase

DEFAULT_THRESHOLD = 0.5
NAMING_METHODS = ("exact", "partial")
"""Resolutions by which a query names its object in words; misspellings and meanings are weighed by the softmax."""
UNIT_BLOCK = 16384
"""Pixels per block of ``Grounder.unit_language`` (16384 x 384 float64: 48 MiB)."""


class Grounder:
    """Scores queries against one scene's objects and turns rendered outputs into relevancy maps."""

    def __init__(self, vocabulary: ObjectVocabulary, encoder: TextEncoder, temperature: float = TEMPERATURE) -> None:
        self.vocabulary = vocabulary
        self.encoder = encoder
        self.temperature = temperature
        self._resolver = ObjectResolver(vocabulary)  # words only: no encoder
        self._object_vectors = [encoder.encode(self.object_phrases(i)) for i in range(len(vocabulary.entries))]
        self._negatives = encoder.encode(list(CANONICAL_NEGATIVES))
        self._table_vectors: list[np.ndarray] | None = None

    def table_vectors(self) -> list[np.ndarray]:
        """Per object ``[2, D]`` embeddings of its closed and open state phrases, then ``[1, D]`` the background's.

        The same phrases ``build_targets`` embeds at the default levels 0 and 1, so a rendered embedding of the
        table lies between an object's two rows.
        """
        if self._table_vectors is None:
            rows = [self.encoder.encode([e.state_phrase(0.0), e.state_phrase(1.0)]) for e in self.vocabulary.entries]
            self._table_vectors = [*rows, self.encoder.encode([BACKGROUND_PHRASE])]
        return self._table_vectors

    def object_phrases(self, index: int) -> list[str]:
        e = self.vocabulary.entries[index]
        phrases = [*e.aliases, normalize_phrase(e.description), e.state_phrase(0.0), e.state_phrase(1.0)]
        return [p for p in dict.fromkeys(phrases) if p]

    def _named_object(self, query: str) -> str | None:
        """The object a query names in words (``ObjectResolver``'s exact and partial matches), else None."""
        try:
            named = self._resolver.resolve(query)
        except CommandError:  # no name in it, or several: the phrases' meaning decides
            return None
        return named.object if named.method in NAMING_METHODS else None

    def _cosines(self, query: str) -> np.ndarray:
        """``[alpha]``: the query's best cosine to each object's phrases."""
        return object_similarities(self.encoder.encode([query])[0], self._object_vectors)

    def object_weights(self, query: str) -> np.ndarray:
        """``[alpha]``: one-hot for a query that names one object in words (its name or a synonym, or one found in
        the query: ``ObjectResolver``'s exact and partial matches), else the softmax over objects (temperature 10)
        of the query's best cosine to each object's phrases."""
        named = self._named_object(query)
        if named is not None:
            return (np.array(self.vocabulary.objects) == named).astype(np.float64)
        return softmax(self._cosines(query), self.temperature)

    def query_match(self, query: str) -> dict[str, Any]:
        """What a query's map shows: the object it names in words, else whether its meaning is near enough an
        object's (the cosine a command needs, ``ResolverConfig.embedding_min_similarity``); the softmax behind
        ``object_weights`` always sums to 1, so a query that names nothing still lights up its nearest object."""
        objects = self.vocabulary.objects
        named = self._named_object(query)
        if named is not None:
            weights = (np.array(objects) == named).astype(np.float64)
            return {"object": named, "by": "name", "weights": dict(zip(objects, weights.tolist(), strict=True))}
        cosines = self._cosines(query)
        weights = softmax(cosines, self.temperature)
        best = int(np.argmax(cosines))
        near = float(cosines[best]) >= ResolverConfig().embedding_min_similarity
        return {"object": objects[best] if near else None, "by": "meaning" if near else None,
                "best_cosine": round(float(cosines[best]), 4),
                "weights": dict(zip(objects, weights.tolist(), strict=True))}

    def relevancy_from_probs(self, probs: np.ndarray, query: str) -> np.ndarray:
        """``[H, W]`` map from rendered per-object probabilities ``[H, W, alpha + 1]`` (background last)."""
        p = np.asarray(probs, dtype=np.float64)
        alpha = len(self.vocabulary.entries)
        if p.shape[-1] != alpha + 1:
            raise ValueError(f"probs has {p.shape[-1]} channels, expected {alpha} objects + background")
        p = p / np.maximum(p.sum(-1, keepdims=True), 1e-12)
        return p[..., :alpha] @ self.object_weights(query)

    @staticmethod
    def unit_language(language: np.ndarray) -> np.ndarray:
        """Rendered embeddings ``[H, W, D]`` in float64, each renormalised to unit length.

        Normalise once per view and pass the result to the ``*_unit_language`` methods of every query:
        each pass over a 256x192x384 float64 array takes ~0.1 s.
        """
        lang = np.asarray(language)
        out = np.empty(lang.shape, dtype=np.float64)
        # in blocks of pixels: the float64 copy, its squares and the quotient of a whole 960x540 view were 4.8 GB at
        # once; each pixel's vector is normalised alone, so the blocks give the same bits
        flat, flat_out = lang.reshape(-1, lang.shape[-1]), out.reshape(-1, lang.shape[-1])
        for a in range(0, len(flat), UNIT_BLOCK):
            block = flat[a:a + UNIT_BLOCK].astype(np.float64)
            flat_out[a:a + UNIT_BLOCK] = block / np.maximum(np.linalg.norm(block, axis=-1, keepdims=True), 1e-12)
        return out

    def relevancy_from_language(self, language: np.ndarray, query: str) -> np.ndarray:
        """``[H, W]`` LERF relevancy of rendered embeddings ``[H, W, D]`` (renormalised per pixel)."""
        return self.relevancy_from_unit_language(self.unit_language(language), query)

    def relevancy_from_unit_language(self, unit: np.ndarray, query: str) -> np.ndarray:
        """``relevancy_from_language`` of embeddings already passed through ``unit_language``."""
        q = self.encoder.encode([query])[0]
        return lerf_relevancy(unit, q, self._negatives, self.temperature)

    def probs_from_language(self, language: np.ndarray) -> np.ndarray:
        """``[H, W, alpha + 1]`` per-object probabilities decoded from rendered embeddings ``[H, W, D]``."""
        return self.probs_from_unit_language(self.unit_language(language))

    def probs_from_unit_language(self, unit: np.ndarray) -> np.ndarray:
        """``probs_from_language`` of embeddings already passed through ``unit_language``."""
        sims = np.stack([(unit @ v.T).max(-1) for v in self.table_vectors()], axis=-1)
        return softmax(sims, self.temperature)

    def relevancy_from_language_objects(self, language: np.ndarray, query: str) -> np.ndarray:
        """``[H, W]`` map: the query's object weights applied to the probabilities decoded from the embedding."""
        return self.relevancy_from_probs(self.probs_from_language(language), query)
