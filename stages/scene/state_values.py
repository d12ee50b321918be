"""Object states given on the command line (``--state fridge=1``, ``--states "cabinet=1,drawer=0"``).

One parser for ``render``, ``control`` and ``export``, so an assignment means, and is refused with, the same words
everywhere: a state is a number in [0, 1] (0 closed, 1 fully open), and an object is named once.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from .errors import InputError


def state_value(item: str, value: str, where: str) -> float:
    """The state of ``item`` (``"fridge=1"``) whose value part is ``value``, checked to lie in [0, 1]."""
    try:
        v = float(value)
    except ValueError as exc:
        raise InputError(where, f"{item!r}: {value.strip()!r} is not a number", "write a value in [0, 1]") from exc
    if not math.isfinite(v) or not 0.0 <= v <= 1.0:
        raise InputError(where, f"{item!r}: state {value.strip()} is not in [0, 1] (0 closed, 1 fully open)",
                         "write a value in [0, 1]")
    return v


def split_assignment(item: str, where: str, example: str = "fridge=1") -> tuple[str, str]:
    """``"fridge = 1"`` -> ``("fridge", "1")``; an item without ``=`` or without a name is refused."""
    name, sep, value = (s.strip() for s in item.partition("="))
    if not sep or not name:
        raise InputError(where, f"{item!r} is not OBJECT=VALUE", f"write e.g. {where} {example}")
    return name, value


def parse_state_assignments(items: Iterable[str], where: str = "--state") -> dict[str, float]:
    """Repeated ``OBJECT=VALUE`` options -> ``{object: state}``; an object given twice is refused (which one was
    meant cannot be told). Whether the names exist is for the caller, who knows the scene."""
    out: dict[str, float] = {}
    for item in items:
        name, value = split_assignment(item, where)
        if name in out:
            raise InputError(where, f"object {name!r} is given twice", f"give {where} {name}=VALUE once")
        out[name] = state_value(item, value, where)
    return out
