"""Rules hold no path of the checkout or of its environment: a moved workflow (or a second clone with the
same results) has nothing to rerun."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from workflow_copy import WorkflowCopy


def test_moved_workflow_reruns_nothing(tmp_path):
    wf = WorkflowCopy(tmp_path / "first")
    wf.write_scenes([{"scene": "tiny", "source": "synthetic", "path": "config/captures/tiny.yaml",
                      "methods": "livescene"}])
    built = wf.snakemake("--cores", "1", "results/tiny/capture")
    assert built.code == 0, built.output[-3000:]

    moved = WorkflowCopy.__new__(WorkflowCopy)
    moved.root = Path(shutil.move(wf.root, tmp_path / "elsewhere"))
    again = moved.snakemake("-n", "--cores", "1", "results/tiny/capture")
    assert again.code == 0 and "Nothing to be done" in again.output, again.output[-3000:]

    plan = moved.dry_run()  # prints every shell command of the default job
    commands = "\n".join(text for _, text in plan.blocks())
    assert "livescene poses --frames results/tiny/frames" in commands
    for prefix in (str(moved.root), str(tmp_path), str(Path(sys.executable).parent)):
        assert prefix not in commands, prefix
