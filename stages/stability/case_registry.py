"""The stability cases: how one is declared, run and reported.

A case is a plain function ``fn(ctx) -> Outcome`` registered with :func:`case`.
It checks what it claims with :func:`require` (not ``assert``, which ``python -O``
strips) and raises :class:`CaseSkipped` when the hardware it needs (CUDA) is
absent. ``livescene stability`` and the pytest suite in ``tests/stability``
both call :func:`run_case`, so the table in the report and the tests can never
disagree about what was checked.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

GROUPS = ("numerics", "guards", "bad_input", "interrupted")
"""numerics: stiff and extreme inputs train and render finitely; guards: non-finite steps are contained;
bad_input: broken files are rejected with a message naming the file and the fix, nothing on disk changes;
interrupted: a killed run resumes to the same result."""


class CaseFailed(Exception):
    """A check of a case did not hold."""


class CaseSkipped(Exception):
    """The case cannot run on this machine (no CUDA)."""


def require(condition: bool, message: str) -> None:
    """Fail the case with ``message`` unless ``condition`` holds."""
    if not condition:
        raise CaseFailed(message)


@dataclass
class Outcome:
    """What a passing case measured."""

    metric: str
    """One line for the table, e.g. 'loss 0.21 -> 0.08, 0 skipped steps'."""
    values: dict[str, Any] = field(default_factory=dict)
    """The measured numbers behind the metric (JSON-serialisable)."""


@dataclass
class Case:
    """A registered case."""

    name: str
    """Short id (table row, pytest id)."""
    group: str
    """One of GROUPS."""
    checks: str
    """What the case asserts, in one sentence (docs/stability.md lists these)."""
    fn: Callable[[Any], Outcome]
    """The case body; takes a CaseContext."""


@dataclass
class CaseResult:
    """One row of the stability table."""

    name: str
    """The case's name."""
    group: str
    """The case's group (one of GROUPS)."""
    result: str
    """pass, fail, skip or error (an unexpected exception: a bug the case found)."""
    metric: str
    """The one-line measurement of a passing case ('-' otherwise)."""
    checks: str
    """What the case asserts."""
    seconds: float
    """Wall time of the case, including building its inputs."""
    values: dict[str, Any] = field(default_factory=dict)
    """The numbers behind the metric."""
    detail: str = ""
    """Why it failed or was skipped."""

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "group": self.group, "result": self.result, "metric": self.metric,
                "checks": self.checks, "seconds": round(self.seconds, 2), "values": self.values,
                "detail": self.detail}


CASES: dict[str, Case] = {}


def case(name: str, group: str, checks: str) -> Callable[[Callable[[Any], Outcome]], Callable[[Any], Outcome]]:
    """Register ``fn`` as a stability case."""
    if group not in GROUPS:
        raise ValueError(f"unknown group {group!r}; use one of {GROUPS}")

    def register(fn: Callable[[Any], Outcome]) -> Callable[[Any], Outcome]:
        if name in CASES:
            raise ValueError(f"stability case {name!r} registered twice")
        CASES[name] = Case(name, group, checks, fn)
        return fn

    return register


def run_case(c: Case, ctx: Any) -> CaseResult:
    """Run one case and turn its outcome (or failure, skip, crash) into a table row."""
    t0 = time.perf_counter()
    try:
        out = c.fn(ctx)
        result, metric, values, detail = "pass", out.metric, out.values, ""
    except CaseSkipped as exc:
        result, metric, values, detail = "skip", "-", {}, str(exc)
    except CaseFailed as exc:
        result, metric, values, detail = "fail", "-", {}, str(exc)
    except Exception as exc:  # a crash is a finding too: keep the traceback for the report
        tb = traceback.format_exception(type(exc), exc, exc.__traceback__)
        result, metric, values, detail = "error", "-", {}, "".join(tb[-3:]).strip()
    return CaseResult(c.name, c.group, result, metric, c.checks, time.perf_counter() - t0, values, detail)
