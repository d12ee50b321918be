"""The report's "Object masks" section (stages/report/labels_section.py) on real labels outputs."""

from __future__ import annotations

import json
from pathlib import Path

from labelset_writers import write_png

from stages.labels import LabelsConfig, ingest_labels
from stages.report.inputs import ReportInputs
from stages.report.labels_section import section_labels
from stages.report.scene_data import SceneData


def scene(results: Path) -> SceneData:
    labels = results / "labels" / "labels.json"
    return SceneData(scene="s", plan={}, benchmarks={}, inputs=ReportInputs(labels=results / "labels"),
                     labels=json.loads(labels.read_text()) if labels.is_file() else None)


def test_section_shows_leave_one_out_and_confidence(label_files):
    src = write_png(label_files.root, label_files.labels)  # frames 0, 2, 4 annotated; 6 propagated
    results = label_files.root / "results"
    ingest_labels(LabelsConfig(input=src, frames=label_files.frames, out=results / "labels", progress=False))
    report = json.loads((results / "labels" / "propagation.json").read_text())
    html = section_labels(scene(results))
    assert "3 of 4 frames annotated" in html and "1 frames propagated from the 3 annotated ones" in html
    for row in report["leave_one_out"]["frames"]:  # one table row per held-out frame
        assert f"<td>{row['frame']}</td>" in html
    assert "IoU door" in html and "IoU fridge" in html
    assert "<svg" in html and "Confidence of the propagated masks" in html
    assert "Weakest held-out frame" in html


def test_section_without_propagation_says_why(label_files):
    results = label_files.root / "results"
    assert "labels rule skipped: no masks" in section_labels(scene(results), "labels rule skipped: no masks")
    src = write_png(label_files.root, label_files.labels)
    ingest_labels(LabelsConfig(input=src, frames=label_files.frames, out=results / "labels", progress=False,
                               missing_masks="leave"))
    assert "1 frames have no mask and were not propagated" in section_labels(scene(results))
    full = dict(label_files.labels, **{"00006": label_files.labels["00000"]})
    src = write_png(label_files.root / "full", full)
    ingest_labels(LabelsConfig(input=src, frames=label_files.frames, out=results / "labels", progress=False))
    html = section_labels(scene(results))
    assert "4 of 4 frames annotated" in html and "Every frame is annotated: nothing was propagated." in html
