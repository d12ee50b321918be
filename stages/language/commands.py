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

import difflib
import re
from collections.abc import Callable, Mapping, Sequence
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
_TO = r"(?:\b(?:to|at)\s+)"
_PERCENT = re.compile(rf"({_TO})?(-?\d+(?:\.\d+)?)\s*(?:%|\bpercent\b|\bper cent\b)")
_BY = re.compile(r"\bby\s+(?:another\s+)?(\d+(?:\.\d+)?)\s*(?:%|\bpercent\b|\bper cent\b)")
_PERCENT_MORE = re.compile(r"(\d+(?:\.\d+)?)\s*(?:%|\bpercent\b|\bper cent\b)\s+more\b")
_RATIO = re.compile(rf"{_TO}?(\d+)\s*/\s*(\d+)\b")
_FRACTION = re.compile(rf"{_TO}(-?\d*\.?\d+)\b|(?<![\w.])(\d*\.\d+)(?![\w.])")
_HALF = re.compile(r"\b(?:half\s*way|half)\b")
_FULL = re.compile(r"\b(?:fully|completely|all the way|wide|entirely)\b")
_SLIGHT = re.compile(r"\b(?:slightly|a (?:little\s+)?bit|a little)(?:\s+more)?\b")
_TO_STATE = re.compile(r"\bto\s+(?:be\s+)?(open|opened|closed|shut)\b")
_UNREAD_AMOUNT = re.compile(r"%|\bpercent\b|\bper cent\b|\bpct\b|\d+\s*/\s*\d+|\d+\s*,\s*\d+")
UNREAD_AMOUNT_WORDS = {"quarter", "quarters", "third", "thirds", "partially", "partly", "mostly", "tiny", "crack",
                       "almost", "nearly", "somewhat", "barely", "more", "less", "bit", "little", "lot"}
"""Amount words the grammar does not read: refused, where the verb's own value (fully open) would have been taken."""
AMOUNT_WORDS = {"half", "halfway", "fully", "completely", "entirely", "wide", "slightly", "bit", "little",
                *UNREAD_AMOUNT_WORDS}
"""Words an object's name may hold that the amount rules would otherwise take ("half door", "wide cabinet")."""

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
"""How far "slightly" / "a bit" moves an object from where it is (towards open for an open verb)."""
GRAMMAR = "command"
"""Where a grammar error is (the command), as a file is for other errors; unknown objects name the vocabulary."""
LONGEST_SHOWN = 120
"""Characters of a command repeated in a message."""


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
    delta: float | None = None
    """A move from the object's current state ("a bit more", "by 20%") instead of a value to set."""
    direction: float | None = None
    """1 for an opening verb, 0 for a closing one, None for a neutral verb ("set") or none."""
    pending: bool = False
    """A neutral verb whose amount a later verbless clause gives ("set the fridge and the drawer to 0.5")."""


def _amount(text: str, direction: float | None, inherited: tuple[float | None, float | None], command: str,
            vocabulary_words: set[str]) -> tuple[float | None, float | None, str]:
    """(value, delta, the clause without its amount words): what a clause asks for. ``inherited`` is the
    (value, delta) of the clause before, for a verbless clause."""
    value: float | None = None
    delta: float | None = None

    def cut(m: re.Match) -> str:
        return text[: m.start()] + " " + text[m.end():]

    def signed(amount: float, what: str) -> float:
        if direction is None:
            raise CommandError(GRAMMAR, f'"{what}" in "{command}" moves an object without saying which way',
                               f'say "open X {what}" or "close X {what}"')
        return amount if direction >= 0.5 else -amount

    # "open the fridge by 20%", "open the fridge 20% more": from where it is
    if (m := _BY.search(text)) is not None or (m := _PERCENT_MORE.search(text)) is not None:
        delta, text = signed(float(m.group(1)) / 100.0, m.group(0)), cut(m)
    elif (m := _PERCENT.search(text)) is not None:
        if direction == 0.0 and not m.group(1):  # "close the drawer 100%": how much closed, or how open?
            raise CommandError(GRAMMAR, f'"{m.group(0).strip()}" in "{command}" could mean how far to close or how '
                               "far open to leave it", f'say "close X to {m.group(2)}%" ({m.group(2)}% open), '
                               f'"close X by {m.group(2)}%", or "close X" (fully)')
        value, text = float(m.group(2)) / 100.0, cut(m)
    elif (m := _TO_STATE.search(text)) is not None:
        value, text = (1.0 if m.group(1).startswith("open") else 0.0), cut(m)
    elif (m := _RATIO.search(text)) is not None:  # "to 1/2", "3/4"
        if int(m.group(2)) == 0:
            raise CommandError(GRAMMAR, f'amount "{m.group(0).strip()}" in "{command}" divides by 0',
                               "give a fraction such as 1/2 or a percentage")
        value, text = int(m.group(1)) / int(m.group(2)), cut(m)
    elif (m := _FRACTION.search(text)) is not None:  # "to 0.3", "0.3"
        value, text = float(m.group(1) if m.group(1) is not None else m.group(2)), cut(m)
    elif (m := _HALF.search(text)) is not None:
        value, text = 0.5, cut(m)
    elif (m := _SLIGHT.search(text)) is not None:  # "open it a bit (more)": from where it is
        delta, text = signed(SLIGHT_AMOUNT, m.group(0)), cut(m)
    elif (m := _FULL.search(text)) is not None:  # "the drawer fully" after "open the fridge halfway"
        value = inherited[0] if direction is None else direction
        text = cut(m)
    else:
        value, delta = inherited
    unread = _UNREAD_AMOUNT.search(text)
    words = set(normalize_phrase(text).split()) & (UNREAD_AMOUNT_WORDS - vocabulary_words)
    if unread is not None or words:
        said = unread.group(0) if unread is not None else sorted(words)[0]
        raise CommandError(GRAMMAR, f'amount "{said}" in "{command}" is not understood (read as nothing, the verb '
                           "would open or close fully)",
                           'say e.g. "half open X", "open X to 30%", "set X to 0.25", "open X a bit", '
                           '"close X by 20%"')
    if value is not None and not 0.0 <= value <= 1.0:
        raise CommandError(GRAMMAR, f'amount {value:g} in "{command}" is outside 0..1 (0% closed .. 100% open)',
                           "give a percentage between 0% and 100% or a fraction between 0 and 1")
    return value, delta, text


def split_clauses(command: str) -> list[str]:
    """Split a command at "and", "then", "also", "," and ";" (empty pieces dropped). "X, not Y" and "X and not Y"
    are read as "X but not Y" (an exception), and a comma before an exception word does not split."""
    text = command.strip().lower()
    text = re.sub(r"\s*(?:,|;|\band\b)\s+(?=not\b)", " but ", text)
    text = re.sub(r"\s*,\s*(?=(?:except|apart from|other than|excluding|save for|but not)\b)", " ", text)
    return [c for c in _SPLIT.split(text) if c.strip()]


def _protect(raw: str, protected: Sequence[str], when: Callable[[str], object] = bool) -> tuple[str, dict[str, str]]:
    """Names replaced by tokens that later rules leave alone, where ``when(matched text)`` holds: names that hold
    amount words ("half door") for the amount rules, names that hold a clause separator ("left, top drawer")
    for the split into clauses (which would cut them into two objects)."""
    tokens: dict[str, str] = {}
    for k, alias in enumerate(sorted(protected, key=len, reverse=True)):
        pattern = r"\b" + r"\W+".join(re.escape(w) for w in alias.split()) + r"\b"
        token = f"zqnamezq{chr(97 + k % 26)}{k}"
        raw = re.sub(pattern, lambda m, t=token: f" {t} " if when(m.group(0)) else m.group(0), raw)
        if token in raw:
            tokens[token] = alias
    return raw, tokens


def _parse_clause(raw: str, previous: _Clause | None, command: str, protected: Sequence[str],
                  vocabulary_words: set[str]) -> _Clause:
    raw, tokens = _protect(raw, protected)
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
    direction = verb_value if has_verb else (previous.direction if previous is not None else None)
    if has_verb:  # a neutral verb ("set") asks for an amount of its own
        inherited: tuple[float | None, float | None] = (verb_value, None)
    else:
        inherited = (previous.value, previous.delta) if previous is not None else (None, None)
    value, delta, text = _amount(text, direction, inherited, command, vocabulary_words)
    pending = value is None and delta is None and (
        (has_verb and verb_value is None) or (not has_verb and previous is not None and previous.pending))
    if not has_verb and value is None and delta is None and not pending:
        first = words[0] if words else ""
        close = difflib.get_close_matches(first, [v for v in [*_ALL_VERBS, *FIRST_WORD_VERBS] if not v.endswith("ed")],
                                          n=1, cutoff=0.7)
        hint = f'; did you mean "{close[0]}"?' if close else ""
        if first == "toggle":
            hint = '; "toggle" is not understood: say "open" or "close"'
        where = "" if raw.strip() == command.strip().lower() else f' of "{command}"'
        raise CommandError(GRAMMAR, f'no action in "{raw.strip()}"{where}',
                           "start with a verb the grammar knows (open, close, shut, lift, raise, pull out, push in, "
                           f'lower, set ... to, make ... open){hint}: "open X", "half open X", "open X to 30%"')
    kept = [w for w in normalize_phrase(text).split() if w not in FILLERS and w not in OPEN_VERBS
            and w not in CLOSE_VERBS]
    particles = PARTICLES.get(verb, ())
    if kept and kept[0] in particles:  # "pull out the drawer"
        kept = kept[1:]
    elif kept and kept[-1] in particles:  # "push the drawer in"
        kept = kept[:-1]
    kept = [tokens.get(w, w) for w in kept]
    head, *excepted = _EXCEPT.split(" ".join(kept), maxsplit=1)
    return _Clause(text=raw.strip(), value=value, object_phrase=head.strip(),
                   excepted=[excepted[0].strip()] if excepted else [], has_verb=has_verb, delta=delta,
                   direction=direction, pending=pending)


def _fill_pending(parsed: list[_Clause], command: str) -> None:
    """A neutral verb takes the amount of the verbless clauses after it: "set the fridge and the drawer to 0.5"."""
    for i, clause in enumerate(parsed):
        if not clause.pending:
            continue
        later = next((c for c in parsed[i + 1:] if not c.pending), None)
        if later is None or later.has_verb:
            raise CommandError(GRAMMAR, f'"{clause.text}" in "{command}" says neither open, closed nor an amount',
                               'say e.g. "set the fridge to 30%" or "open the fridge"')
        clause.value, clause.delta, clause.pending = later.value, later.delta, False


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
        states = self._initial(current)
        shown = command if len(command) <= LONGEST_SHOWN else command[: LONGEST_SHOWN - 3] + "..."
        aliases = [a for e in self.vocabulary.entries for a in e.aliases]
        # names holding a separator kept whole through the split (split_clauses lower-cases the command too)
        joined, names = _protect(command.lower(), [a for a in aliases if " " in a], when=_SPLIT.search)
        clauses = []
        for clause in split_clauses(joined):
            for token, alias in names.items():
                clause = clause.replace(token, alias)
            clauses.append(clause)
        # a clause of politeness alone ("..., please?") is no clause
        clauses = [c for c in clauses if set(normalize_phrase(c).split()) - FILLERS - {"thanks"}]
        if not clauses:
            raise CommandError(GRAMMAR, "empty command", 'say e.g. "open the fridge"')
        if (m := re.search(r"\d,\d", command)) is not None:  # a decimal comma: the comma would split the clause
            raise CommandError(GRAMMAR, f'"{m.group(0)}" in "{shown}" has a decimal comma, which splits clauses here',
                               f'write the decimal with a point ({m.group(0).replace(",", ".")})')
        if _NEGATION.search(normalize_phrase(command)):
            raise CommandError(GRAMMAR, f'"{shown}" says what not to do, which commands do not take (read as the '
                               "verb alone, it would do what it forbids)",
                               f'say what to do, e.g. "close the {(self.objects or ["fridge"])[0]}", or leave the '
                               "object out")
        vocabulary_words = {w for a in aliases for w in a.split()}
        protected = [a for a in aliases if set(a.split()) & AMOUNT_WORDS]
        parsed: list[_Clause] = []
        for raw in clauses:
            clause = _parse_clause(raw, parsed[-1] if parsed else None, shown, protected, vocabulary_words)
            parsed.append(clause)
        _fill_pending(parsed, shown)
        parsed = _continue_exceptions(parsed)
        named: dict[int, list[tuple[str, str, float]]] = {}
        excepted: dict[int, set[str]] = {}
        for i, clause in enumerate(parsed):
            if clause.excepted:
                excepted[i] = {self.resolver.resolve(p, shown).object for p in clause.excepted}
            if clause.object_phrase in EVERYTHING or clause.object_phrase in EVERYTHING_ELSE:
                continue
            first = clause.object_phrase.split()[0] if clause.object_phrase else ""
            if not clause.object_phrase:
                raise CommandError(GRAMMAR, f'"{clause.text}" in "{shown}" names no object',
                                   f"name one of {self.objects}, or say everything")
            if first in {"no", "not", "none", "neither", "nor"}:
                raise CommandError(GRAMMAR, f'"{clause.object_phrase}" in "{shown}" says what not to act on, which '
                                   "commands do not take", "name the objects to act on; the others keep their state")
            if clause.object_phrase in PRONOUNS or first in {"it", "them"}:
                raise CommandError(GRAMMAR, f'"{clause.object_phrase}" in "{shown}" refers back to an object, which '
                                   "commands do not resolve", f'name the object again, e.g. "close the '
                                   f'{self.objects[0]} then open the {self.objects[0]}"' if self.objects else
                                   "name the object again")
            group = self._group(clause.object_phrase, shown)
            if group is not None:
                named[i] = group
                continue
            r = self.resolver.resolve(clause.object_phrase, shown)
            if r.object in excepted.get(i, set()):
                raise CommandError(GRAMMAR, f'"{clause.text}" in "{shown}" excepts the object it names',
                                   'name the object, or except objects from everything or a group: "close '
                                   'everything except the fridge"')
            # "open the fridge but not the drawer": the drawer is left as it is anyway
            excepted.pop(i, None)
            named[i] = [(r.object, r.method, r.score)]
        # an excepted object counts as named: "everything else" in a later clause leaves it alone too
        mentioned = {o for items in named.values() for o, _, _ in items} | set().union(*excepted.values())
        actions: list[Action] = []
        for i, clause in enumerate(parsed):
            assert clause.value is not None or clause.delta is not None
            if clause.object_phrase in EVERYTHING:
                targets = [(o, "everything", 1.0) for o in self.objects]
            elif clause.object_phrase in EVERYTHING_ELSE:
                targets = [(o, "everything-else", 1.0) for o in self.objects if o not in mentioned]
            else:
                targets = named[i]
            outside = excepted.get(i, set()) - {o for o, _, _ in targets} if i in named else set()
            if outside:  # "all drawers except the washer"
                raise CommandError(GRAMMAR, f'"{clause.text}" in "{shown}" excepts {sorted(outside)}, which '
                                   f'"{clause.object_phrase}" does not include',
                                   "except only objects of the group, or name them in a clause of their own")
            targets = [t for t in targets if t[0] not in excepted.get(i, set())]
            for obj, method, score in targets:
                value = clause.value if clause.delta is None else min(max(states[obj] + clause.delta, 0.0), 1.0)
                states[obj] = float(value)
                actions.append(Action(obj, float(value), clause.text, method, float(score)))
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
            by_case = {o.casefold(): o for o in self.objects}  # names compare case-insensitively, as in commands
            unknown = sorted(k for k in current if k not in self.objects and k.casefold() not in by_case)
            if unknown:
                raise CommandError(self.vocabulary.source, f"current state names unknown objects {unknown}",
                                   f"use the object names {self.objects}")
            out = dict.fromkeys(self.objects, 0.0)
            out.update({k if k in self.objects else by_case[k.casefold()]: float(v) for k, v in current.items()})
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
