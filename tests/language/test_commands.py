"""The command suite: each phrasing sets exactly the expected states or fails with the expected message."""

from __future__ import annotations

import re

import pytest

from stages.language import (
    AmbiguousObjectError,
    CommandError,
    CommandParser,
    ObjectVocabulary,
    UnknownObjectError,
    parse_command,
    split_clauses,
)

START = {"fridge": 0.2, "upper_cabinet": 0.4, "lower_cabinet": 0.6, "drawer": 0.8}


def _expect(**changes: float) -> dict[str, float]:
    out = dict(START)
    out.update(changes)
    return out


ALL_CLOSED = dict.fromkeys(START, 0.0)
ALL_OPEN = dict.fromkeys(START, 1.0)

SUCCEEDS = [
    ("open the fridge", _expect(fridge=1.0)),
    ("Open the Refrigerator!", _expect(fridge=1.0)),  # synonym, case, punctuation
    ("please open the frige", _expect(fridge=1.0)),  # misspelling
    ("close the drawr", _expect(drawer=0.0)),  # misspelling
    ("half open the drawer", _expect(drawer=0.5)),
    ("open the fridge halfway", _expect(fridge=0.5)),
    ("open the drawer to 30%", _expect(drawer=0.3)),
    ("set the fridge to 0.25", _expect(fridge=0.25)),
    ("close the drawer to 20 percent", _expect(drawer=0.2)),
    ("open the fridge and the drawer", _expect(fridge=1.0, drawer=1.0)),  # verb carried over "and"
    ("open the fridge, close the drawer", _expect(fridge=1.0, drawer=0.0)),
    ("close the fridge; then open the wall cupboard", _expect(fridge=0.0, upper_cabinet=1.0)),
    ("close everything", ALL_CLOSED),
    ("open all", ALL_OPEN),
    ("open the fridge and close everything else", {**ALL_CLOSED, "fridge": 1.0}),
    ("close everything and half open the drawer", {**ALL_CLOSED, "drawer": 0.5}),  # later clauses override
    ("open the upper cabinet door", _expect(upper_cabinet=1.0)),  # a name inside a longer phrase
    ("shut the base cupboard", _expect(lower_cabinet=0.0)),  # synonym with another verb
    ("open the freezer", _expect(fridge=1.0)),  # meaning only: the text encoder decides
    ("make the kitchen drawer open", _expect(drawer=1.0)),
    ("slightly open the fridge", _expect(fridge=0.45)),  # a bit from where it is (0.2)
    ("open the lower_cabinet fully", _expect(lower_cabinet=1.0)),
    ("open all cabinets", _expect(upper_cabinet=1.0, lower_cabinet=1.0)),  # a group by a shared word
    ("close both cupboards and open the fridge", _expect(upper_cabinet=0.0, lower_cabinet=0.0, fridge=1.0)),
    ("close all the doors", ALL_CLOSED),  # no name has "door": every object
    ("close everything except the fridge", {**ALL_CLOSED, "fridge": 0.2}),  # the excepted keep their state
    ("open everything but the fridge and the drawer", _expect(upper_cabinet=1.0, lower_cabinet=1.0)),
    ("open all cabinets except the upper cabinet", _expect(lower_cabinet=1.0)),
    ("open the drawer and close everything else apart from the fridge", {**ALL_CLOSED, "drawer": 1.0, "fridge": 0.2}),
    ("open the fridge but close the drawer", _expect(fridge=1.0, drawer=0.0)),  # "but" before a verb: a clause
    ("pull out the drawer", _expect(drawer=1.0)),
    ("push the drawer in", _expect(drawer=0.0)),
    ("raise the wall cupboard", _expect(upper_cabinet=1.0)),
    ("lower the fridge", _expect(fridge=0.0)),
    ("open the lower cabinet", _expect(lower_cabinet=1.0)),  # "lower" inside a name is no verb
    ("open the fridge but not the drawer", _expect(fridge=1.0)),  # the excepted object is left as it is
    # a review of 29 Nov found each of these accepted and doing something else than it says
    ("open the fridge and not the drawer", _expect(fridge=1.0)),  # it opened the drawer too
    ("open the fridge, not the drawer", _expect(fridge=1.0)),
    ("open the fridge to 1/2", _expect(fridge=0.5)),  # fractions and bare decimals were read as nothing: open
    ("open the fridge 3/4", _expect(fridge=0.75)),
    ("open the fridge 0.5", _expect(fridge=0.5)),
    ("set the fridge at 0.3", _expect(fridge=0.3)),
    ("open the drawer a bit more", _expect(drawer=1.0)),  # from where it is (0.8): it went to 0.25
    ("close the drawer slightly", _expect(drawer=0.55)),  # it went to 0.75, more open than before
    ("close the drawer by 20%", _expect(drawer=0.6)),
    ("open the fridge 30% more", _expect(fridge=0.5)),
    ("open the fridge halfway, the drawer fully", _expect(fridge=0.5, drawer=1.0)),  # "fully" was dropped: 0.5
    ("set the fridge and the drawer to 0.5", _expect(fridge=0.5, drawer=0.5)),  # a later amount for both
    ("Could you open the fridge, please?", _expect(fridge=1.0)),  # "please?" was a clause naming no object
    ("open everything, except the fridge", {**ALL_OPEN, "fridge": 0.2}),
]

FAILS = [
    ("open the toaster", UnknownObjectError, r'unknown object "toaster".*fridge \(spelling \d\.\d\d, cosine'),
    ("open it", CommandError, r'"it" in "open it" refers back to an object'),
    ("close the fridge then open it", CommandError, r"refers back to an object.*name the object again"),
    # a negation read as its verb did what it forbids ("don't open the fridge" opened it)
    ("don't open the fridge", CommandError, r"says what not to do"),
    ("do not close the drawer", CommandError, r"says what not to do"),
    ("close", CommandError, r'"close" in "close" names no object'),
    # the longer name was taken and the other dropped (names of one length were refused as ambiguous already)
    ("open the fridge or the upper cabinet", AmbiguousObjectError, r"names 2 objects \(fridge, upper_cabinet\)"),
    ("open the drawer under the upper cabinet", AmbiguousObjectError, r"names 2 objects"),
    ("open the bottom drawer", UnknownObjectError, r"no object is the bottom one"),  # opened the only drawer
    ("open the fridge thirty percent", CommandError, r'amount "percent" .* is not understood'),  # read as fully
    ("open the drawer a quarter", CommandError, r'amount "quarter" .* is not understood'),
    ("open the drawer partially", CommandError, r'amount "partially" .* is not understood'),
    ("open the fridge a bit less", CommandError, r'amount "less" .* is not understood'),
    ("close the drawer 100%", CommandError, r"could mean how far to close or how far open"),  # left it open
    ("open no drawers", CommandError, r"says what not to act on"),  # opened the drawer
    ("open the fridge to 0,5", CommandError, r"decimal comma"),
    ("toggle the fridge", CommandError, r'"toggle" is not understood: say "open" or "close"'),
    ("opne the fridge", CommandError, r'did you mean "open"'),
    ("open the cabinet", AmbiguousObjectError,
     r'ambiguous object "cabinet".*(upper_cabinet|lower_cabinet) \(1\.00\).*(lower_cabinet|upper_cabinet) \(1\.00\)'),
    ("close the cupboard", AmbiguousObjectError, r"ambiguous object \"cupboard\".*lower_cabinet.*upper_cabinet"),
    ("open the fridge to 130%", CommandError, r"amount 1\.3 .* outside 0\.\.1"),
    ("the fridge", CommandError, r'no action in "the fridge"'),
    ("set the drawer", CommandError, r"neither open, closed nor an amount"),
    ("", CommandError, r"empty command"),
    ("open all ovens", UnknownObjectError, r'no object of the group "all ovens"'),
    ("open the fridge except the refrigerator", CommandError, r"excepts the object it names"),
    ("open all cabinets except the fridge", CommandError, r"excepts \['fridge'\], which \"all cabinets\" does not"),
]


@pytest.mark.parametrize(("command", "expected"), SUCCEEDS, ids=[c for c, _ in SUCCEEDS])
def test_command_sets_exactly_the_expected_states(command, expected, kitchen, encoder):
    result = CommandParser(kitchen, encoder).parse(command, START)
    assert result.states == pytest.approx(expected, abs=1e-12)
    assert set(result.states) == set(START)


@pytest.mark.parametrize(("command", "error", "message"), FAILS, ids=[c or "<empty>" for c, _, _ in FAILS])
def test_command_fails_with_the_expected_message(command, error, message, kitchen, encoder):
    with pytest.raises(error) as info:
        CommandParser(kitchen, encoder).parse(command, START)
    assert re.search(message, str(info.value)), str(info.value)
    assert "fix:" in str(info.value)


def test_suite_is_large_enough():
    assert len(SUCCEEDS) + len(FAILS) >= 20


def test_actions_record_how_each_object_was_found(kitchen, encoder):
    result = CommandParser(kitchen, encoder).parse("open the refrigerator and close the drawr and the freezer")
    methods = [(a.object, a.method, a.value) for a in result.actions]
    assert methods == [("fridge", "exact", 1.0), ("drawer", "fuzzy", 0.0), ("fridge", "embedding", 0.0)]
    assert result.vector(kitchen.objects) == [0.0, 0.0, 0.0, 0.0]


def test_shared_synonym_is_ambiguous_not_guessed():
    vocab = ObjectVocabulary.from_prompts(["fridge", "cabinet"], {"fridge": {"synonyms": ["door"]},
                                                                  "cabinet": {"synonyms": ["door"]}})
    with pytest.raises(AmbiguousObjectError, match=r"fridge \(1\.00\), cabinet \(1\.00\) by exact name"):
        CommandParser(vocab).parse("open the door")


def test_without_encoder_names_and_spelling_still_resolve(kitchen):
    parser = CommandParser(kitchen)  # no text model loaded
    assert parser.parse("open the refrigerator and half open the drawr").states == {
        "fridge": 1.0, "upper_cabinet": 0.0, "lower_cabinet": 0.0, "drawer": 0.5}
    with pytest.raises(UnknownObjectError, match="no text encoder loaded"):
        parser.parse("open the freezer")


def test_parse_command_one_call_api():
    result = parse_command("open the chiller to 40%", ["fridge", "drawer"], {"fridge": {"synonyms": ["chiller"]}},
                           current=[0.0, 1.0])
    assert result.states == {"fridge": 0.4, "drawer": 1.0}
    assert result.to_json(["fridge", "drawer"])["vector"] == [0.4, 1.0]


def test_current_state_is_checked(kitchen):
    with pytest.raises(CommandError, match="unknown objects"):
        CommandParser(kitchen).parse("open the fridge", {"oven": 1.0})
    with pytest.raises(CommandError, match="3 values for 4 objects"):
        CommandParser(kitchen).parse("open the fridge", [0.0, 0.0, 0.0])


def test_split_clauses():
    assert split_clauses("Open the fridge, close the drawer and then the cabinet; open all") == [
        "open the fridge", "close the drawer", "the cabinet", "open all"]


@pytest.mark.parametrize("names", [["холодильник", "ящик"], ["冷蔵庫", "引き出し"],
                                   ["Küchenschrank", "Schublade oben"]])
def test_names_in_any_script_keep_their_words_and_are_commanded(names):
    """Names come from the user's mapping.yaml or folder names: each keeps its own phrases (distinct language
    targets), and a command naming it sets it."""
    vocab = ObjectVocabulary.from_prompts(names, {}, None)
    phrases = [e.state_phrase(1.0) for e in vocab.entries]
    assert phrases == [f"open {n.lower()}" for n in names]
    result = parse_command(f"open the {names[0]} and close the {names[1]}", names, {}, current=[0.0, 1.0])
    assert result.states == {names[0]: 1.0, names[1]: 0.0}
