"""SIGTERM, how Snakemake cancels a job, unwinds each command's atomic writes as Ctrl-C does: before, the default
action killed the process and left its hidden temporary (a capture's, a video's frames) until the next run."""

from __future__ import annotations

import importlib
import signal
import subprocess
import sys
import time
from pathlib import Path

from stages.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]

# Commands (or subcommands) whose SIGTERM keeps its default action, and why.
KEEP_DEFAULT = {
    "poses": "COLMAP's mapping is one long C call: a handler would wait for it to return",
    "dataset.orient": "its triangulation is one long COLMAP call",
    "train": "its own handler saves a checkpoint and leaves the run resumable",
    "compare": "its trainings run as child processes with their own handlers",
    "stability": "pytest's own process",
    "view": "a server: the default action stops it",
}


def test_every_command_that_writes_atomically_unwinds_on_sigterm():
    for name, (module, _) in COMMANDS.items():
        mod = importlib.import_module(module)
        mains = {n: f for n, f in vars(mod).items() if hasattr(f, "unwinds_sigterm")}  # the @cli_errors functions
        assert mains or name in KEEP_DEFAULT, f"{module}: no @cli_errors main"
        for fn_name, fn in mains.items():
            key = name if fn_name == "main" else f"{name}.{fn_name}"
            assert fn.unwinds_sigterm == (key not in KEEP_DEFAULT and name not in KEEP_DEFAULT), key


def test_a_terminated_capture_leaves_no_temporary(tmp_path):
    spec = ROOT / "config" / "captures" / "tiny.yaml"
    out = tmp_path / "cap"
    proc = subprocess.Popen([sys.executable, "-m", "stages.cli", "capture", "--spec", str(spec), "--out", str(out),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not any(p.name.startswith(".cap.") for p in tmp_path.iterdir()):  # the capture's temporary folder
        assert proc.poll() is None, f"the capture ended before it was signalled: {proc.communicate()}"
        assert time.monotonic() < deadline, "no temporary folder within 60 s"
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "terminated: this command's output was not written" in err
    assert list(tmp_path.iterdir()) == []  # neither the capture nor its temporary
