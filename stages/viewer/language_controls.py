"""Words in the viewer: language commands -> slider values, text queries -> relevancy maps.

Both reuse stages.language as `livescene control` and `livescene language relevancy` do (docs/language.md):
``CommandParser`` for the grammar, ``Grounder`` for the maps. The text encoder (MiniLM by default, several
seconds to load on a CPU) is built only when it is needed: commands that name objects by name, synonym or
a misspelling resolve without it, so "open the fridge" answers at once; the first command that needs
meaning ("open the freezer") or the first relevancy query loads it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping

import numpy as np

from stages.language.commands import CommandParser, CommandResult
from stages.language.encoder import TextEncoder
from stages.language.grounding import Grounder
from stages.language.object_resolution import UnknownObjectError
from stages.language.vocabulary import ObjectVocabulary
from stages.scene import InputError

SOURCES = ("probs", "language", "language_objects")
"""Relevancy evidence, as in `livescene language relevancy --source` (docs/language.md, Evaluation)."""


class LanguageControls:
    """Commands and relevancy for one scene's objects; thread-safe (GUI callbacks run in a thread pool)."""

    def __init__(self, vocabulary: ObjectVocabulary, encoder_factory: Callable[[], TextEncoder] | None = None,
                 renders_language: bool = False, run_encoder: str | None = None) -> None:
        self.vocabulary = vocabulary
        self._encoder_factory = encoder_factory
        self._encoder: TextEncoder | None = None
        self._grounder: Grounder | None = None
        self._lock = threading.Lock()
        self._by_name = CommandParser(vocabulary)
        self._by_meaning: CommandParser | None = None
        self.renders_language = renders_language
        self.run_encoder = run_encoder
        """The encoder the run's language table was trained with (its embedding space), if any."""

    @property
    def objects(self) -> list[str]:
        return self.vocabulary.objects

    @property
    def encoder_loaded(self) -> bool:
        return self._encoder is not None

    def encoder(self) -> TextEncoder:
        with self._lock:
            if self._encoder is None:
                if self._encoder_factory is None:
                    raise InputError("--no-encoder", "this needs a text encoder and the viewer was started without one",
                                     "restart `livescene view` without --no-encoder (MiniLM loads offline)")
                self._encoder = self._encoder_factory()
            return self._encoder

    def command(self, text: str, current: Mapping[str, float]) -> CommandResult:
        """The states after ``text`` applied to ``current``; raises CommandError (an InputError) with the fix."""
        try:
            return self._by_name.parse(text, current)
        except UnknownObjectError:
            if self._encoder_factory is None:
                raise
        if self._by_meaning is None:
            self._by_meaning = CommandParser(self.vocabulary, self.encoder())
        return self._by_meaning.parse(text, current)

    def sources(self) -> list[str]:
        """The relevancy sources this run supports: probs always, the language ones with a language table."""
        return list(SOURCES) if self.renders_language else ["probs"]

    @staticmethod
    def outputs_for(source: str) -> tuple[str, ...]:
        """The render outputs a relevancy map of ``source`` is computed from."""
        return ("probs",) if source == "probs" else ("language",)

    def grounder(self) -> Grounder:
        encoder = self.encoder()
        with self._lock:
            if self._grounder is None:
                self._grounder = Grounder(self.vocabulary, encoder)
            return self._grounder

    def check_source(self, source: str) -> None:
        """Refuse a source this run cannot serve, naming the fix."""
        if source not in SOURCES:
            raise InputError("relevancy source", f"unknown source {source!r}", f"choose one of {list(SOURCES)}")
        if source != "probs" and not self.renders_language:
            raise InputError("relevancy source", f"the run renders no language embedding, so {source!r} has no map",
                             "use the probs source, or train the run with --language-targets targets.npz")
        if source != "probs" and self.run_encoder not in (None, self.encoder().name):
            raise InputError("relevancy source", f"the run's language table was trained with encoder "
                             f"{self.run_encoder!r} but queries are embedded with {self.encoder().name!r}",
                             "restart `livescene view` with the --encoder the targets were built with, or use probs")

    def relevancy(self, query: str, source: str, rendered: Mapping[str, np.ndarray]) -> np.ndarray:
        """``[H, W]`` relevancy in [0, 1] of ``query`` from the rendered outputs of ``outputs_for(source)``."""
        self.check_source(source)
        grounder = self.grounder()
        if source == "probs":
            return grounder.relevancy_from_probs(rendered["probs"], query)
        if source == "language":
            return grounder.relevancy_from_language(rendered["language"], query)
        return grounder.relevancy_from_language_objects(rendered["language"], query)
