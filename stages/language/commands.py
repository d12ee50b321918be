"""Language commands -> object states: the grammar behind ``livescene control``.

Beyond the reference's ``open X`` / ``close X`` this accepts:

- synonyms, descriptions and misspellings of object names (see object_resolution);
- amounts: "half open X", "open X halfway", "open X to 30%", "set X to 0.3", "close X to 20 percent";
- several commands joined by "and", "then", "," or ";" ("open the fridge and close the drawer"),
  where a clause without a verb repeats the previous one ("open the fridge and the drawer");
- every object at once: "close everything", "open all", and "everything else"/"all other" for the
  objects the rest of the command does not name;
- exceptions: "close everything except the washer and the fridge", "open all drawers but the top drawer"
  (verbless clauses after an exception extend it; the excepted objects keep their state);
- verbs of particular joints: "lift"/"raise" (a lid or flap) and "pull out" open, "push in" and "lower"
  (as the clause's first word only, since "lower drawer" names an object) close;
- "but" before a verb starts a new clause ("open the fridge but close the drawer");
- groups: "open all cabinets", "close both cupboards" (every object whose name or synonym has the word).

State values are openness in [0, 1] (0 closed, 1 fully open), so "close X to 20%" leaves it 20% open.
Later clauses override earlier ones. Parsing needs no trained run: a vocabulary (names, synonyms,
descriptions) and optionally a text encoder are enough.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .encoder import TextEncoder
from .object_resolution import CommandError, ObjectResolver, ResolverConfig, UnknownObjectError
from .vocabulary import ObjectVocabulary, normalize_phrase

OPEN_VERBS = {"open": 1.0, "opened": 1.0, "lift": 1.0, "raise": 1.0, "pull": 1.0}
CLOSE_VERBS = {"close": 0.0, "closed": 0.0, "shut": 0.0, "push": 0.0}
FIRST_WORD_VERBS = {"lower": 0.0}
"""Verbs that are also adjectives of object names ("the lower drawer"): a verb only as a clause's first word."""
PARTICLES = {"pull": ("out", "open"), "push": ("in", "shut", "closed")}
"""Words that complete a verb ("pull out the drawer", "push the drawer in") and are no part of the object."""
NEUTRAL_VERBS = {"set", "put", "move", "make", "turn", "leave", "adjust"}
_ALL_VERBS = [*OPEN_VERBS, *CLOSE_VERBS, *NEUTRAL_VERBS]
_SPLIT = re.compile(r"\s*(?:,|;|\band\b|\bthen\b|\balso\b|\bbut\b(?=\s+(?:" + "|".join(_ALL_VERBS) + r")\b))\s*")
_EXCEPT = re.compile(r"\b(?:except(?: for)?|but(?: not)?|apart from|other than|excluding|save for)\b")
_PERCENT = re.compile(r"(?:\bto\s+)?(-?\d+(?:\.\d+)?)\s*(?:%|\bpercent\b|\bper cent\b)")
_FRACTION = re.compile(r"\bto\s+(-?\d*\.?\d+)\b")
_HALF = re.compile(r"\b(?:half\s*way|half)\b")
_FULL = re.compile(r"\b(?:fully|completely|all the way|wide|entirely)\b")
_SLIGHT = re.compile(r"\b(?:slightly|a (?:little\s+)?bit|a little)\b")
_TO_STATE = re.compile(r"\bto\s+(?:be\s+)?(open|opened|closed|shut)\b")

FILLERS = {"please", "the", "a", "an", "my", "that", "this", "can", "you", "could", "would", "now", "up", "kindly"}
EVERYTHING = {"everything", "all", "all objects", "all the objects", "every object", "all of them", "each object",
              "everything in the room", "it all", "them all", "objects", "both", "both of them"}
GROUP_WORDS = ("all", "every", "each", "both")
"""A phrase "all cabinets" / "both cabinets" names every object whose name or synonym has the word "cabinet"."""
GENERIC_GROUPS = {"door", "doors", "thing", "things", "part", "parts", "object", "objects"}
"""Group words that name every object when no name contains them ("close all doors")."""
EVERYTHING_ELSE = {"everything else", "all else", "all other", "all others", "all other objects", "the rest",
                   "rest", "all the others", "the others", "others", "anything else"}
PRONOUNS = {"it", "them", "this one", "that one", "this", "that", "those", "these"}
"""Words that refer back to an object: not resolved (name the object again)."""
_NEGATION = re.compile(r"\b(?:don t|dont|do not|does not|doesn t|never|not)\s+(?:please\s+)?(?:"
                       + "|".join([*_ALL_VERBS, *FIRST_WORD_VERBS]) + r")\b")
"""A negated verb ("don't open the fridge"): read as the verb, it would do what it forbids."""
SLIGHT_AMOUNT = 0.25
"""Openness that "slightly"/"a bit" means for an open command (and 1 - it for a close command)."""


@dataclass(frozen=True)
class Action:
    """One object set to one value by one clause of a command."""

    object: str
    value: float
    clause: str
    method: str
    """How the object was found: exact, partial, fuzzy, embedding, group, everything or everything-else."""
    score: float


@dataclass
class CommandResult:
    """The state vector after a command, and the actions that made it."""

    states: dict[str, float]
    actions: list[Action] = field(default_factory=list)

    def vector(self, objects: Sequence[str]) -> list[float]:
        return [float(self.states[o]) for o in objects]

    def to_json(self, objects: Sequence[str]) -> dict:
        return {"objects": list(objects), "states": self.states, "vector": self.vector(objects),
                "actions": [a.__dict__ for a in self.actions]}


@dataclass
class _Clause:
    text: str
    value: float | None
    object_phrase: str
    excepted: list[str] = field(default_factory=list)
    """Object phrases after "except" / "but" / "apart from": left out of an everything or group phrase."""
    has_verb: bool = True


def _amount(text: str, base: float | None, source: str, command: str) -> tuple[float | None, str]:
    """The value a clause asks for and the clause with the amount words removed."""
    m = _PERCENT.search(text)
    if m:
        value = float(m.group(1)) / 100.0
        text = text[: m.start()] + " " + text[m.end():]
    elif (m := _TO_STATE.search(text)) is not None:
        value = 1.0 if m.group(1).startswith("open") else 0.0
        text = text[: m.start()] + " " + text[m.end():]
    elif (m := _FRACTION.search(text)) is not None:
        value = float(m.group(1))
        text = text[: m.start()] + " " + text[m.end():]
    elif (m := _HALF.search(text)) is not None:
        value = 0.5
        text = text[: m.start()] + " " + text[m.end():]
    elif (m := _SLIGHT.search(text)) is not None:
        value = None if base is None else (SLIGHT_AMOUNT if base >= 0.5 else 1.0 - SLIGHT_AMOUNT)
        text = text[: m.start()] + " " + text[m.end():]
    else:
        value = base
        text = _FULL.sub(" ", text)
    if value is not None and not 0.0 <= value <= 1.0:
        raise CommandError(source, f'amount {value:g} in "{command}" is outside 0..1 (0% closed .. 100% open)',
                           "give a percentage between 0% and 100% or a fraction between 0 and 1")
    return value, text


def split_clauses(command: str) -> list[str]:
    """Split a command at "and", "then", "also", "," and ";" (empty pieces dropped)."""
    return [c for c in _SPLIT.split(command.strip().lower()) if c.strip()]


def _parse_clause(raw: str, previous_value: float | None, source: str, command: str) -> _Clause:
    words = normalize_phrase(raw).split()
    verb_value: float | None = None
    verb = ""
    rest: list[str] = []
    for i, w in enumerate(words):
        if not verb and (w in OPEN_VERBS or w in CLOSE_VERBS or w in NEUTRAL_VERBS
                         or (i == 0 and w in FIRST_WORD_VERBS)):
            verb = w
            verb_value = OPEN_VERBS.get(w, CLOSE_VERBS.get(w, FIRST_WORD_VERBS.get(w)))
            continue
        rest.append(w)
    has_verb = bool(verb)
    if has_verb and verb_value is None:
        # "make the fridge open", "leave the drawer closed": the state word comes after the object
        for w in rest:
            if w in OPEN_VERBS or w in CLOSE_VERBS:
                verb_value = OPEN_VERBS.get(w, CLOSE_VERBS.get(w))
                break
    # amounts are read from the raw text (so "0.3" and "30%" survive), after the verb is known
    text = raw
    if has_verb:
        text = re.sub(rf"\b{verb}\b", " ", raw, count=1)  # split_clauses lower-cased it
    base = verb_value if has_verb else previous_value
    value, text = _amount(text, base, source, command)
    if has_verb and verb_value is None and value is None:
        raise CommandError(source, f'"{raw.strip()}" in "{command}" says neither open, closed nor an amount',
                           'say e.g. "set the fridge to 30%" or "open the fridge"')
    if not has_verb and value is None:
        raise CommandError(source, f'no action in "{raw.strip()}" of "{command}"',
                           'start with a verb: "open X", "close X", "half open X", "open X to 30%"')
    kept = [w for w in normalize_phrase(text).split() if w not in FILLERS and w not in OPEN_VERBS
            and w not in CLOSE_VERBS]
    particles = PARTICLES.get(verb, ())
    if kept and kept[0] in particles:  # "pull out the drawer"
        kept = kept[1:]
    elif kept and kept[-1] in particles:  # "push the drawer in"
        kept = kept[:-1]
    head, *excepted = _EXCEPT.split(" ".join(kept), maxsplit=1)
    return _Clause(text=raw.strip(), value=value, object_phrase=head.strip(),
                   excepted=[excepted[0].strip()] if excepted else [], has_verb=has_verb)


def _continue_exceptions(parsed: list[_Clause]) -> list[_Clause]:
    """Verbless clauses right after an exception extend it: "close all except the fridge and the drawer"."""
    out: list[_Clause] = []
    for clause in parsed:
        previous = out[-1] if out else None
        if previous is not None and previous.excepted and not clause.has_verb and clause.value == previous.value \
                and not clause.excepted:
            previous.excepted.append(clause.object_phrase)
            previous.text = f"{previous.text} and {clause.text}"
            continue
        out.append(clause)
    return out


class CommandParser:
    """Turns commands into state vectors for one scene's objects.

    ``encoder`` enables meaning-based object matches (descriptions, related
    words); without it names, synonyms and misspellings still resolve.
    """

    def __init__(self, vocabulary: ObjectVocabulary, encoder: TextEncoder | None = None,
                 config: ResolverConfig | None = None) -> None:
        self.vocabulary = vocabulary
        self.resolver = ObjectResolver(vocabulary, encoder, config)

    @property
    def objects(self) -> list[str]:
        return self.vocabulary.objects

    def parse(self, command: str, current: Mapping[str, float] | Sequence[float] | None = None) -> CommandResult:
        """Apply ``command`` to ``current`` states (default: every object closed) and return the result."""
        source = self.vocabulary.source
        states = self._initial(current)
        clauses = split_clauses(command)
        if not clauses:
            raise CommandError(source, "empty command", 'say e.g. "open the fridge"')
        if _NEGATION.search(normalize_phrase(command)):
            raise CommandError(source, f'"{command}" says what not to do, which commands do not take (read as the '
                               "verb alone, it would do what it forbids)",
                               f'say what to do, e.g. "close the {(self.objects or ["fridge"])[0]}", or leave the '
                               "object out")
        parsed: list[_Clause] = []
        previous: float | None = None
        for raw in clauses:
            clause = _parse_clause(raw, previous, source, command)
            parsed.append(clause)
            previous = clause.value
        parsed = _continue_exceptions(parsed)
        named: dict[int, list[tuple[str, str, float]]] = {}
        excepted: dict[int, set[str]] = {}
        for i, clause in enumerate(parsed):
            if clause.excepted:
                excepted[i] = {self.resolver.resolve(p, command).object for p in clause.excepted}
            if clause.object_phrase in EVERYTHING or clause.object_phrase in EVERYTHING_ELSE:
                continue
            if not clause.object_phrase:
                raise CommandError(source, f'"{clause.text}" in "{command}" names no object',
                                   f"name one of {self.objects}, or say everything")
            if clause.object_phrase in PRONOUNS:
                raise CommandError(source, f'"{clause.object_phrase}" in "{command}" refers back to an object, which '
                                   "commands do not resolve", f'name the object again, e.g. "close the '
                                   f'{self.objects[0]} then open the {self.objects[0]}"' if self.objects else
                                   "name the object again")
            group = self._group(clause.object_phrase, command)
            if group is not None:
                named[i] = group
                continue
            r = self.resolver.resolve(clause.object_phrase, command)
            if r.object in excepted.get(i, set()):
                raise CommandError(source, f'"{clause.text}" in "{command}" excepts the object it names',
                                   'name the object, or except objects from everything or a group: "close '
                                   'everything except the fridge"')
            # "open the fridge but not the drawer": the drawer is left as it is anyway
            excepted.pop(i, None)
            named[i] = [(r.object, r.method, r.score)]
        # an excepted object counts as named: "everything else" in a later clause leaves it alone too
        mentioned = {o for items in named.values() for o, _, _ in items} | set().union(*excepted.values())
        actions: list[Action] = []
        for i, clause in enumerate(parsed):
            assert clause.value is not None
            if clause.object_phrase in EVERYTHING:
                targets = [(o, "everything", 1.0) for o in self.objects]
            elif clause.object_phrase in EVERYTHING_ELSE:
                targets = [(o, "everything-else", 1.0) for o in self.objects if o not in mentioned]
            else:
                targets = named[i]
            outside = excepted.get(i, set()) - {o for o, _, _ in targets} if i in named else set()
            if outside:  # "all drawers except the washer"
                raise CommandError(source, f'"{clause.text}" in "{command}" excepts {sorted(outside)}, which '
                                   f'"{clause.object_phrase}" does not include',
                                   "except only objects of the group, or name them in a clause of their own")
            targets = [t for t in targets if t[0] not in excepted.get(i, set())]
            for obj, method, score in targets:
                states[obj] = float(clause.value)
                actions.append(Action(obj, float(clause.value), clause.text, method, float(score)))
        return CommandResult(states=states, actions=actions)

    def _group(self, phrase: str, command: str) -> list[tuple[str, str, float]] | None:
        """Objects named by "all X" / "both X" (X singular or plural), or None when the phrase is no group."""
        words = phrase.split()
        if len(words) < 2 or words[0] not in GROUP_WORDS:
            return None
        rest = " ".join(words[1:])
        singular = " ".join(w[:-1] if w.endswith("s") and len(w) > 3 else w for w in words[1:])
        members = [e.name for e in self.vocabulary.entries
                   if any(f" {form} " in f" {a} " for a in e.aliases for form in (rest, singular))]
        if members:
            return [(o, "group", 1.0) for o in members]
        if rest in GENERIC_GROUPS or singular in GENERIC_GROUPS:
            return [(o, "everything", 1.0) for o in self.objects]
        raise UnknownObjectError(self.vocabulary.source, f'no object of the group "{phrase}" in "{command}"',
                                 f"name objects of {self.objects} (or say everything)")

    def _initial(self, current: Mapping[str, float] | Sequence[float] | None) -> dict[str, float]:
        if current is None:
            return dict.fromkeys(self.objects, 0.0)
        if isinstance(current, Mapping):
            unknown = sorted(set(current) - set(self.objects))
            if unknown:
                raise CommandError(self.vocabulary.source, f"current state names unknown objects {unknown}",
                                   f"use the object names {self.objects}")
            out = dict.fromkeys(self.objects, 0.0)
            out.update({k: float(v) for k, v in current.items()})
            return out
        values = [float(v) for v in current]
        if len(values) != len(self.objects):
            raise CommandError(self.vocabulary.source, f"current state has {len(values)} values for "
                               f"{len(self.objects)} objects", f"give one value per object {self.objects}")
        return dict(zip(self.objects, values, strict=True))


def parse_command(command: str, objects: Sequence[str], prompts: Mapping | None = None,
                  encoder: TextEncoder | None = None,
                  current: Mapping[str, float] | Sequence[float] | None = None) -> CommandResult:
    """One-call form: object names + prompts.yaml content (+ encoder) -> the state vector after ``command``."""
    return CommandParser(ObjectVocabulary.from_prompts(objects, prompts), encoder).parse(command, current)
