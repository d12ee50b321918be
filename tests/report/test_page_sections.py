"""The scene page's sections, cell by cell: each number in its method's row and its own column, the plots' axes,
the images under their captions, the warnings where they apply (fake stage outputs of report_browser.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path

from report_browser import fake_inputs, make_fake_results

from stages.report.export_section import section_export
from stages.report.images import png_data_uri, read_rgb
from stages.report.inputs import ReportInputs, inputs_from_mapping
from stages.report.labels_section import section_labels
from stages.report.scene_data import MethodData, SceneData, collect_scene
from stages.report.scene_page import (
    _beyond_note,
    _interval,
    build_scene_page,
    scene_summary,
    section_commands,
    section_curves,
    section_grid,
    section_locality,
    section_methods,
    section_poses,
    section_rules,
    section_sliders,
    section_stability,
    section_states,
    section_timings,
    section_unseen,
    section_verdict,
)
from tests.conftest import make_tiny_dataset

PLAN = {
    "capture": {"needed": True},
    "poses": {"needed": True},
    "train[livescene]": {"needed": True},
    "train[conerf]": {"needed": True},
    "evaluate[livescene]": {"needed": True},
    "labels": {"needed": False, "why": "scene has no masks"},
    "train[mk-planes]": {"needed": False, "why": "method not listed for this scene"},
    "train[k-planes]": {"needed": False, "why": "method not listed for this scene"},
}


def _rows(html: str) -> list[list[str]]:
    """The body rows of the (first) table in ``html`` as lists of cell HTML."""
    body = html.split("<tbody>", 1)[1].split("</tbody>", 1)[0]
    return [re.findall(r"<td[^>]*>(.*?)</td>", row) for row in re.findall(r"<tr>(.*?)</tr>", body)]


def _headers(html: str) -> list[str]:
    return re.findall(r"<th>(.*?)</th>", html.split("<thead>", 1)[1].split("</thead>", 1)[0])


def _scene(tmp_path: Path, tiny_dataset, methods: list[str] | None = None, edit=None, **extra) -> SceneData:
    res = make_fake_results(tmp_path, tiny_dataset.root)
    if edit is not None:
        edit(res)
    manifest = fake_inputs(res, tiny_dataset.root) | extra
    return collect_scene("fake", inputs_from_mapping(manifest), methods=methods, plan=PLAN)


def _edit_json(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def test_methods_table_puts_each_number_in_its_method_row_and_column(tmp_path, tiny_dataset):
    def edit(res: Path) -> None:
        def split(m: dict) -> None:
            m["held_out"]["psnr_objects"] = {"mean": 17.25}
            m["held_out"]["psnr_static"] = {"mean": 23.75}

        _edit_json(res / "eval" / "livescene" / "metrics.json", split)
        _edit_json(res / "runs" / "conerf" / "run.json", lambda r: r.update(train_seconds=98.5))

    sd = _scene(tmp_path, tiny_dataset, ["livescene", "conerf", "mk-planes"], edit)
    html = section_methods(sd)
    head = _headers(html)
    rows = {re.sub(r"<.*", "", r[0]): dict(zip(head, r, strict=True)) for r in _rows(html)}
    live, conerf = rows["livescene"], rows["conerf"]
    assert (live["PSNR dB"], live["PSNR objects dB"], live["PSNR static dB"]) == ("20.000", "17.250", "23.750")
    assert (conerf["PSNR dB"], conerf["PSNR objects dB"], conerf["PSNR static dB"]) == ("21.000", "–", "–")
    assert (live["train s"], live["steps"], conerf["train s"], conerf["steps"]) == ("150.000", "400", "98.500", "401")
    assert live["parameters"] == "1,000,000" and conerf["parameters"] == "1,000,001"
    assert live["trust"].startswith('<span class="ok">ok</span>') and "undertrained" in conerf["trust"]
    # a method of the manifest that did not train still gets its row, saying why
    assert (
        "rule train[mk-planes] skipped for this scene: method not listed for this scene" in rows["mk-planes"]["trust"]
    )
    # the flagged run is named in a banner above the table
    banner = html.index('<p class="flag">&#9888; Not results: conerf (undertrained).')
    assert banner < html.index("<table")


def test_grid_shows_each_methods_render_and_psnr_under_its_view(tmp_path, tiny_dataset):
    sd = _scene(tmp_path, tiny_dataset)
    html = section_grid(sd, views=2)
    assert _headers(html) == ["view", "truth", "livescene", "livescene error", "conerf", "conerf error"]
    rows = _rows(html)
    test_ids = [f.frame_id for f in tiny_dataset.frames_in("test")]
    assert [r[0] for r in rows] == test_ids[:2]  # --views 2: two views
    for i, (fid, row) in enumerate(zip(test_ids, rows, strict=False)):
        # the fakes: view i of method k has PSNR 20 + k + 0.5 i
        assert row[2].endswith(f"PSNR {20.0 + 0.5 * i:.2f}") and row[4].endswith(f"PSNR {21.0 + 0.5 * i:.2f}")
        for cell, method in ((row[2], "livescene"), (row[4], "conerf")):
            render = read_rgb(tmp_path / "fake" / "eval" / method / "renders" / f"{fid}.png")
            assert png_data_uri(render) in cell and f'alt="{method} {fid}"' in cell
        assert png_data_uri(read_rgb(tiny_dataset.root / f"images/frame_{fid}.png")) in row[1]


def test_curves_plot_steps_and_seconds_on_their_own_axes():
    """Logged steps 0, 100, 200 (wall 0, 5, 10 s), closed by run.json's final evaluation at 300 steps, 15 s; a run
    whose last logged step is its last step gets no second point there."""
    log = ([0.0, 5.0, 10.0], [12.0, 13.0, 14.0], [0.0, 5.0, 10.0], [0.3, 0.2, 0.1])
    log_steps = ([0.0, 100.0, 200.0], log[1], [0.0, 100.0, 200.0], log[3])
    a = MethodData(
        "livescene", run={"eval_psnr": 15.0, "steps": 300, "train_seconds": 15.0}, curve=log, step_curve=log_steps
    )
    b = MethodData(
        "conerf", run={"eval_psnr": 14.0, "steps": 200, "train_seconds": 10.0}, curve=log, step_curve=log_steps
    )
    html = section_curves(SceneData(scene="s", plan={}, benchmarks={}, methods=[a, b]))
    svgs = html.split("<svg")[1:]
    assert len(svgs) == 4
    points = [re.findall(r'points="([^"]*)"', s) for s in svgs]
    assert [len(p.split()) for p in points[0]] == [4, 3]  # final evaluation added for livescene only
    assert [len(p.split()) for p in points[2]] == [4, 3]
    x_ticks = [re.findall(r'text-anchor="middle" font-size="11">([^<]+)</text>', s) for s in svgs]
    assert x_ticks[0] == ["0", "100", "200", "300"]  # held-out error against steps
    assert x_ticks[1] == ["0", "50", "100", "150", "200"]  # training loss against steps
    assert x_ticks[2] == ["0", "5", "10", "15"]  # held-out error against run time
    assert x_ticks[3] == ["0", "2", "4", "6", "8", "10"]  # training loss against run time
    assert "held-out error against steps" in svgs[0] and "training loss against steps" in svgs[1]


def test_locality_rows_give_each_method_its_own_verdict(tmp_path, tiny_dataset):
    rows = _rows(section_locality(_scene(tmp_path, tiny_dataset)).split("<table", 1)[1])
    # the fakes: livescene keeps every change local, conerf leaks 3.2/255 onto the room
    verdicts = {(r[0], r[1]): (r[2], r[-1]) for r in rows}
    for obj in tiny_dataset.objects:
        assert verdicts[("livescene", obj)] == ("0.200", '<span class="ok">local</span>')
        assert verdicts[("conerf", obj)] == ("3.200", '<span class="fail">not local</span>')


def test_pose_errors_are_shown_in_percent_and_degrees(tmp_path, tiny_dataset):
    html = section_poses(_scene(tmp_path, tiny_dataset))
    against = html.split("<h3>Against the truth</h3>")[1]
    cells = dict(r for r in _rows(against))
    # the fake pose_error.json: centre error 0.007 / 0.015 of the extent, rotation 1.4 / 1.9 deg, fx 9 % off
    assert cells["camera-centre error / scene extent (mean, max)"] == "0.70 %, 1.50 %"
    assert cells["rotation error deg (mean, max)"] == "1.40, 1.90"
    assert cells["focal error (relative fx)"] == "9.00 %"


def test_pose_warnings_up_check_and_a_given_focal_are_shown(tmp_path, tiny_dataset):
    """The poses stage's warnings reached only its log (stderr) before; the up check and a given focal length are rows
    of the COLMAP table."""
    sd = _scene(tmp_path, tiny_dataset)
    sd.poses = {**sd.poses, "warnings": ["the world's up <z> lies 11.4 degrees from ..."],
                "up_check": {"plane_tilt_deg": 11.37, "plane_points": 41, "n_points": 420},
                "camera": {"model": "RADIAL", "focal_given": {"focal_px": 150.69, "given": "--focal 150.69",
                                                              "refined": False}}}
    html = section_poses(sd)
    cells = dict(r for r in _rows(html))
    assert cells["up check: largest horizontal plane's normal against z (deg)"] == "11.37 (41 of 420 points)"
    assert cells["focal length given"] == "150.7 px (--focal 150.69; kept fixed)"
    assert "1 warning(s) from the poses stage" in html
    assert "<li>the world&#x27;s up &lt;z&gt; lies 11.4 degrees from ...</li>" in html  # escaped
    sd.poses = {**sd.poses, "warnings": [], "up_check": {"plane_tilt_deg": None, "plane_points": 3, "n_points": 20}}
    html = section_poses(sd)
    assert dict(r for r in _rows(html))["up check: largest horizontal plane's normal against z (deg)"] == \
        "no horizontal plane found: not checked"
    assert "warning(s) from the poses stage" not in html


def test_states_table_marks_the_interpolation_used_and_gives_it_the_truth_errors(tmp_path, tiny_dataset):
    sd = _scene(tmp_path, tiny_dataset)
    sd.states_vs_truth = {"object0": {"mae": 0.05, "max": 0.08, "n": 3}}
    rows = _rows(section_states(sd))
    assert rows == [
        ["object0", "linear", "0.200", "0.400", "5", "–", "–"],
        ["object0", "pchip (used)", "0.100", "0.300", "5", "0.050", "0.080"],
    ]


def test_summary_numbers_skipped_rules_and_job_seconds(tmp_path, tiny_dataset):
    stability = tmp_path / "stability.tsv"
    stability.write_text("s\tmax_rss\tcpu_time\tmean_load\n99.0\t1\t1\t1\n")
    sd = _scene(tmp_path, tiny_dataset, stability_benchmark=str(stability))
    assert sd.benchmarks["stability"]["s"] == 99.0  # the shared suite's timing is listed with the scene's
    summary = scene_summary(sd, "scenes/fake.html")
    assert summary["methods"]["livescene"] | {"trust": None} == {
        "psnr": 20.0,
        "ssim": 0.7,
        "train_seconds": 150.0,
        "steps": 400,
        "trust": None,
    }
    assert summary["skipped"] == ["labels"]  # not train[mk-planes]: that method is not this scene's
    # capture, poses, both trainings and livescene's evaluation; the stability suite (99 s) is shared: not summed
    assert summary["job_seconds"] == round(3.1 + 12.5 + 150.2 + 151.0 + 40.0, 1)
    timings = section_timings(sd)
    longest_first = ["train_conerf", "train_livescene", "stability", "evaluate_livescene", "poses", "capture"]
    assert [r[0] for r in _rows(timings.split("</svg>")[1])] == longest_first
    assert re.findall(r'text-anchor="end" font-size="12">([^<]+)</text>', timings) == longest_first
    # a dataset folder without transforms.json gives no counts (the head shows dashes, not 0 frames)
    assert collect_scene("x", ReportInputs(dataset=tmp_path), methods=[], plan={}).dataset_info is None


def test_verdict_cells_are_coloured_by_direction_and_name_the_seed_trained(tmp_path, tiny_dataset):
    sd = _scene(
        tmp_path,
        tiny_dataset,
        edit=lambda res: _edit_json(res / "runs" / "livescene" / "run.json", lambda r: r.update(seed=7)),
    )
    html = section_verdict(sd)
    assert '<span class="fail">LiveScene behind</span>' in html and '<span class="ok">LiveScene ahead</span>' in html
    assert "livescene seed 7, conerf seed 0" in html  # run.json's seed before the config's
    assert _interval(None, "dB") == "– (n &lt; 2)" and _interval([0.5, 1.5], "dB") == "[0.500, 1.500] dB"


def test_unseen_note_gives_the_evaluations_own_distance(tmp_path, tiny_dataset):
    def edit(res: Path) -> None:
        for m in ("livescene", "conerf"):
            _edit_json(
                res / "eval" / m / "metrics.json", lambda d: d["unseen_combinations"].update(observed_within=0.2)
            )

    html = section_unseen(_scene(tmp_path, tiny_dataset, edit=edit))
    assert "no training frame holds the object within 0.200 of the level" in html


def test_sliders_start_at_the_first_state_and_warn_only_where_training_stops_short(tmp_path, tiny_dataset):
    sd = _scene(tmp_path, tiny_dataset)
    sd.dataset_info = {"state_ranges": {"object0": [0.0, 1.0], "object1": [0.2, 0.9], "object2": None}}
    html, images = section_sliders(sd)
    assert html.count('<p class="note">') == 1
    assert "The training frames hold object1 between 0.20 and 0.90: beyond that the renders extrapolate." in html
    assert html.count('">0.00</output>') == 3 and list(images) == ["sweep-0", "sweep-1", "sweep-2"]
    assert _beyond_note("a<b", [0.0, 1.0]) == "" and "a&lt;b between 0.30 and 1.00" in _beyond_note("a<b", [0.3, 1])


def test_commands_escape_the_error_and_stability_failures_are_red(tmp_path):
    m = MethodData("livescene", control={"commands": [{"command": "open <x>", "error": "no object named '<x>'"}]})
    sd = SceneData(scene="s", plan={"stability": {"needed": True}}, benchmarks={}, methods=[m])
    html = section_commands(sd)
    assert "<td>open &lt;x&gt;</td>" in html and "no object named &#x27;&lt;x&gt;&#x27;" in html
    assert "<x>" not in html
    sd.stability = {
        "counts": {"pass": 1, "fail": 1},
        "seconds": 3.0,
        "cases": [{"name": "a", "group": "g", "result": "fail"}, {"name": "b", "group": "g", "result": "pass"}],
    }
    html = section_stability(sd)
    assert '<span class="fail">fail</span>' in html and '<span class="ok">pass</span>' in html
    # the suite's summary is there though its benchmark is not: it ran
    assert _rows(section_rules(sd))[0][:2] == ["stability", '<span class="ok">ran</span>']


def test_the_heading_escapes_the_scene_name_and_counts_the_splits(tmp_path):
    html = build_scene_page(SceneData(scene="<kitchen>", plan={}, benchmarks={}))
    assert "<h1>Scene &lt;kitchen&gt;</h1>" in html and "<kitchen>" not in html
    data = make_tiny_dataset(tmp_path / "five", n_frames=5).root  # frames 0, 2, 4 test; 1, 3 train
    (data / "mapping.yaml").write_text("3: object2\n1: object0\n2: object1\n")  # objects in the order of their ids
    sd = collect_scene("five", ReportInputs(dataset=data), methods=[], plan={})
    assert "5 frames (2 train, 3 test), 16x12, objects object0, object1, object2" in build_scene_page(sd)


# -- the export and object-mask sections ----------------------------------------------------------------------------


def test_export_rows_keep_the_timings_in_their_columns_and_escape_states(tmp_path):
    (tmp_path / "export.json").write_text(
        json.dumps(
            {
                "objects": ["<door>"],
                "options": {"objects": True},
                "exports": [
                    {
                        "states": {"<door>": 0.5},
                        "files": {
                            "scene_mesh": {"vertices": 10, "triangles": 20, "bytes": 3 * 2**20},
                            "objects/<door>_mesh": {"vertices": 3, "triangles": 1, "bytes": 100},
                        },
                        "timings_s": {"render": 1.0, "fuse": 2.0, "extract": 3.0, "write": 4.0, "total": 10.0},
                    }
                ],
            }
        )
    )
    html = section_export({"livescene": tmp_path})
    head = _headers(html)
    row = dict(zip(head, _rows(html)[0], strict=True))
    assert row["states"] == "&lt;door&gt;=0.5" and "<door>" not in html
    assert (row["render s"], row["fuse s"], row["extract s"], row["write s"], row["total s"]) == (
        "1.000",
        "2.000",
        "3.000",
        "4.000",
        "10.000",
    )
    assert row["scene mesh"] == "10 v / 20 t" and "3.00 MiB" in html
    assert row["&lt;door&gt; part"] == "3 v / 1 t"  # the object's own part, in its column


def test_labels_section_numbers_each_object_and_frame(tmp_path):
    (tmp_path / "labels.json").write_text(
        json.dumps(
            {
                "objects": ["door", "fridge"],
                "n_frames": 10,
                "n_labelled": 3,
                "format": "png",
                "unreliable_frames": {"00001": ["door"], "00003": ["fridge"]},
                "frames_without_masks": [],
            }
        )
    )
    frames = [
        {
            "frame": "00002",
            "previous_key": "00000",
            "next_key": "00004",
            "distance": 2,
            "iou": {"door": 0.9, "fridge": 0.5},
            "mean_iou": 0.7,
        },
        {
            "frame": "00006",
            "previous_key": "00004",
            "next_key": "00008",
            "distance": 2,
            "iou": {"door": 0.8, "fridge": 0.4},
            "mean_iou": 0.6,
        },
        {
            "frame": "00007",
            "previous_key": "00004",
            "next_key": "00008",
            "distance": 3,
            "iou": {"door": 1.0, "fridge": 0.8},
            "mean_iou": 0.9,
        },
    ]
    (tmp_path / "propagation.json").write_text(
        json.dumps(
            {
                "propagated_frames": 7,
                "annotated_frames": ["00000", "00004", "00008"],
                "method": "optical flow",
                "mean_confidence": 0.8,
                "timings": {"total_s": 1.0, "per_frame_ms": 140},
                "confidence_by_distance": {"1": 0.9, "2": 0.8, "10": 0.5},
                "leave_one_out": {
                    "rule": "each annotated frame held out",
                    "frames": frames,
                    "mean_iou": {"door": 0.9, "fridge": 0.5667},
                    "mean_iou_all": 0.7333,
                },
            }
        )
    )
    (tmp_path / "confidence.csv").write_text(
        "frame,mean_confidence,confidence_door,confidence_fridge\n00000,1.0,1.0,1.0\n00001,0.9,0.8,0.95\n"
    )
    labels = json.loads((tmp_path / "labels.json").read_text())
    html = section_labels(
        SceneData(scene="s", plan={}, benchmarks={}, inputs=ReportInputs(labels=tmp_path), labels=labels)
    )
    assert "3 of 10 frames annotated" in html and "; 2 frames with an object under H*W/300 pixels" in html
    loo = html.split("<h3>Leave-one-out IoU</h3>")[1].split("<h3>")[0]
    assert _headers(loo)[4:] == ["IoU door", "IoU fridge", "mean IoU"]
    assert _rows(loo)[0][4:] == ["0.900", "0.500", "0.700"]
    assert "Weakest held-out frame: 00006 (mean IoU 0.600)" in loo
    confidence = html.split("<h3>Confidence</h3>")[1]
    assert [r[0] for r in _rows(confidence)] == ["1", "2", "10"]  # by distance, not as text
