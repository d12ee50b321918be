"""State combinations given on the command line: ``--states "cabinet=1,drawer=0"`` (docs/export.md).

Each ``--states`` string is one combination; objects it does not name stay closed (0), the default of
``LoadedRun.state_vector`` without a frame (docs/model.md).
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from stages.scene import InputError
from stages.scene.dataset import fit_file_name
from stages.scene.state_values import split_assignment, state_value

_SLUG_UNSAFE = re.compile(r"[^\w.-]+|_")  # letters and digits of any script kept ("冰箱"), '_' is the separator


def parse_state_string(text: str, objects: Sequence[str], where: str = "--states") -> dict[str, float]:
    """``"cabinet=1, drawer=0.5"`` -> ``{"cabinet": 1.0, "drawer": 0.5}``; every value in [0, 1].

    An empty string means "every object closed"; ``all=V`` (unless an object is called ``all``) sets every
    object the string does not name to V, so a workflow can ask for "everything open" without knowing the
    scene's names. Errors name the option, the problem and the fix.
    """
    out: dict[str, float] = {}
    every: float | None = None
    items: list[str] = []
    for part in text.split(","):  # a part without '=' is the start of a name holding a comma ("left, top drawer=1")
        items.append(f"{items.pop()},{part}" if items and items[-1].strip() and "=" not in items[-1] else part)
    for item in (p.strip() for p in items):
        if not item:
            continue
        if "=" not in item:
            raise InputError(where, f"{item!r} in {text!r} is not OBJECT=VALUE",
                             f'write e.g. --states "{objects[0] if objects else "fridge"}=1"')
        name, value = split_assignment(item, where)
        if name == "all" and name not in objects:
            if every is not None:
                raise InputError(where, f"'all' is given twice in {text!r}", "give all=VALUE once")
            every = state_value(item, value, where)
            continue
        if name not in objects:
            raise InputError(where, f"unknown object {name!r} in {text!r}", f"use one of {list(objects)}")
        if name in out:
            raise InputError(where, f"object {name!r} is given twice in {text!r}", "name each object once")
        out[name] = state_value(item, value, where)
    if every is not None:
        out = {name: out.get(name, every) for name in objects}
    return out


def full_state(states: dict[str, float], objects: Sequence[str]) -> dict[str, float]:
    """Every object's state, the unnamed ones at 0 (closed)."""
    return {name: float(states.get(name, 0.0)) for name in objects}


def state_slug(states: dict[str, float]) -> str:
    """A folder name for one combination: ``cabinet-1_drawer-0`` (names made file-system safe)."""
    # 12 significant digits: states that differ in the 7th (0.1234567, 0.1234568) are two folders, not a clash
    parts = [f"{_SLUG_UNSAFE.sub('-', name)}-{value:.12g}" for name, value in states.items()]
    return fit_file_name("_".join(parts)) or "no-objects"
