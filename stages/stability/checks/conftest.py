"""Options, markers and fixtures of the stability checks.

``livescene stability`` passes its options as ``--stability-*`` (stages/stability/suite.py); a plain
``pytest stages/stability/checks --stability-quick`` runs the same checks. Every check gets the ``ctx``
fixture (scratch folder, quick switch, device, threads, capture presets, workflow checkout: one per
session, so inputs several checks share are built once) and the ``outcome`` fixture, on which it records
the one-line metric of the table. The checks' helpers use ``assert`` as the tests do; they are registered
for pytest's assertion rewriting here, before anything imports them, so no check vanishes under
``python -O``.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

_HELPERS = [f"stages.stability.checks.{m}" for m in ("brief_training", "tiny_scenes", "case_context")]
# modules imported by an earlier pytest session of this process were rewritten by it
pytest.register_assert_rewrite(*(m for m in _HELPERS if m not in sys.modules))

from stages.stability.collector import (  # noqa: E402  (after the rewrite registration)
    CHECKS_MARKER,
    GROUP_MARKER,
    GROUPS,
    OUTCOME,
    Outcome,
    SummaryCollector,
    case_checks,
    case_group,
)
from stages.stability.suite import CAPTURES_DIR  # noqa: E402

from .case_context import CaseContext  # noqa: E402


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("stability", "livescene stability (docs/stability.md)")
    group.addoption("--stability-quick", action="store_true",
                    help="fewer steps and frames; the checks are the same (livescene stability --quick)")
    group.addoption("--stability-threads", type=int, default=1, help="torch CPU threads (default 1)")
    group.addoption("--stability-workdir", type=Path, default=None,
                    help="keep the scratch files here (default: a pytest temporary folder)")
    group.addoption("--stability-workflow", type=Path, default=None,
                    help="a checkout of the workflow (Snakefile, workflow/, config/); without it the check "
                         "that dry-runs the workflow is skipped")
    group.addoption("--stability-captures", type=Path, default=None,
                    help=f"folder of capture presets (default: {CAPTURES_DIR})")
    group.addoption("--stability-case", action="append", default=[], metavar="NAME",
                    help="run only this case (exact name, repeatable)")
    group.addoption("--stability-group", action="append", default=[], choices=GROUPS,
                    help="run only this group (repeatable)")
    group.addoption("--stability-out", type=Path, default=None,
                    help="write the JSON summary here (livescene stability --out)")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{GROUP_MARKER}(name): the check's group, one of {', '.join(GROUPS)}")
    config.addinivalue_line("markers", f"{CHECKS_MARKER}(text): what one member of a parametrized family checks")
    config.addinivalue_line("markers", "slow: starts and kills real processes (tens of seconds)")
    if not any(isinstance(p, SummaryCollector) for p in config.pluginmanager.get_plugins()):
        # a plain pytest run: rows, selection and order as `livescene stability` has them
        config.pluginmanager.register(SummaryCollector(
            config.getoption("stability_case"), config.getoption("stability_group"),
            quick=config.getoption("stability_quick"), threads=config.getoption("stability_threads"), strict=True),
            "stability-summary")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every check names its group and says what it checks: the table has a row with both for it."""
    bad = [i.nodeid for i in items if case_group(i) not in GROUPS or not case_checks(i)]
    if bad:
        raise pytest.UsageError(f"stability checks without a group marker or a docstring: {bad}")


@pytest.hookimpl(trylast=True)  # after the collector has taken the time
def pytest_sessionfinish(session: pytest.Session) -> None:
    out = session.config.getoption("stability_out")
    collector = session.config.pluginmanager.get_plugin("stability-summary")
    if out is not None and collector is not None:
        from stages.scene import write_json

        write_json(out, collector.summary())


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A check that passed must have recorded its metric: the table shows it and the report includes it."""
    result = yield
    outcome = item.stash.get(OUTCOME, None)
    assert outcome is not None and outcome.metric, (
        f"{item.name} passed without recording its metric (outcome.record(metric, values))")
    return result


@pytest.fixture(scope="session")
def ctx(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[CaseContext]:
    """The run's settings and scratch folder; torch is pinned to ``--stability-threads`` and given back after."""
    import torch

    option = request.config.getoption
    workdir = option("stability_workdir") or tmp_path_factory.mktemp("stability")
    threads = torch.get_num_threads()
    torch.set_num_threads(max(option("stability_threads"), 1))
    try:
        yield CaseContext(workdir, captures=option("stability_captures") or CAPTURES_DIR,
                          quick=option("stability_quick"), threads=option("stability_threads"),
                          workflow=option("stability_workflow"))
    finally:
        torch.set_num_threads(threads)  # the caller (a test session, the CLI's process) gets its own back


@pytest.fixture
def outcome(request: pytest.FixtureRequest) -> Outcome:
    """Where a check records its metric and the numbers behind it (the table row and the summary's values)."""
    record = Outcome()
    request.node.stash[OUTCOME] = record
    return record
