"""The pytest plugin that turns each stability check into one row of the summary the report includes.

The checks are plain pytest tests (``stages/stability/checks``); this plugin is what makes a pytest
run of them a ``livescene stability`` run: it selects cases by exact name and group, orders them by
group, records each case's outcome (pass / fail / error / skip, the one-line metric the test recorded,
the reason of a failure or skip, the seconds) and builds the JSON summary whose format the report
reads (docs/stability.md). It imports neither torch nor the checks, so ``--help`` stays fast.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pytest

from stages.scene.machine import machine_info

SUMMARY_FORMAT = 1
"""Version of the summary JSON (the report reads it; bump it only with the report)."""

GROUPS = ("numerics", "guards", "bad_input", "interrupted")
"""numerics: stiff and extreme inputs train and render finitely; guards: non-finite steps are contained;
bad_input: broken files are rejected with a message naming the file and the fix, nothing on disk changes;
interrupted: a killed run resumes to the same result."""

GROUP_MARKER = "stability_group"
"""``@pytest.mark.stability_group("numerics")``: the group of a check (a module's ``pytestmark``)."""
CHECKS_MARKER = "stability_checks"
"""``pytest.param(..., marks=pytest.mark.stability_checks("..."))``: what one member of a family checks
(a plain test says it in its docstring)."""


@dataclass
class Outcome:
    """What a passing check measured; the ``outcome`` fixture hands one to every check."""

    metric: str = ""
    """One line for the table, e.g. 'loss 0.21 -> 0.08, 0 skipped steps'."""
    values: dict[str, Any] = field(default_factory=dict)
    """The measured numbers behind the metric (JSON-serialisable)."""

    def record(self, metric: str, values: dict[str, Any] | None = None) -> None:
        """Set the table's metric and the numbers behind it (call once, when every check has held)."""
        self.metric = metric
        self.values = dict(values or {})


OUTCOME = pytest.StashKey[Outcome]()
"""Where the ``outcome`` fixture leaves a check's Outcome on its test item."""


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


# -- what a test item says about itself ---------------------------------------------------------------------------


def case_name(item: pytest.Item) -> str:
    """The row name: the test's name without ``test_``, plus ``_<id>`` for a member of a parametrized family
    (``test_units[0.001x]`` -> ``units_0.001x``)."""
    base = getattr(item, "originalname", None) or item.name.split("[", 1)[0]
    base = base.removeprefix("test_")
    callspec = getattr(item, "callspec", None)
    return f"{base}_{callspec.id}" if callspec is not None else base


def case_group(item: pytest.Item) -> str:
    mark = item.get_closest_marker(GROUP_MARKER)
    return str(mark.args[0]) if mark is not None and mark.args else ""


def case_checks(item: pytest.Item) -> str:
    """What the case asserts: its ``stability_checks`` marker, else the first paragraph of its docstring."""
    mark = item.get_closest_marker(CHECKS_MARKER)
    if mark is not None and mark.args:
        return " ".join(str(mark.args[0]).split())
    doc = getattr(getattr(item, "function", None), "__doc__", None) or ""
    return " ".join(doc.strip().split("\n\n", 1)[0].split())


def failure_message(exc: BaseException) -> str:
    """The message of a failed check, without pytest's assertion introspection (``assert x == y ...``)."""
    msg = getattr(exc, "msg", None)  # pytest.fail / pytest.skip
    text = str(msg) if isinstance(msg, str) else str(exc)
    if isinstance(exc, AssertionError) and not text.startswith("assert "):
        # a rewritten `assert cond, message` reads "message\nassert <explanation>"; continuation lines of the
        # message are indented by two spaces, so the first unindented "assert " line starts the explanation
        text = text.split("\nassert ", 1)[0].replace("\n  ", "\n")
    return text.strip()


# -- the plugin ---------------------------------------------------------------------------------------------------


class SummaryCollector:
    """pytest plugin: exact selection by case name and group, group order, one CaseResult per case.

    ``cases`` / ``groups``: run only these. An unknown case name sets :attr:`error` (listing the known
    ones) and runs nothing; with ``strict`` it is also a pytest usage error, which is what a plain pytest
    run needs to stop (``livescene stability`` prints the error itself). ``on_result`` is called with
    each finished row.
    """

    def __init__(self, cases: list[str] | None = None, groups: list[str] | None = None, *, quick: bool = False,
                 threads: int = 1, on_result: Callable[[CaseResult], None] | None = None,
                 strict: bool = False) -> None:
        self.strict = strict
        self.cases = list(cases or [])
        self.groups = list(groups or [])
        self.quick = quick
        self.threads = threads
        self.on_result = on_result
        self.collected: list[dict[str, Any]] = []
        """Every selected case: name, group, checks, nodeid and markers (what ``--list`` prints)."""
        self.rows: list[CaseResult] = []
        self.error = ""
        """Why the run could not start (an unknown case name); empty otherwise."""
        self._partial: dict[str, dict[str, Any]] = {}
        self._t0: float | None = None
        self._seconds = 0.0

    # selection and order
    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, session: pytest.Session, config: pytest.Config,
                                      items: list[pytest.Item]) -> None:
        names = {case_name(i) for i in items}
        unknown = sorted(set(self.cases) - names)
        if unknown:
            self.error = f"unknown stability cases {unknown}; known: {sorted(names)}"
            if self.strict:
                raise pytest.UsageError(self.error)
        keep = [i for i in items if not unknown and (not self.cases or case_name(i) in self.cases)
                and (not self.groups or case_group(i) in self.groups)]
        drop = [i for i in items if i not in keep]
        if drop:
            config.hook.pytest_deselected(items=drop)
        rank = {g: k for k, g in enumerate(GROUPS)}
        keep.sort(key=lambda i: rank.get(case_group(i), len(GROUPS)))  # numerics first, as the table reads
        items[:] = keep
        self.collected = [{"name": case_name(i), "group": case_group(i), "checks": case_checks(i),
                           "nodeid": i.nodeid, "markers": sorted({m.name for m in i.iter_markers()})} for i in keep]

    # outcomes
    def pytest_collection_finish(self, session: pytest.Session) -> None:
        self._t0 = time.perf_counter()  # the seconds of the summary are those of the cases, not of the imports

    @pytest.hookimpl(wrapper=True, tryfirst=True)  # outermost: sees the report after the xfail handling
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
        report = yield
        row = self._partial.setdefault(item.nodeid, {"result": "pass", "detail": "", "seconds": 0.0})
        row["seconds"] += call.duration
        if call.excinfo is not None and row["result"] == "pass":
            exc = call.excinfo.value
            wasxfail = getattr(report, "wasxfail", None)
            if isinstance(exc, pytest.skip.Exception) and wasxfail is None:
                row["result"], row["detail"] = "skip", failure_message(exc)
            elif wasxfail is not None:  # a known gap of another stage: still a failed check in the summary
                row["result"], row["detail"] = "fail", f"known gap ({wasxfail}): {failure_message(exc)}"
            elif isinstance(exc, AssertionError | pytest.fail.Exception):
                row["result"], row["detail"] = "fail", failure_message(exc)
            else:  # a crash is a finding too: keep the traceback's tail for the report
                tb = traceback.format_exception(type(exc), exc, exc.__traceback__)
                row["result"], row["detail"] = "error", "".join(tb[-3:]).strip()
        elif report.skipped and row["result"] == "pass":  # a skip marker: no exception to read
            reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
            row["result"], row["detail"] = "skip", str(reason).removeprefix("Skipped: ")
        if call.when == "teardown":
            self._finish(item, self._partial.pop(item.nodeid))
        return report

    def _finish(self, item: pytest.Item, row: dict[str, Any]) -> None:
        outcome = item.stash.get(OUTCOME, None)
        passed = row["result"] == "pass"
        metric = (outcome.metric if outcome is not None and outcome.metric else "-") if passed else "-"
        values = outcome.values if passed and outcome is not None else {}
        result = CaseResult(case_name(item), case_group(item), row["result"], metric, case_checks(item),
                            row["seconds"], values, row["detail"])
        self.rows.append(result)
        if self.on_result is not None:
            self.on_result(result)

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        if self._t0 is not None:
            self._seconds = time.perf_counter() - self._t0

    # the summary
    def summary(self) -> dict[str, Any]:
        """The JSON summary of the run (format SUMMARY_FORMAT; docs/stability.md lists the keys)."""
        counts = Counter(r.result for r in self.rows)
        torch = sys.modules.get("torch")  # loaded by the checks; a run that collected nothing has none
        cuda = torch.cuda.get_device_name(0) if torch is not None and torch.cuda.is_available() else None
        return {
            "format": SUMMARY_FORMAT,
            "quick": self.quick,
            "counts": {k: counts.get(k, 0) for k in ("pass", "fail", "error", "skip")},
            "seconds": round(self._seconds, 1),
            # torch: None where no check loaded it (machine_info then leaves the key out)
            "machine": {**machine_info(), "torch": torch.__version__ if torch else None, "cuda": cuda,
                        "threads": self.threads},
            "cases": [r.to_dict() for r in self.rows],
        }
