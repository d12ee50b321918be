"""An object name that holds a clause separator ("left, top drawer", "salt and pepper drawer") is one object in a
command: the command was split at the separator first, so "open the left, top drawer" opened the left, top drawer
(a partial match of "left") and, as a clause of its own, the top drawer too."""

from __future__ import annotations

import pytest

from stages.language import parse_command

OBJECTS = ["left, top drawer", "top drawer", "salt and pepper drawer", "pepper drawer"]


@pytest.mark.parametrize(("command", "opened"), [
    ("open the left, top drawer", {"left, top drawer": 1.0}),
    ("Open the Salt And Pepper Drawer", {"salt and pepper drawer": 1.0}),
    ("open the salt and pepper drawer, then half open the pepper drawer",
     {"salt and pepper drawer": 1.0, "pepper drawer": 0.5}),
    ("open the left, top drawer and the top drawer", {"left, top drawer": 1.0, "top drawer": 1.0}),
    ("open the top drawer, then the pepper drawer", {"top drawer": 1.0, "pepper drawer": 1.0}),
])
def test_a_name_holding_a_separator_names_one_object(command, opened):
    result = parse_command(command, OBJECTS)
    assert result.states == {name: opened.get(name, 0.0) for name in OBJECTS}
    assert all(a.method == "exact" for a in result.actions), result.actions
