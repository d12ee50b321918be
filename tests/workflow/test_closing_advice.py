"""The closing advice's reading of Snakemake's log (workflow/rules/plan.smk: log_text, failed_scenes, run_stopped),
called directly: plan.smk holds only functions, so it runs as Python with the names the workflow gives it. The
log lines are those Snakemake 9 writes (snakemake/logging.py, _format_job_error; the scheduler's stop messages);
tests/workflow/test_failed_rows.py runs the real thing."""

from __future__ import annotations

import shlex
from pathlib import Path

from workflow_copy import REPO


def plan_functions(selected: list[str], results: str = "results") -> dict:
    """The functions of plan.smk, with the sheet's selection and results folder of a run."""
    names = {"Path": Path, "shlex": shlex, "SELECTED": selected, "RESULTS": results}
    exec(compile((REPO / "workflow" / "rules" / "plan.smk").read_text(), "plan.smk", "exec"), names)
    return names


def job_started(scene: str, rule: str) -> str:
    return f"rule {rule}:\n    output: results/{scene}/{rule}\n    log: results/{scene}/logs/{rule}.log\n"


def job_failed(log: str, rule: str) -> str:
    return (
        f"Error in rule {rule}:\n    jobid: 3\n    output: x\n"
        f"    log: {log} (check log file(s) for error details)\n    shell:\n        false\n"
    )


def test_failed_scenes_are_those_of_the_error_blocks_in_the_selection():
    text = "".join(
        [
            job_started("good", "capture"),
            job_started("broken", "capture"),
            job_started("late", "capture"),
            job_failed("results/late/logs/train_livescene.log", "train"),
            job_failed("results/broken/logs/capture.log", "capture"),
            job_failed("results/late/logs/evaluate_livescene.log", "evaluate"),  # a second failure of 'late'
            job_failed("results/stability/stability.log", "stability"),  # not a scene's job
            job_failed("results/old/logs/capture.log", "capture"),  # a scene of the sheet this run does not build
        ]
    )
    functions = plan_functions(["good", "broken", "late"])
    assert functions["failed_scenes"](text) == ["late", "broken"]  # in the order of the log, each once
    assert functions["failed_scenes"]("".join(job_started(s, "capture") for s in ("good", "broken"))) == []
    # the results folder of the config, not the default's
    elsewhere = plan_functions(["broken"], results="/data/out")
    assert elsewhere["failed_scenes"](job_failed("/data/out/broken/logs/capture.log", "capture")) == ["broken"]
    assert elsewhere["failed_scenes"](job_failed("results/broken/logs/capture.log", "capture")) == []


def test_a_stopped_run_is_told_from_a_failed_one(tmp_path):
    functions = plan_functions(["one"])
    stopped = functions["run_stopped"]
    assert stopped("Terminating processes on user request, this might take some time.\n")  # Ctrl-C
    assert stopped("Will exit after finishing currently running jobs (scheduler).\n")  # SIGTERM
    assert not stopped(job_failed("results/one/logs/capture.log", "capture"))
    log = tmp_path / "snakemake.log"
    log.write_text("Terminating processes on user request, this might take some time.\n")
    # a log file that is gone counts empty; the others are read
    assert stopped(functions["log_text"]([str(tmp_path / "gone.log"), str(log)]))
    assert functions["log_text"](None) == "" and functions["log_text"]([str(tmp_path / "gone.log")]) == ""
