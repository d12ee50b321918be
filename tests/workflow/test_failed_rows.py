"""A row whose jobs fail: the run says that the index was not rebuilt, names the row and how to rebuild the index
from the rows that finished (Snakemake cannot build the index without every selected scene's page)."""

from __future__ import annotations

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
    assert "the jobs of broken failed" in run.output
    assert "snakemake --cores 2 --config only=good" in run.output
