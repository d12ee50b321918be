"""Per-stage digests (stages/report/digests.py): where two runs of the same job part (docs/workflow.md, "Where two
runs part")."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from report_browser import fake_inputs, make_fake_results

from stages.report.cli import main as report_main
from stages.report.digests import StageRule, digest_path, digests_csv, stage_digests
from stages.report.inputs import inputs_from_mapping
from stages.report.scene_data import collect_scene
from stages.report.scene_page import build_scene_page, scene_summary, section_digests

METHODS = ["livescene", "conerf"]

COVERED = {
    "capture": ["capture/capture.json", "capture/video.mp4", "capture/truth/states.csv"],
    "frames": ["frames/frames.csv", "frames/frames.json", "frames/images/frame_00000.png"],
    "poses": ["poses/poses.json", "poses/transforms.json", "poses/sparse/0/images.bin"],
    "labels": ["labels/labels.json", "labels/masks/00000.npy"],
    "states": ["states/states.csv"],
    "dataset": ["dataset/transforms.json", "dataset/images/frame_00000.png"],
    "language": ["language/targets.npz"],
    "exposure": ["exposure.json"],
    "run/livescene": ["runs/livescene/model.pt", "runs/livescene/run.json", "runs/livescene/config.yaml"],
    "run/conerf": ["runs/conerf/model.pt"],
    "eval/livescene": ["eval/livescene/metrics.json", "eval/livescene/renders/00001.png"],
    "eval/conerf": ["eval/conerf/metrics.json"],
}
LEFT_OUT = [
    "runs/livescene/train_log.csv",
    "runs/livescene/checkpoints/step_000010.pt",
    "runs/livescene/checkpoints/run.json",
    "eval/livescene/timings.json",
    "frames/.livescene-stage",
    "dataset/.snakemake_timestamp",
]


def _results(root: Path) -> dict:
    """A tiny results tree of every digested stage (bytes made up, names and JSON keys as the stages write) and
    its report inputs manifest."""
    files = {rel: f"{rel} v1\n".encode() for names in COVERED.values() for rel in names}
    files |= {rel: b"volatile\n" for rel in LEFT_OUT}
    files["capture/capture.json"] = json.dumps({"n_frames": 2, "timings": {"total_s": 6.4}}).encode()
    files["frames/frames.json"] = json.dumps(
        {"n_frames": 2, "source": "/home/a/results/demo/capture/video.mp4", "timings": {"total": 0.2}}
    ).encode()
    files["poses/poses.json"] = json.dumps(
        {"n_registered": 2, "timings": {"total": 17.4}, "motion_precheck": {"seconds": 0.27, "pairs": 3}}
    ).encode()
    files["runs/livescene/run.json"] = json.dumps(
        {
            "steps": 10,
            "train_seconds": 87.4,
            "peak_memory_mib": 583.0,
            "peak_memory_kind": "process max RSS",
            "peak_reserved_mib": None,
            "machine": {"cpu": "A"},
            "code_digest": "13c4",
            "data_digest": "fdac",
        }
    ).encode()
    for rel, data in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    return {
        "capture": str(root / "capture"),
        "truth": str(root / "capture"),
        "frames": str(root / "frames"),
        "poses": str(root / "poses"),
        "labels": str(root / "labels"),
        "states": str(root / "states"),
        "dataset": str(root / "dataset"),
        "language": str(root / "language" / "targets.npz"),
        "exposure": str(root / "exposure.json"),
        "benchmarks": str(root / "benchmarks"),
        "runs": {m: str(root / "runs" / m / "run.json") for m in METHODS},
        "eval": {m: str(root / "eval" / m) for m in METHODS},
    }


def _digests(manifest: dict) -> dict[str, str | None]:
    return {d.stage: d.digest for d in stage_digests(inputs_from_mapping(manifest), METHODS)}


def test_a_digest_hashes_each_files_path_size_and_bytes_in_sorted_path_order(tmp_path):
    (tmp_path / "b.txt").write_bytes(b"xy")
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "z.bin").write_bytes(b"\x00\x01\x02")
    (tmp_path / ".marker").write_bytes(b"done")
    (tmp_path / ".partial").mkdir()  # a hidden folder, and all it holds
    (tmp_path / ".partial" / "c.txt").write_bytes(b"half")
    files, digest = digest_path(tmp_path)
    # "a/z.bin" sorts before "b.txt"; the hidden marker and folder are left out
    assert files == 2
    assert digest == hashlib.sha256(b"a/z.bin\x003\x00\x00\x01\x02" + b"b.txt\x002\x00xy").hexdigest()
    # a file's own digest names it by its file name
    assert digest_path(tmp_path / "b.txt") == (1, hashlib.sha256(b"b.txt\x002\x00xy").hexdigest())
    assert digest_path(tmp_path / "absent") == (0, None)


def test_a_json_file_is_digested_without_its_volatile_keys_as_canonical_json(tmp_path):
    (tmp_path / "run.json").write_text('{"timings": {"total": 3.5, "n": 2},\n "steps": 10}')  # keys sorted below
    rule = StageRule(json_keys={"run.json": ("timings.total",)})
    canonical = b'{"steps":10,"timings":{"n":2}}'
    expected = hashlib.sha256(b"run.json\x00%d\x00" % len(canonical) + canonical).hexdigest()
    assert digest_path(tmp_path, rule) == (1, expected)
    # a file that does not parse is hashed as it is
    (tmp_path / "run.json").write_bytes(b"{broken")
    assert digest_path(tmp_path, rule) == (1, hashlib.sha256(b"run.json\x007\x00{broken").hexdigest())


def test_a_one_byte_change_moves_its_stages_digest_alone(tmp_path):
    manifest = _results(tmp_path)
    before = _digests(manifest)
    assert list(before) == list(COVERED)  # pipeline order: single stages, then runs, then evaluations
    assert all(len(d) == 12 for d in before.values())
    for stage, names in COVERED.items():
        for rel in names:
            path = tmp_path / rel
            data = path.read_bytes()
            path.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
            after = _digests(manifest)
            assert {s for s in after if after[s] != before[s]} == {stage}, rel
            path.write_bytes(data)
    assert _digests(manifest) == before


def test_what_records_time_machine_or_paths_moves_no_digest(tmp_path):
    manifest = _results(tmp_path)
    before = _digests(manifest)
    for rel in LEFT_OUT:
        (tmp_path / rel).write_bytes(b"another machine, another hour\n")
    (tmp_path / "capture" / "capture.json").write_text(json.dumps({"n_frames": 2, "timings": {"total_s": 13.5}}))
    (tmp_path / "frames" / "frames.json").write_text(
        json.dumps(
            {"timings": {"total": 0.4}, "source": "/tmp/elsewhere/results/demo/capture/video.mp4", "n_frames": 2}
        )
    )
    (tmp_path / "poses" / "poses.json").write_text(
        json.dumps({"n_registered": 2, "timings": {"total": 31.0}, "motion_precheck": {"pairs": 3, "seconds": 0.53}})
    )
    (tmp_path / "runs" / "livescene" / "run.json").write_text(
        json.dumps(
            {
                "steps": 10,
                "train_seconds": 154.2,
                "peak_memory_mib": 574.5,
                "peak_memory_kind": "cuda max allocated",
                "peak_reserved_mib": 900.0,
                "machine": {"cpu": "B"},
                "code_digest": "8ba0",
                "data_digest": "fdac",
            }
        )
    )
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "train_livescene.tsv").write_text("s\n154.2\n")
    assert _digests(manifest) == before
    # the keys kept are covered: another step count is another run
    run_json = tmp_path / "runs" / "livescene" / "run.json"
    run_json.write_text(run_json.read_text().replace('"steps": 10', '"steps": 11'))
    after = _digests(manifest)
    assert {s for s in after if after[s] != before[s]} == {"run/livescene"}


def test_the_page_summary_and_digests_csv_show_each_stage(tmp_path, tiny_dataset):
    res = make_fake_results(tmp_path, tiny_dataset.root)
    (res / "frames").mkdir()
    (res / "frames" / "frames.csv").write_text("frame,source_index\n")
    manifest = fake_inputs(res, tiny_dataset.root) | {
        "frames": str(res / "frames"),
        "exposure": str(tmp_path / "absent.json"),
    }
    sd = collect_scene("fake", inputs_from_mapping(manifest), plan={})
    html = section_digests(sd)
    stages = [
        "frames",
        "poses",
        "states",
        "dataset",
        "exposure",
        "run/livescene",
        "run/conerf",
        "eval/livescene",
        "eval/conerf",
    ]
    assert [d.stage for d in sd.digests] == stages
    frames = hashlib.sha256(b"frames.csv\x0019\x00frame,source_index\n").hexdigest()[:12]
    assert (
        f'<td>frames</td><td class="num">1</td><td>frames.json without timings, source</td><td><code>{frames}' in html
    )
    assert f"not found: {tmp_path / 'absent.json'}" in html
    assert "checkpoints/; train_log.csv; run.json without train_seconds" in html
    assert 'id="digests"' in build_scene_page(sd)
    summary = scene_summary(sd, page="scenes/fake.html")
    assert summary["digests"][0] == {"stage": "frames", "files": 1, "digest": frames}
    assert summary["digests"][4] == {"stage": "exposure", "files": 0, "digest": None}
    # the index writes every scene's rows, in the summaries' order
    other = {
        "scene": "b",
        "page": "b.html",
        "methods": {},
        "digests": [{"stage": "poses", "files": 9, "digest": "5ddcbd9f7ba0"}],
    }
    paths = []
    for i, s in enumerate([summary, other]):
        paths.append(tmp_path / f"s{i}.json")
        paths[-1].write_text(json.dumps(s))
    out = tmp_path / "reports" / "digests.csv"
    assert (
        report_main(
            [
                "index",
                "--summaries",
                *map(str, paths),
                "--out",
                str(tmp_path / "reports" / "index.html"),
                "--digests",
                str(out),
            ]
        )
        == 0
    )
    lines = out.read_text().splitlines()
    assert lines[0] == "scene,stage,files,digest"
    assert lines[1] == f"fake,frames,1,{frames}"
    assert "fake,exposure,0," in lines
    assert lines[-1] == "b,poses,9,5ddcbd9f7ba0"
    assert out.read_text() == digests_csv([summary, other])
