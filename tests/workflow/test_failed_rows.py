"""A row whose jobs fail: the run says that the index was not rebuilt, names the row and how to rebuild the index
from the rows that finished (Snakemake cannot build the index without every selected scene's page)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import yaml
from workflow_copy import REPO, WorkflowCopy


def test_a_failed_row_is_named_with_the_command_that_rebuilds_the_index(tmp_path):
    spec = yaml.safe_load((REPO / "config" / "captures" / "tiny.yaml").read_text())
    spec["objects"][0]["kind"] = "slidingthing"  # refused by the capture stage, when its job runs
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(spec))
    wf = WorkflowCopy(tmp_path / "wf")
    wf.write_scenes([
        {"scene": "good", "source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene"},
        {"scene": "broken", "source": "synthetic", "path": bad, "methods": "livescene"}])
    run = wf.snakemake("--cores", "2", "--keep-going", "results/good/capture", "results/broken/capture")
    assert run.code != 0
    assert (wf.root / "results" / "good" / "capture").is_dir()  # --keep-going: the other row's job ran
    assert "reports/index.html and reports/verdicts.csv were not rebuilt" in run.output
    assert "the jobs of broken failed (their logs are named above: fix what they say" in run.output
    # the user's own command, not a stock one that drops their --configfile or profile
    assert ("run the same command with only=good among its --config values (snakemake --cores 2 --keep-going "
            "results/good/capture results/broken/capture)") in run.output


def test_a_stopped_run_says_to_run_the_same_command_again(tmp_path):
    """Ctrl-C while a job runs: the jobs did not fail, so the advice is to rerun, not to fix rows."""
    # a capture of many frames: its job is still running when the signal comes, however fast the machine
    spec = yaml.safe_load((REPO / "config" / "captures" / "tiny.yaml").read_text())
    spec["video"]["n_frames"] = 3000
    long = tmp_path / "long.yaml"
    long.write_text(yaml.safe_dump(spec))
    wf = WorkflowCopy(tmp_path / "wf")
    wf.write_scenes([
        {"scene": "one", "source": "synthetic", "path": long, "methods": "livescene"},
        {"scene": "two", "source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene"}])
    out = tmp_path / "snakemake.out"
    with out.open("w") as sink:
        # SIGINT at its default: a shell without job control (CI, `make test &`) starts its children ignoring it
        proc = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "1", "results/one/capture"],
                                cwd=wf.root, stdout=sink, stderr=subprocess.STDOUT, start_new_session=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        deadline = time.monotonic() + 120
        while "rule capture:" not in out.read_text() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert "rule capture:" in out.read_text(), out.read_text()[-2000:]
        time.sleep(1.0)  # the job has started (3000 frames take minutes to render)
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the terminal's whole process group
        proc.wait(timeout=120)
    assert not (wf.root / "results" / "one" / "capture").exists()  # stopped mid-job
    output = out.read_text()
    assert proc.returncode != 0
    assert "the jobs of one did not finish: the run was stopped. Run the same command again" in output, output[-3000:]
    assert "fix what they say" not in output and "only=two" not in output  # nothing of "two" ran either
