"""``--state OBJECT=VALUE`` means the same, and is refused with the same words, in render, control and export."""

from __future__ import annotations

import pytest

from stages.scene import InputError
from stages.scene.state_values import parse_state_assignments


def test_assignments_are_read_with_spaces_and_in_order():
    assert parse_state_assignments(["fridge=1", " drawer = 0.25 ", "lid=0"]) == {"fridge": 1.0, "drawer": 0.25,
                                                                                 "lid": 0.0}
    assert parse_state_assignments([]) == {}


@pytest.mark.parametrize(("items", "words"), [
    (["fridge"], ["'fridge' is not OBJECT=VALUE", "fix: write e.g. --state fridge=1"]),
    (["=1"], ["'=1' is not OBJECT=VALUE"]),
    (["fridge=open"], ["'open' is not a number", "write a value in [0, 1]"]),
    (["fridge=1.5"], ["state 1.5 is not in [0, 1] (0 closed, 1 fully open)"]),
    (["fridge=nan"], ["state nan is not in [0, 1]"]),
    (["fridge=-inf"], ["state -inf is not in [0, 1]"]),
    (["fridge=1", "fridge=0"], ["object 'fridge' is given twice", "give --state fridge=VALUE once"]),
])
def test_bad_assignments_are_refused_with_the_option_and_the_fix(items, words):
    with pytest.raises(InputError) as info:
        parse_state_assignments(items)
    message = str(info.value)
    assert message.startswith("--state: ") and "; fix: " in message, message
    for word in words:
        assert word in message, (word, message)
