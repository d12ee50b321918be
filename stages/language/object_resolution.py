"""Which object does a phrase name? Exact, partial, fuzzy, then embedding match, with a margin.

Order of evidence, strongest first; the first stage that decides wins:

1. exact: the phrase is the object's name or a synonym ("refrigerator");
2. partial: a name/synonym appears as whole words in the phrase ("fridge door"),
   or the phrase is part of exactly one object's name ("upper" of "upper cabinet");
3. fuzzy: character similarity (difflib ratio) for misspellings ("frige");
4. embedding: cosine similarity of the phrase to each object's name, synonyms
   and description, softmax over objects with temperature 10, and the winner
   must be more relevant than the canonical negatives (LERF relevancy > 0.5).

A stage that finds two objects equally good raises AmbiguousObjectError; no
stage deciding raises UnknownObjectError. Both list the candidates with their
scores, and nothing is chosen below the confidence margin.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

import numpy as np

from stages.scene import InputError

from .encoder import TextEncoder
from .relevancy import CANONICAL_NEGATIVES, TEMPERATURE, lerf_relevancy, object_similarities, softmax
from .vocabulary import ObjectVocabulary, normalize_phrase


class CommandError(InputError):
    """A language command that cannot be carried out as written."""


class UnknownObjectError(CommandError):
    """No object matches the phrase well enough."""


class AmbiguousObjectError(CommandError):
    """Several objects match the phrase about equally well."""


@dataclass(frozen=True)
class ResolverConfig:
    """Thresholds of object resolution (similarities are in [0, 1] or cosine in [-1, 1])."""

    fuzzy_min_ratio: float = 0.8
    """Least difflib ratio between phrase and a name/synonym for a fuzzy match (one typo in 6 letters ~ 0.83)."""
    fuzzy_margin: float = 0.1
    """A fuzzy winner must beat the best other object's ratio by this much."""
    embedding_min_similarity: float = 0.6
    """Least cosine similarity of phrase and the winner's best phrase for an embedding match."""
    embedding_min_probability: float = 0.7
    """Least softmax probability (temperature 10, over objects) of the embedding winner."""
    min_relevancy: float = 0.5
    """Least LERF relevancy of the winner against the canonical negatives ("object", "things", ...)."""
    ambiguous_similarity: float = 0.45
    """Two objects both at least this similar and within ``ambiguous_gap`` of each other read as ambiguous."""
    ambiguous_gap: float = 0.1
    """Cosine gap below which two plausible objects are reported as ambiguous rather than unknown."""


@dataclass(frozen=True)
class Resolution:
    """The object a phrase names, how it was found and how sure that is."""

    object: str
    method: str
    """exact, partial, fuzzy or embedding."""
    score: float
    """1 for exact/partial, the difflib ratio for fuzzy, the softmax probability for embedding."""


PLACE_WORDS = {"top", "bottom", "upper", "lower", "left", "right", "front", "back", "rear", "middle", "centre",
               "center", "first", "second", "third", "fourth", "fifth", "last", "inner", "outer", "big", "small",
               "large", "tall", "short", "other"}
"""Words of place, order or size: in a phrase, one that none of an object's names holds names another object."""


def _contains_words(haystack: str, needle: str) -> bool:
    return f" {needle} " in f" {haystack} "


class ObjectResolver:
    """Resolves object phrases against one scene's vocabulary (encoder optional)."""

    def __init__(self, vocabulary: ObjectVocabulary, encoder: TextEncoder | None = None,
                 config: ResolverConfig | None = None) -> None:
        self.vocabulary = vocabulary
        self.encoder = encoder
        self.config = config or ResolverConfig()
        self._phrase_vectors: list[np.ndarray] | None = None
        self._negatives: np.ndarray | None = None

    # -- embedding side -------------------------------------------------------------------------------------
    def object_phrases(self, entry_index: int) -> list[str]:
        """Name, synonyms and description of one object: what an embedding match compares against."""
        e = self.vocabulary.entries[entry_index]
        return [p for p in dict.fromkeys([*e.aliases, normalize_phrase(e.description)]) if p]

    def _vectors(self) -> tuple[list[np.ndarray], np.ndarray]:
        assert self.encoder is not None
        if self._phrase_vectors is None:
            self._phrase_vectors = [self.encoder.encode(self.object_phrases(i))
                                    for i in range(len(self.vocabulary.entries))]
            self._negatives = self.encoder.encode(list(CANONICAL_NEGATIVES))
        assert self._negatives is not None
        return self._phrase_vectors, self._negatives

    def embedding_scores(self, phrase: str) -> dict[str, tuple[float, float, float]]:
        """Per object: (cosine similarity, softmax probability over objects, LERF relevancy)."""
        vectors, negatives = self._vectors()
        query = self.encoder.encode([phrase])[0]  # type: ignore[union-attr]
        sims = object_similarities(query, vectors)
        probs = softmax(sims, TEMPERATURE)
        rel = [float(lerf_relevancy(v, query, negatives).max()) for v in vectors]
        return {e.name: (float(s), float(p), r)
                for e, s, p, r in zip(self.vocabulary.entries, sims, probs, rel, strict=True)}

    # -- resolution -----------------------------------------------------------------------------------------
    def fuzzy_scores(self, phrase: str) -> dict[str, float]:
        """Best difflib ratio of the phrase against each object's name and synonyms."""
        return {e.name: max(difflib.SequenceMatcher(None, phrase, a).ratio() for a in e.aliases)
                for e in self.vocabulary.entries}

    def resolve(self, phrase: str, command: str | None = None) -> Resolution:
        """The object ``phrase`` names; raises Unknown/AmbiguousObjectError listing candidates and scores."""
        p = normalize_phrase(phrase)
        said = f'"{phrase}"' + (f' in "{command}"' if command and command.strip() != phrase.strip() else "")
        entries = self.vocabulary.entries
        if not p:
            raise UnknownObjectError(self.vocabulary.source, f"no object named in {said}",
                                     f"name one of {self.vocabulary.objects}")

        exact = [e.name for e in entries if p in e.aliases]
        if len(exact) == 1:
            return Resolution(exact[0], "exact", 1.0)
        if len(exact) > 1:
            raise self._ambiguous(said, {n: 1.0 for n in exact}, "exact name or synonym")

        # longest name/synonym found inside the phrase ("the fridge door" -> "fridge")
        inside = {e.name: max((len(a) for a in e.aliases if _contains_words(p, a)), default=0) for e in entries}
        best = max(inside.values())
        if best:
            winners = [n for n, v in inside.items() if v == best]
            if len(winners) > 1:
                raise self._ambiguous(said, {n: 1.0 for n in winners}, "name contained in the phrase")
            self._one_object_named(p, said)
            self._no_contradicting_word(p, winners[0], said)
            return Resolution(winners[0], "partial", 1.0)
        # the phrase is part of a longer name ("upper" -> "upper cabinet"); two such names are ambiguous
        within = [e.name for e in entries if any(_contains_words(a, p) for a in e.aliases)]
        if len(within) == 1:
            return Resolution(within[0], "partial", 1.0)
        if len(within) > 1:
            raise self._ambiguous(said, {n: 1.0 for n in within}, "phrase contained in several names")

        fuzzy = self.fuzzy_scores(p)
        ranked = sorted(fuzzy.items(), key=lambda kv: -kv[1])
        top_name, top = ranked[0]
        second = ranked[1][1] if len(ranked) > 1 else 0.0
        cfg = self.config
        if top >= cfg.fuzzy_min_ratio:
            if top - second >= cfg.fuzzy_margin:
                return Resolution(top_name, "fuzzy", float(top))
            close = {n: s for n, s in ranked if top - s < cfg.fuzzy_margin}
            raise self._ambiguous(said, close, "spelling similarity")

        emb = self.embedding_scores(p) if self.encoder is not None else {}
        if emb:
            ranked_e = sorted(emb.items(), key=lambda kv: -kv[1][0])
            name, (sim, prob, rel) = ranked_e[0]
            if (sim >= cfg.embedding_min_similarity and prob >= cfg.embedding_min_probability
                    and rel > cfg.min_relevancy):
                return Resolution(name, "embedding", prob)
            plausible = {n: v for n, v in ranked_e
                         if v[0] >= cfg.ambiguous_similarity and sim - v[0] < cfg.ambiguous_gap}
            if len(plausible) > 1:
                raise self._ambiguous(said, {n: v[1] for n, v in plausible.items()},
                                      "meaning (embedding softmax probability)", detail=emb)
        raise self._unknown(said, fuzzy, emb)

    # -- errors ---------------------------------------------------------------------------------------------
    def _one_object_named(self, phrase: str, said: str) -> None:
        """Refuse a phrase that names two objects at different places ("the fridge or the microwave", "the drawer
        under the microwave"): taking the longer name dropped the other without a word. A name inside a longer
        one ("cabinet" in "lower cabinet") is the longer name's."""
        words = phrase.split()
        spans: dict[str, list[tuple[int, int]]] = {}
        for e in self.vocabulary.entries:
            for alias in e.aliases:
                n = len(alias.split())
                spans.setdefault(e.name, []).extend(
                    (i, i + n) for i in range(len(words) - n + 1) if words[i:i + n] == alias.split())
        # an object's span that lies inside another object's longer span is that object's word, not a mention
        mentioned = {name for name, own in spans.items()
                     if any(not any(o0 <= a and b <= o1 and (o1 - o0) > (b - a)
                                    for other, theirs in spans.items() if other != name for o0, o1 in theirs)
                            for a, b in own)}
        if len(mentioned) > 1:
            raise AmbiguousObjectError(self.vocabulary.source, f"{said} names {len(mentioned)} objects "
                                       f"({', '.join(sorted(mentioned))}), and one is asked for",
                                       'give each its own clause ("open the fridge and the microwave"), or name one')

    def _no_contradicting_word(self, phrase: str, name: str, said: str) -> None:
        """Refuse "the bottom drawer" for a room whose only drawer is the top drawer: a word of place or order in
        the phrase that none of the object's names holds says it is another object."""
        entry = next(e for e in self.vocabulary.entries if e.name == name)
        own = {w for a in entry.aliases for w in a.split()}
        wrong = sorted((set(phrase.split()) & PLACE_WORDS) - own)
        if wrong:
            raise UnknownObjectError(self.vocabulary.source, f"{said}: no object is the {wrong[0]} one; the phrase's "
                                     f"other words match {name} ({', '.join(entry.aliases)})",
                                     f"name it as one of {', '.join(entry.aliases)}, or add the words as a synonym "
                                     "in prompts.yaml")

    def _ambiguous(self, said: str, candidates: dict[str, float], basis: str,
                   detail: dict[str, tuple[float, float, float]] | None = None) -> AmbiguousObjectError:
        listing = ", ".join(f"{n} ({s:.2f}" + (f", cosine {detail[n][0]:.2f}" if detail else "") + ")"
                            for n, s in sorted(candidates.items(), key=lambda kv: -kv[1]))
        return AmbiguousObjectError(self.vocabulary.source,
                                    f"ambiguous object {said}: matches {listing} by {basis}",
                                    "use a more specific name, e.g. one of " + ", ".join(sorted(candidates)))

    def _unknown(self, said: str, fuzzy: dict[str, float],
                 emb: dict[str, tuple[float, float, float]]) -> UnknownObjectError:
        order = sorted(fuzzy, key=lambda n: -(emb[n][0] if emb else fuzzy[n]))
        parts = []
        for n in order:
            s = f"{n} (spelling {fuzzy[n]:.2f}"
            if emb:
                s += f", cosine {emb[n][0]:.2f}, probability {emb[n][1]:.2f}"
            parts.append(s + ")")
        hint = "" if emb else " (no text encoder loaded, so meaning was not compared)"
        return UnknownObjectError(self.vocabulary.source,
                                  f"unknown object {said}; candidates: {', '.join(parts)}{hint}",
                                  "name one of the objects above or add the word as a synonym in prompts.yaml")
