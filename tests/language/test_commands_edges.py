"""Commands whose reading a mutation audit found unchecked: each expected state is what the command says."""

from __future__ import annotations

import pytest

from stages.language import AmbiguousObjectError, CommandError, CommandParser, ObjectVocabulary, UnknownObjectError

START = {"fridge": 0.2, "upper_cabinet": 0.4, "lower_cabinet": 0.6, "drawer": 0.8}


def _expect(**changes: float) -> dict[str, float]:
    return {**START, **changes}


# no text encoder: names, synonyms and spelling decide, so these run without the model
SUCCEEDS = [
    ("set the fridge to open", _expect(fridge=1.0)),  # "to open" is a state, not the object
    ("leave the drawer to closed", _expect(drawer=0.0)),
    ("close the fridge by 30%", _expect(fridge=0.0)),  # 0.2 - 0.3 stops at closed, never below 0
    ("open the fridge and the lower cabinet", _expect(fridge=1.0, lower_cabinet=1.0)),  # "lower" in a name: no verb
    # an excepted object keeps its state also for "everything else" in a later clause
    (
        "open all cabinets except the upper cabinet and close everything else",
        _expect(fridge=0.0, lower_cabinet=1.0, drawer=0.0),
    ),
    (
        "close everything except the fridge, then open everything else",
        _expect(upper_cabinet=1.0, lower_cabinet=1.0, drawer=1.0),
    ),
    # a verbless clause with an amount of its own is no extension of the exception: it sets the drawer
    ("close all except the fridge, the drawer to 0.5", _expect(upper_cabinet=0.0, lower_cabinet=0.0, drawer=0.5)),
    ("pull out the drawr", _expect(drawer=1.0)),  # the particle is no part of the (misspelt) name
    ("push the drawr in", _expect(drawer=0.0)),
    ("open the upper", _expect(upper_cabinet=1.0)),  # a word of one object's name alone
]

FAILS = [
    ("open the fridge to 1/0", CommandError, r'amount "to 1/0" in .* divides by 0'),
    ("set the fridge to -0.5", CommandError, r"amount -0\.5 .* outside 0\.\.1"),
    ("open the fridge to -10%", CommandError, r"amount -0\.1 .* outside 0\.\.1"),
    # a neutral verb takes the amount of the verbless clauses after it, never the next verb's
    (
        "set the fridge and open the drawer",
        CommandError,
        r'"set the fridge" .* says neither open, closed nor an amount',
    ),
    ("close all boards", UnknownObjectError, r'no object of the group "all boards"'),  # not "cupboard"
    ("open the fudge", UnknownObjectError, r'unknown object "fudge"'),  # spelling 0.73 to "fridge", under 0.8
    (
        "open the oper cabinet",
        AmbiguousObjectError,  # 0.88 to "upper cabinet" and to "lower cabinet"
        r'ambiguous object "oper cabinet".*upper_cabinet \(0\.88\), lower_cabinet \(0\.88\) by spelling similarity',
    ),
]


@pytest.mark.parametrize(("command", "expected"), SUCCEEDS, ids=[c for c, _ in SUCCEEDS])
def test_command_sets_exactly_the_expected_states(command, expected, kitchen):
    assert CommandParser(kitchen).parse(command, START).states == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(("command", "error", "message"), FAILS, ids=[c for c, _, _ in FAILS])
def test_command_fails_with_the_expected_message(command, error, message, kitchen):
    with pytest.raises(error, match=message):
        CommandParser(kitchen).parse(command, START)


def test_names_holding_amount_words_are_names():
    parser = CommandParser(ObjectVocabulary.from_prompts(["half door", "tiny cabinet"], {}))
    assert parser.parse("open the half door").states == {"half door": 1.0, "tiny cabinet": 0.0}
    assert parser.parse("half open the half door").states == {"half door": 0.5, "tiny cabinet": 0.0}
    # "tiny" is an amount the grammar refuses, but here a word of a name: "tiny cabnet" is a misspelt name
    assert parser.parse("open the tiny cabnet").states == {"half door": 0.0, "tiny cabinet": 1.0}


def test_a_name_inside_a_longer_name_is_the_longer_names_word():
    parser = CommandParser(ObjectVocabulary.from_prompts(["cabinet", "lower cabinet"], {}))
    assert parser.parse("open the lower cabinet door").states == {"cabinet": 0.0, "lower cabinet": 1.0}


def test_current_state_names_compare_case_insensitively_and_the_count_is_checked(kitchen):
    states = CommandParser(kitchen).parse("open the drawer", {"FRIDGE": 0.3}).states
    assert states == {"fridge": 0.3, "upper_cabinet": 0.0, "lower_cabinet": 0.0, "drawer": 1.0}
    with pytest.raises(CommandError, match="5 values for 4 objects"):
        CommandParser(kitchen).parse("open the drawer", [0.1] * 5)
