"""What a scene's objects are called: names, synonyms, descriptions and state phrases.

Built from ``mapping.yaml`` names and the optional ``prompts.yaml``
(``{name: {synonyms: [...], description: "...", states: {0: "closed fridge", 1: "open fridge"}}}``).
Commands, language targets and grounding all read the same vocabulary, so a
synonym added to prompts.yaml works everywhere at once.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from stages.scene import InputError

_WORD = re.compile(r"[^\W_]+")  # letters and digits of any script: "Küchenschrank", "холодильник", "冷蔵庫"


def normalize_phrase(text: str) -> str:
    """Lower case, words only (``"Fridge_Door!"`` -> ``"fridge door"``), so spelling variants compare equal."""
    return " ".join(_WORD.findall(str(text).lower().replace("_", " ")))


def read_object_names(path: Path) -> list[str]:
    """Object names of a ``mapping.yaml`` in id order (the state-vector and mask-channel order)."""
    if not path.is_file():
        return []
    try:
        raw = yaml.safe_load(path.read_text()) or {}
        return [str(raw[k]) for k in sorted(raw, key=int)]
    except (yaml.YAMLError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(path, f"not a mapping of integer ids to names ({exc})", "write {int_id: object_name}") from exc


@dataclass
class ObjectEntry:
    """One interactive object and every way of referring to it."""

    name: str
    """The object's name as in mapping.yaml (what state vectors are keyed on)."""
    synonyms: list[str] = field(default_factory=list)
    """Other names for it (prompts.yaml), e.g. "refrigerator" for "fridge"."""
    description: str = ""
    """A free-text description (prompts.yaml), used for embedding matches only."""
    state_phrases: dict[float, str] = field(default_factory=dict)
    """Phrase per state level, e.g. {0.0: "closed fridge", 1.0: "open fridge"} (prompts.yaml or generated)."""

    @property
    def aliases(self) -> list[str]:
        """Normalised names that select this object exactly: its name and synonyms."""
        out = [normalize_phrase(self.name), *(normalize_phrase(s) for s in self.synonyms)]
        return [a for a in dict.fromkeys(out) if a]

    def state_phrase(self, level: float) -> str:
        """The phrase of a state level: given in prompts.yaml, else generated ("closed X", "half open X", "open X")."""
        if level in self.state_phrases:
            return self.state_phrases[level]
        label = normalize_phrase(self.name)
        if level <= 0.0:
            return f"closed {label}"
        if level >= 1.0:
            return f"open {label}"
        if abs(level - 0.5) < 1e-9:
            return f"half open {label}"
        return f"{round(100 * level)} percent open {label}"


@dataclass
class ObjectVocabulary:
    """The objects of one scene in state-vector order, with their names and phrases."""

    entries: list[ObjectEntry]
    source: str = "prompts.yaml"
    """Where the vocabulary came from; error messages name it."""

    @property
    def objects(self) -> list[str]:
        return [e.name for e in self.entries]

    def entry(self, name: str) -> ObjectEntry:
        for e in self.entries:
            if e.name == name:
                return e
        raise KeyError(name)

    @classmethod
    def from_prompts(cls, objects: Sequence[str], prompts: Mapping[str, Any] | None = None,
                     source: str | Path = "prompts.yaml") -> ObjectVocabulary:
        """Objects in state-vector order plus the ``prompts.yaml`` content (may be empty or partial)."""
        prompts = dict(prompts or {})
        words = [k for k in prompts if isinstance(k, bool) or k is None]  # yes / on / null unquoted
        if words:
            raise InputError(source, f"YAML reads the keys {words} as booleans or nothing, not as object names",
                             "quote the name: `'yes': {synonyms: [...]}` (or whichever word it is)")
        prompts = {str(k): v for k, v in prompts.items()}  # `2:` names the object "2" as mapping.yaml's `1: '2'`
        unknown = sorted(set(prompts) - set(objects))
        if unknown:
            raise InputError(source, f"prompts for unknown objects {unknown}",
                             f"key prompts.yaml on the names of mapping.yaml {list(objects)}")
        entries = []
        for name in objects:
            raw = prompts.get(name) or {}
            if not isinstance(raw, Mapping):
                raise InputError(source, f"entry of {name!r} is not a mapping",
                                 "write {name: {synonyms: [...], description: ...}}")
            synonyms = raw.get("synonyms") or []
            if isinstance(synonyms, str):
                synonyms = [synonyms]
            states = raw.get("states") or {}
            if isinstance(states, Sequence) and not isinstance(states, str):
                # a list names the levels evenly from closed to open
                n = len(states)
                states = {(i / (n - 1) if n > 1 else 1.0): s for i, s in enumerate(states)}
            try:
                state_phrases = {float(k): str(v) for k, v in dict(states).items()}
            except (TypeError, ValueError) as exc:
                raise InputError(source, f"states of {name!r} are not {{level: phrase}}",
                                 "write states: {0: 'closed fridge', 1: 'open fridge'}") from exc
            entries.append(ObjectEntry(name=str(name), synonyms=[str(s) for s in synonyms],
                                       description=str(raw.get("description") or ""),
                                       state_phrases=state_phrases))
        return cls(entries=entries, source=str(source))

    @classmethod
    def from_dataset(cls, root: str | Path, objects: Sequence[str] | None = None) -> ObjectVocabulary:
        """Read ``mapping.yaml`` (unless ``objects`` is given) and ``prompts.yaml`` of a scene dataset."""
        root = Path(root)
        if objects is None:
            objects = read_object_names(root / "mapping.yaml")
            if not objects:
                raise InputError(root / "mapping.yaml", "no object names (file missing or empty)",
                                 "write mapping.yaml {id: name} for the scene's interactive objects")
        ppath = root / "prompts.yaml"
        prompts: dict[str, Any] = {}
        if ppath.is_file():
            try:
                prompts = yaml.safe_load(ppath.read_text()) or {}
            except yaml.YAMLError as exc:
                raise InputError(ppath, f"not valid YAML ({exc})", "repair the file") from exc
            if not isinstance(prompts, Mapping):
                raise InputError(ppath, "top level is not a mapping", "write {name: {synonyms: [...]}}")
        return cls.from_prompts(list(objects), prompts, source=ppath)
