"""The scene page in a real browser: no console errors, every image loads, the sliders scrub; the page reads
only the inputs its manifest names, wherever they lie."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
from report_browser import ARTIFACTS, fake_inputs, make_fake_results, write_inputs

from stages.report.cli import main as report_main

PLAN = {"capture": {"needed": True, "why": "synthetic spec"}, "frames": {"needed": True, "why": "video"},
        "poses": {"needed": True, "why": "COLMAP"}, "states": {"needed": True, "why": "key frames given"},
        "labels": {"needed": False, "why": "scene has no masks"},
        "train[livescene]": {"needed": True, "why": "listed"}, "train[conerf]": {"needed": True, "why": "listed"},
        "sweep[livescene]": {"needed": True, "why": "sliders"}, "control[livescene]": {"needed": True, "why": "x"},
        "stability": {"needed": False, "why": "stability.run is false"}}


def render(tmp_path: Path, manifest: dict, plan: dict = PLAN, methods: str = "livescene,conerf") -> Path:
    """The page of ``manifest`` at tmp_path/reports/scenes/fake.html (summary at tmp_path/summary.json)."""
    page = tmp_path / "reports" / "scenes" / "fake.html"
    code = report_main(["scene", "--scene", "fake", "--inputs", str(write_inputs(tmp_path / "inputs.json", manifest)),
                        "--methods", methods, "--plan-json", json.dumps(plan), "--out", str(page),
                        "--index", str(tmp_path / "reports" / "index.html"),
                        "--summary", str(tmp_path / "summary.json")])
    assert code == 0
    return page


def build_page(tmp_path: Path, data: Path, plan: dict = PLAN) -> Path:
    return render(tmp_path, fake_inputs(make_fake_results(tmp_path, data), data), plan)


def test_page_in_chromium(tmp_path, tiny_dataset, chromium):
    page = build_page(tmp_path, tiny_dataset.root)
    chromium.load(page.as_uri())
    images = chromium.evaluate("Array.from(document.images).map(i => [i.alt, i.complete && i.naturalWidth > 0])")
    # truth + 2 x (render + error) per test view, relevancy maps, 3 sliders, 1 command render
    assert len(images) >= 3 * 5 + 3
    assert [alt for alt, ok in images if not ok] == []
    slider = """(async () => {
      const el = document.querySelector('input.sweep');
      const img = document.getElementById(el.dataset.target);
      const before = [img.src, document.getElementById(el.dataset.target + '-value').textContent];
      el.value = el.max; el.dispatchEvent(new Event('input'));
      await img.decode();
      const after = [img.src, document.getElementById(el.dataset.target + '-value').textContent];
      return {before, after, loaded: img.complete && img.naturalWidth > 0,
              count: document.querySelectorAll('input.sweep').length};
    })()"""
    moved = chromium.evaluate(slider, await_promise=True)
    assert moved["count"] == 3
    assert moved["before"][0] != moved["after"][0], "moving the slider did not change the image"
    assert (moved["before"][1], moved["after"][1]) == ("0.00", "1.00")
    assert moved["loaded"]
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    chromium.screenshot(ARTIFACTS / "scene_page.png")
    assert (ARTIFACTS / "scene_page.png").stat().st_size > 10_000
    assert chromium.errors() == []


def test_page_is_self_contained_and_says_why(tmp_path, tiny_dataset):
    html = build_page(tmp_path, tiny_dataset.root).read_text()
    for section in ("rules", "timings", "poses", "states", "methods", "curves", "grid", "sliders", "relevancy",
                    "unseen", "locality", "commands", "stability"):
        assert f'<section id="{section}">' in html
    locality = html.split('<section id="locality">')[1].split("</section>")[0]
    assert locality.count(">local<") == 3 and locality.count(">not local<") == 3  # 3 objects x 2 methods
    assert "poses:" not in locality  # all the poses asked for: no note
    # the tiny dataset's training frames hold object0 at 0.01-0.48, object1 and object2 short of 1 as well
    assert "The training frames do not take every object from closed to open: object0 (0.01 to 0.48)" in locality
    unseen = html.split('<section id="unseen">')[1].split("</section>")[0]
    assert unseen.count("2 of 3 poses: at 3, this room's objects would take more than the evaluation's budget of "
                        "4 renders") == 1  # one sentence for both methods
    assert "nothing to test here" not in unseen
    assert unseen.count("no training frame holds the object within 0.125 of the level") == 1  # once for both methods
    assert "object2 at 1.00 (training: 0.00 to 0.60)" in unseen
    # the tiny dataset's training frames hold object0 between 0.01 and 0.48: its slider says the rest extrapolates
    sliders = html.split('<section id="sliders">')[1].split("</section>")[0]
    ranges = tiny_dataset.state_ranges(tiny_dataset.frames_in("train"))
    assert ranges["object0"][1] < 0.5
    assert (f"The training frames hold object0 between {ranges['object0'][0]:.2f} and {ranges['object0'][1]:.2f}: "
            "beyond that the renders extrapolate.") in sliders
    commands = html.split('<section id="commands">')[1].split("</section>")[0]
    assert ("object0 at 1.00 is beyond the states its training frames show (0.01 to 0.48): the render "
            "extrapolates") in commands
    assert "http://" not in html.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "https://" not in html
    assert "<svg" in html and "eval PSNR (dB)" in html  # the error-vs-run-time plot is inline SVG
    curves = html.split('<section id="curves">')[1].split("</section>")[0]
    # wall times name their machine (run.json): the same steps take 2-3x longer on a slower CPU
    assert "Training ran on Test CPU @ 2.50GHz, 2 logical cores, torch 2.13.0 (AVX2)." in curves
    methods = html.split('<section id="methods">')[1].split("</section>")[0]
    assert methods.count("not available: torchvision is not installed") == 1  # LPIPS says why, once for all
    assert "stability.run is false" in html  # absent stability summary: the page says why
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["methods"]["conerf"]["psnr"] == 21.0


def test_a_room_with_no_unseen_combination_says_why(tmp_path, tiny_dataset):
    """One object: every state it takes is a training state, so no candidate vector is unseen; the section says so
    instead of showing an empty table."""
    results = make_fake_results(tmp_path, tiny_dataset.root)
    for metrics in results.glob("**/metrics.json"):
        m = json.loads(metrics.read_text())
        u = m["unseen_combinations"]
        u["combinations"] = [{"unseen": False}] * 3
        u["records"], u["psnr"], u["psnr_moved"], u["ssim"] = [], {"mean": None}, {"mean": None}, {"mean": None}
        metrics.write_text(json.dumps(m))
    html = render(tmp_path, fake_inputs(results, tiny_dataset.root)).read_text()
    unseen = html.split('<section id="unseen">')[1].split("</section>")[0]
    assert "No candidate state vector is unseen" in unseen and "nothing to test here" in unseen


def test_an_evaluation_at_a_fraction_of_the_size_says_so(tmp_path, tiny_dataset):
    """evaluate --max-side scored the views at half size: the methods section says it once for all methods."""
    html = build_page(tmp_path / "full", tiny_dataset.root).read_text()
    assert "of the dataset's image size" not in html.split('<section id="methods">')[1].split("</section>")[0]
    results = make_fake_results(tmp_path, tiny_dataset.root)
    for metrics in results.glob("**/metrics.json"):
        m = json.loads(metrics.read_text())
        m.setdefault("config", {})["render_scale"] = 0.5
        metrics.write_text(json.dumps(m))
    html = render(tmp_path, fake_inputs(results, tiny_dataset.root)).read_text()
    methods = html.split('<section id="methods">')[1].split("</section>")[0]
    assert methods.count("rendered and scored at 1/2 of the dataset's image size") == 1


def test_page_without_evaluations(tmp_path, tiny_dataset):
    """A scene whose trainings have not run still gets a page that says so, section by section."""
    data = tiny_dataset.root
    page = tmp_path / "empty.html"
    plan = {"train[livescene]": {"needed": False, "why": "method not listed for this scene"},
            "sweep[livescene]": {"needed": False, "why": "not in report.sweep_methods"}}
    inputs = write_inputs(tmp_path / "inputs.json", {"dataset": str(data)})
    assert report_main(["scene", "--scene", "empty", "--inputs", str(inputs), "--methods", "livescene",
                        "--plan-json", json.dumps(plan), "--out", str(page)]) == 0
    html = page.read_text()
    assert "not in report.sweep_methods" in html
    assert "No periodic evaluation" in html
    assert "No benchmark files" in html


def test_bad_plan_json_is_an_input_error(tmp_path, capsys):
    code = report_main(["scene", "--scene", "x", "--inputs", str(write_inputs(tmp_path / "in.json", {})),
                        "--plan-json", "{nope", "--out", str(tmp_path / "x.html")])
    assert code == 2
    assert "--plan-json" in capsys.readouterr().err


# -- the page reads only its inputs -----------------------------------------------------------------------------

# Where the fake outputs are moved to: no folder name the workflow uses, runs named by their folder this time.
SCATTERED = {"poses": "a/cameras", "pose_error": "a/b/cam-vs-truth.json", "states": "s/t", "benchmarks": "timing",
             "runs": {"livescene": "a/b/train-ls", "conerf": "c/conerf-run"},
             "eval": {"livescene": "a/b/eval-x", "conerf": "eval-y"},
             "sweep": {"livescene": "sl/ider"}, "control": {"livescene": "cmds"}}


def test_page_from_an_arbitrary_layout_matches(tmp_path, tiny_dataset):
    """Outputs put anywhere, named by the manifest, give the very same page as the fake tree."""
    data = tiny_dataset.root
    reference = build_page(tmp_path / "ref", data).read_text()
    source = fake_inputs(make_fake_results(tmp_path / "src", data), data)
    manifest: dict = {"dataset": str(data)}
    for role, target in SCATTERED.items():
        if isinstance(target, dict):
            manifest[role] = {}
            for method, folder in target.items():
                origin = Path(source[role][method])
                origin = origin.parent if origin.suffix == ".json" else origin  # a run folder, not its run.json
                manifest[role][method] = str(_move(origin, tmp_path / "x" / folder))
        else:
            manifest[role] = str(_move(Path(source[role]), tmp_path / "x" / target))
    shutil.rmtree(tmp_path / "src")  # nothing is left where the outputs were written
    html = render(tmp_path / "out", manifest).read_text()
    assert html == reference
    for section in ("timings", "poses", "methods", "verdict", "curves", "grid", "sliders", "relevancy", "unseen",
                    "locality", "commands"):
        body = html.split(f'<section id="{section}">')[1].split("</section>")[0]
        assert 'class="missing"' not in body, section
    assert html.count('class="sweep"') == 3 and "open the object0" in html


def _move(origin: Path, target: Path) -> Path:
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(origin, target)
    return target


def test_absent_roles_say_why(tmp_path, tiny_dataset):
    """A manifest without poses, states or the sweep (stages the plan left out): those sections say why."""
    data = tiny_dataset.root
    manifest = fake_inputs(make_fake_results(tmp_path, data), data)
    for role in ("poses", "pose_error", "states", "sweep"):
        del manifest[role]
    plan = PLAN | {"poses": {"needed": False, "why": "poses come with the data"},
                   "states": {"needed": False, "why": "poses come with the data"},
                   "sweep[livescene]": {"needed": False, "why": "not in report.sweep_methods"}}
    html = render(tmp_path, manifest, plan).read_text()
    for section in ("poses", "states", "sliders"):
        body = html.split(f'<section id="{section}">')[1].split("</section>")[0]
        assert 'class="missing"' in body and "skipped for this scene" in body, section
    methods = html.split('<section id="methods">')[1].split("</section>")[0]
    assert "21.000" in methods  # the roles that are given still fill their sections


def test_methods_default_to_the_manifest_and_links_follow_the_index(tmp_path, tiny_dataset):
    data = tiny_dataset.root
    manifest = write_inputs(tmp_path / "in.json", fake_inputs(make_fake_results(tmp_path, data), data))
    page, summary = tmp_path / "site" / "pages" / "deep" / "fake.html", tmp_path / "s.json"
    assert report_main(["scene", "--scene", "fake", "--inputs", str(manifest), "--out", str(page),
                        "--index", str(tmp_path / "site" / "all.html"), "--summary", str(summary)]) == 0
    html = page.read_text()
    assert '<a href="../../all.html">all scenes</a>' in html
    assert json.loads(summary.read_text())["page"] == "pages/deep/fake.html"
    assert list(json.loads(summary.read_text())["methods"]) == ["livescene", "conerf"]  # the manifest's order
    # without --index: no link back, and the summary links the page by its file URI
    assert report_main(["scene", "--scene", "fake", "--inputs", str(manifest), "--out", str(page),
                        "--summary", str(summary)]) == 0
    assert "all scenes" not in page.read_text()
    assert json.loads(summary.read_text())["page"] == page.resolve().as_uri()


def test_a_yaml_manifest_gives_the_same_page(tmp_path, tiny_dataset):
    import yaml

    data = tiny_dataset.root
    reference = build_page(tmp_path / "ref", data).read_text()
    manifest = json.loads((tmp_path / "ref" / "inputs.json").read_text())
    (tmp_path / "inputs.yaml").write_text(yaml.safe_dump(manifest))
    page = tmp_path / "reports" / "scenes" / "fake.html"
    assert report_main(["scene", "--scene", "fake", "--inputs", str(tmp_path / "inputs.yaml"), "--methods",
                        "livescene,conerf", "--plan-json", json.dumps(PLAN), "--out", str(page),
                        "--index", str(tmp_path / "reports" / "index.html")]) == 0
    assert page.read_text() == reference


@pytest.mark.parametrize(("manifest", "message"), [
    ('{"results": "results/fake"}', "unknown role(s) ['results']"),
    ('{"poses": 3}', "role 'poses' is 3, not a path"),
    ('{"eval": "eval/livescene"}', "role 'eval' is 'eval/livescene', not a mapping of method -> path"),
    ('["poses"]', "is list, not a mapping of role -> path"),
    ("{poses", "is not JSON"),
])
def test_bad_manifest_is_an_input_error(tmp_path, capsys, manifest, message):
    (tmp_path / "inputs.json").write_text(manifest)
    code = report_main(["scene", "--scene", "x", "--inputs", str(tmp_path / "inputs.json"),
                        "--out", str(tmp_path / "x.html")])
    assert code == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "inputs.json") in err and message in err
    assert not (tmp_path / "x.html").exists()


def test_report_code_names_no_workflow_folder():
    """The stage knows no layout: where its inputs lie comes from the manifest only."""
    folders = "runs|eval|sweep|control|benchmarks|logs|capture|frames|poses|labels|states|language|stability|report"
    joined = re.compile(rf'/ "({folders}|scenes|dataset|truth_dataset)"')  # e.g. root / "runs"
    root = Path(__file__).resolve().parents[2] / "stages" / "report"
    for path in sorted(root.glob("*.py")):
        text = path.read_text()
        assert not joined.search(text), (path.name, joined.search(text))
        for layout in ("results/", "reports/", "scenes/", "pose_error.json", "index.html"):
            assert layout not in text, (path.name, layout)


def test_runs_on_different_machines_are_named_each():
    from types import SimpleNamespace

    from stages.report.scene_page import _machines_note

    def method(name, cpu):
        return SimpleNamespace(name=name, run={"machine": {"cpu": cpu, "logical_cores": 2}} if cpu else {})

    sd = SimpleNamespace(methods=[method("livescene", "CPU A"), method("mk-planes", "CPU B"),
                                  method("conerf", "CPU A"), method("k-planes", None)])
    assert _machines_note(sd) == (" livescene, conerf trained on CPU A, 2 logical cores. mk-planes trained on CPU B, "
                                  "2 logical cores.")
    assert _machines_note(SimpleNamespace(methods=[method("livescene", None)])) == ""  # an older run.json: nothing


def test_a_gpu_run_shows_the_memory_its_allocator_reserved(tmp_path, tiny_dataset):
    """A run replayed as CUDA graphs allocates little after capture; its pool shows in the reserved peak."""
    results = make_fake_results(tmp_path, tiny_dataset.root)
    for run_json in results.glob("runs/*/run.json"):
        run = json.loads(run_json.read_text())
        run.update(peak_memory_mib=713.0, peak_reserved_mib=4052.0, cuda_graphs=True)
        run_json.write_text(json.dumps(run))
    html = render(tmp_path, fake_inputs(results, tiny_dataset.root)).read_text()
    methods = html.split('<section id="methods">')[1].split("</section>")[0]
    assert "4052" in methods and "713" not in methods


def test_relevancy_maps_of_names_in_any_script_and_the_view_they_show(tmp_path, tiny_dataset):
    objects = ("Küchenschublade", "冷蔵庫", "object2")
    res = make_fake_results(tmp_path, tiny_dataset.root, objects=objects)
    html = render(tmp_path, fake_inputs(res, tiny_dataset.root)).read_text()
    relevancy = html.split('<section id="relevancy">')[1].split("</section>")[0]
    for name in objects:  # each map found by the name the evaluation gave its file
        assert f'"{name}" (probs)<br>view ' in relevancy
    metrics = json.loads((res / "eval" / "livescene" / "metrics.json").read_text())
    q = metrics["grounding"]["queries"][0]["probs"]
    # the caption gives the shown view's IoU, and the mean over the views apart
    assert (f"view {q['frames'][0]}: IoU {q['per_view'][0]:.2f} (mean over {len(q['per_view'])} views "
            f"{q['iou']['mean']:.2f})") in relevancy


def test_timings_list_the_jobs_of_the_plan_only(tmp_path, tiny_dataset):
    res = make_fake_results(tmp_path, tiny_dataset.root)
    for stale in ("train_mk-planes", "report"):  # a method dropped from the row; the page's own earlier build
        shutil.copy(res / "benchmarks" / "capture.tsv", res / "benchmarks" / f"{stale}.tsv")
    html = render(tmp_path, fake_inputs(res, tiny_dataset.root)).read_text()
    timings = html.split('<section id="timings">')[1].split("</section>")[0]
    assert "train_livescene" in timings and "train_mk-planes" not in timings and ">report<" not in timings
    planned = 3.1 + 12.5 + 150.2 + 151.0  # evaluate_livescene is not in this page's plan either
    assert f"<b>{planned:.1f} s</b>" in timings
    assert json.loads((tmp_path / "summary.json").read_text())["job_seconds"] == round(planned, 1)


def test_runs_scored_at_aligned_poses_are_named_in_the_methods_note():
    from types import SimpleNamespace

    from stages.report.scene_page import _view_alignment_note

    refined = SimpleNamespace(name="livescene", metrics={"view_alignment": {
        "training_cameras": "SO3xR3", "steps": 100, "rotation_deg": {"mean": 0.25}}})
    plain = SimpleNamespace(name="mk-planes", metrics={"held_out": {}})
    assert _view_alignment_note(SimpleNamespace(methods=[refined, plain])) == (
        " Refined training cameras: livescene (SO3xR3: each held-out pose aligned by 100 steps against its image, "
        "model frozen, mean correction 0.25 degrees); their held-out, unseen-combination and grounding numbers are at "
        "those aligned poses, the others' at the dataset's.")
    assert _view_alignment_note(SimpleNamespace(methods=[plain])) == ""
