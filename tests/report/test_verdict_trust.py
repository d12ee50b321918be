"""The report's verdict (paired differences with a 95% CI), the trust flags and the error-against-steps plot."""

from __future__ import annotations

import json
import math
from dataclasses import asdict

import pytest
from report_browser import make_fake_results
from test_report_page import build_page

from stages.model.config import TrustConfig
from stages.report.index_page import build_index, load_summaries
from stages.report.paired import compare, grounding_items, held_out_items, paired_difference, unseen_items, verdict
from stages.report.scene_data import train_curve_by_step
from stages.report.trust import assess_run, trust_floors
from stages.scene import InputError

T_975 = {2: 4.3026527, 3: 3.1824463, 4: 2.7764451}  # Student t quantiles from tables, by degrees of freedom


def _metrics(views: dict[str, float] | None = None, records: list[dict] | None = None,
             ious: dict[str, tuple[list[float], list[str]]] | None = None, miou: float = 0.9,
             object_accumulation: float | None = 0.95) -> dict:
    # held-out mean: the trust tests pass one view, whose PSNR is then the mean
    return {"held_out": {"views": [{"frame": f, "psnr": p} for f, p in (views or {}).items()],
                         "psnr": {"mean": min((p for p in (views or {}).values() if p is not None), default=None)},
                         "accumulation_objects": {"mean": object_accumulation}},
            "unseen_combinations": {"status": "computed", "records": records or []},
            "grounding": {"status": "computed", "miou_probs_name": miou,
                          "queries": [{"query": q, "probs": {"per_view": v, "frames": f}}
                                      for q, (v, f) in (ious or {}).items()]}}


# -- paired differences -----------------------------------------------------------------------------------------


def test_paired_difference_uses_only_shared_items_and_student_t():
    ours = {("a",): 21.0, ("b",): 23.0, ("c",): 22.0, ("d",): 30.0, ("only-ours",): 99.0}
    theirs = {("a",): 20.0, ("b",): 21.0, ("c",): 19.0, ("d",): 28.0, ("only-theirs",): 0.0}
    n, mean, ci = paired_difference(ours, theirs)
    diffs = [1.0, 2.0, 3.0, 2.0]
    sd = math.sqrt(sum((d - 2.0) ** 2 for d in diffs) / 3)
    half = T_975[3] * sd / math.sqrt(4)
    assert n == 4 and mean == pytest.approx(2.0)
    assert ci == [pytest.approx(2.0 - half, abs=1e-6), pytest.approx(2.0 + half, abs=1e-6)]
    assert verdict(n, ci) == "LiveScene ahead"  # [0.70, 3.30] excludes 0


def test_verdict_needs_the_interval_to_exclude_zero():
    assert verdict(4, [0.1, 2.0]) == "LiveScene ahead"
    assert verdict(4, [-3.0, -0.01]) == "LiveScene behind"
    assert verdict(4, [-0.5, 2.0]) == "no measurable difference (n=4)"
    # a closed interval that reaches 0 does not exclude it, from either side
    assert verdict(4, [0.0, 2.0]) == "no measurable difference (n=4)"
    assert verdict(4, [-2.0, 0.0]) == "no measurable difference (n=4)"
    assert verdict(1, None) == "no measurable difference (n=1)"  # one item: no interval, no verdict
    assert verdict(0, None) == "no paired items"
    # a large mean difference on few, noisy items is still no verdict
    n, mean, ci = paired_difference({(i,): v for i, v in enumerate([5.0, -1.0, 6.0])},
                                    {(i,): 0.0 for i in range(3)})
    assert mean == pytest.approx(10 / 3) and ci[0] < 0 < ci[1]
    assert verdict(n, ci) == "no measurable difference (n=3)"


def test_items_are_matched_by_frame_state_vector_and_query():
    a = _metrics(views={"0": 20.0, "2": 22.0, "4": None},
                 records=[{"frame": "0", "states": {"x": 0.0, "y": 1.0}, "unseen": True, "psnr": 18.0},
                          {"frame": "0", "states": {"y": 0.0, "x": 1.0}, "unseen": True, "psnr": 17.0},
                          {"frame": "0", "states": {"x": 0.5, "y": 0.5}, "unseen": False, "psnr": None}],
                 ious={"door": ([0.5, 0.7], ["0", "2"])})
    b = _metrics(views={"2": 21.0, "0": 19.5, "6": 30.0},
                 records=[{"frame": "0", "states": {"x": 1.0, "y": 0.0}, "unseen": True, "psnr": 16.0},
                          {"frame": "0", "states": {"y": 1.0, "x": 0.0}, "unseen": True, "psnr": 17.5}],
                 ious={"door": ([0.6], ["2"])})
    assert paired_difference(held_out_items(a), held_out_items(b))[:2] == (2, pytest.approx((0.5 + 1.0) / 2))
    # the same state vector whatever the key order; the non-novel record is not an item
    n, mean, _ = paired_difference(unseen_items(a), unseen_items(b))
    assert (n, mean) == (2, pytest.approx((0.5 + 1.0) / 2))
    assert paired_difference(grounding_items(a), grounding_items(b))[:2] == (1, pytest.approx(0.1))


def test_a_non_novel_record_is_not_an_unseen_item_even_with_a_psnr():
    """Evaluations before version 2 rendered non-novel combinations too: their PSNR is no unseen item."""
    m = _metrics(records=[{"frame": "0", "states": {"x": 0.0}, "unseen": True, "psnr": 18.0},
                          {"frame": "0", "states": {"x": 0.5}, "unseen": False, "psnr": 30.0},
                          {"frame": "2", "states": {"x": 1.0}, "psnr": 31.0}])  # no flag: not shown to be novel
    assert unseen_items(m) == {("0", (("x", 0.0),)): 18.0}


def test_an_undefined_value_is_no_item():
    """NaN / inf (a json NaN, an exact reproduction's PSNR) is left out, never averaged or paired."""
    m = _metrics(views={"0": 20.0, "2": float("inf"), "4": float("nan")},
                 records=[{"frame": "0", "states": {"x": 0.0}, "unseen": True, "psnr": float("inf")}],
                 ious={"door": ([0.5, float("nan")], ["0", "2"]), "the door": ([0.7, 0.9], ["0", "2"])})
    for q in m["grounding"]["queries"]:
        q["object"] = "door"
    assert held_out_items(m) == {("0",): 20.0}
    assert unseen_items(m) == {}
    # view 0: (0.5 + 0.7) / 2; view 2: the NaN query is left out, the other one's 0.9 stays
    assert grounding_items(m) == pytest.approx({("door", "0"): 0.6, ("door", "2"): 0.9})


def test_a_name_and_its_synonym_are_one_grounding_item_per_view():
    """Both queries of one object are scored on the same mask: one (object, view) item, their mean IoU."""
    def queries(ious: dict[tuple[str, str], list[float]]) -> dict:
        return {"grounding": {"status": "computed", "queries": [
            {"query": q, "object": o, "probs": {"per_view": v, "frames": ["0", "2"]}} for (q, o), v in ious.items()]}}

    ours = queries({("fridge", "fridge"): [0.9, 0.8], ("refrigerator", "fridge"): [0.7, 0.8],
                    ("drawer", "drawer"): [0.6, 0.5]})
    theirs = queries({("fridge", "fridge"): [0.8, 0.8], ("refrigerator", "fridge"): [0.8, 0.8],
                      ("drawer", "drawer"): [0.5, 0.5]})
    assert grounding_items(ours) == pytest.approx({("fridge", "0"): 0.8, ("fridge", "2"): 0.8,
                                                   ("drawer", "0"): 0.6, ("drawer", "2"): 0.5})
    n, mean, _ = paired_difference(grounding_items(ours), grounding_items(theirs))
    assert (n, mean) == (4, pytest.approx(0.1 / 4))
    # an evaluation that names no object keys by query, as before
    old = queries({("door", ""): [0.5, 0.7]})
    assert set(grounding_items(old)) == {("door", "0"), ("door", "2")}


def test_held_out_difference_is_split_into_object_and_static_pixels():
    def views(rows: dict[str, tuple[float, float]]) -> dict:
        return {"held_out": {"views": [{"frame": f, "psnr": 0.5 * (o + s), "psnr_objects": o, "psnr_static": s}
                                       for f, (o, s) in rows.items()]}}

    ours = views({"0": (24.0, 27.0), "2": (25.0, 26.0), "4": (23.0, 28.8)})
    theirs = views({"0": (22.0, 27.5), "2": (23.5, 26.6), "4": (21.0, 29.5)})
    rows = {r.metric: r for r in compare({"livescene": ours, "mk-planes": theirs}, {})}
    assert rows["held_out_psnr_objects"].n == 3 and rows["held_out_psnr_objects"].mean == pytest.approx(5.5 / 3)
    assert rows["held_out_psnr_objects"].verdict == "LiveScene ahead"
    assert rows["held_out_psnr_static"].mean == pytest.approx(-0.6)
    assert rows["held_out_psnr_static"].verdict == "LiveScene behind"
    # an evaluation older than the split has no such items: no verdict, and the whole-image one stays
    old = {"held_out": {"views": [{"frame": f, "psnr": v["psnr"]} for f, v in
                                  zip("024", theirs["held_out"]["views"], strict=True)]}}
    rows = {r.metric: r for r in compare({"livescene": ours, "mk-planes": old}, {})}
    assert rows["held_out_psnr_static"].verdict == "no paired items" and rows["held_out_psnr"].n == 3


def test_older_grounding_without_frames_pairs_only_on_the_same_views():
    a = _metrics(views={"0": 20.0, "2": 20.0}, ious={"door": ([0.5, 0.9], None)})
    b = _metrics(views={"0": 20.0, "2": 20.0}, ious={"door": ([0.4, 0.8], None)})
    c = _metrics(views={"0": 20.0, "4": 20.0}, ious={"door": ([0.4, 0.8], None)})
    same = {r.baseline: r for r in compare({"livescene": a, "b": b, "c": c}, {}) if r.metric == "grounding_iou"}
    assert same["b"].n == 2 and same["b"].mean == pytest.approx(0.1)
    assert same["c"].n == 0 and same["c"].verdict == "no paired items" and "other views" in same["c"].note


def test_compare_says_when_a_verdict_rests_on_a_flagged_run():
    a = _metrics(views={"0": 20.0, "2": 21.0})
    b = _metrics(views={"0": 19.0, "2": 20.0})
    results = compare({"livescene": a, "mk-planes": b, "conerf": None}, {"mk-planes": "undertrained"})
    assert {r.baseline for r in results} == {"mk-planes"}  # no metrics, no comparison
    held = next(r for r in results if r.metric == "held_out_psnr")
    assert held.verdict == "LiveScene ahead" and held.flagged == {"mk-planes": "undertrained"}
    assert held.to_dict()["statement"] == "LiveScene ahead, but it rests on a flagged run: mk-planes (undertrained)"
    clean = compare({"livescene": a, "mk-planes": b}, {})[0]
    assert clean.to_dict()["statement"] == "LiveScene ahead" and clean.to_dict()["rests_on_flagged_run"] == []
    assert compare({"mk-planes": b}, {}) == []  # without LiveScene there is nothing to compare


def test_a_verdict_on_a_flagged_livescene_run_says_so():
    """A verdict rests on both runs: LiveScene's own flag is named as much as the baseline's."""
    a = _metrics(views={"0": 20.0, "2": 21.0})
    b = _metrics(views={"0": 19.0, "2": 20.0})
    results = compare({"livescene": a, "mk-planes": b}, {"livescene": "undertrained"})
    held = next(r for r in results if r.metric == "held_out_psnr")
    assert held.flagged == {"livescene": "undertrained"}
    assert held.statement == "LiveScene ahead, but it rests on a flagged run: livescene (undertrained)"
    assert held.to_dict()["rests_on_flagged_run"] == ["livescene"]
    both = compare({"livescene": a, "mk-planes": b}, {"livescene": "undertrained", "mk-planes": "not trustworthy"})
    assert both[0].flagged == {"livescene": "undertrained", "mk-planes": "not trustworthy"}


# -- trust flags --------------------------------------------------------------------------------------------------


def _run(steps: int = 50_000, status: str = "completed") -> dict:
    return {"steps": steps, "status": status}


FLOORS = {"min_steps": 1000, "min_psnr": 20.0, "min_grounding_miou": 0.5, "min_object_accumulation": 0.5}


@pytest.mark.parametrize(("run", "metrics", "reason", "kind"), [
    (_run(steps=999), _metrics({"0": 25.0}), "999 steps < trust.min_steps 1,000", "undertrained"),
    (_run(), _metrics({"0": 19.5}), "held-out PSNR 19.50 dB < trust.min_psnr 20 dB", "not trustworthy"),
    (_run(), _metrics({"0": 25.0}, miou=0.4), "grounding mIoU (probs, names) 0.400 < trust.min_grounding_miou 0.5",
     "not trustworthy"),
    (_run(), _metrics({"0": 25.0}, object_accumulation=0.44), "objects mostly transparent: held-out accumulation "
     "over object pixels 0.44 < trust.min_object_accumulation 0.5 (their colour comes from behind them)",
     "not trustworthy"),
    (_run(status="time_budget"), _metrics({"0": 25.0}), "training status 'time_budget', not 'completed'",
     "not trustworthy"),
    (None, _metrics({"0": 25.0}), "no run.json: training did not finish", "not trustworthy"),
])
def test_each_trust_floor_flags_the_run(run, metrics, reason, kind):
    flag = assess_run("m", run, {"trust": FLOORS}, metrics)
    assert flag.flagged and flag.reasons == [reason] and flag.label == kind


def test_each_floor_is_compared_with_its_own_value():
    """With distinct floors, the accumulation is held to min_object_accumulation, not to the mIoU floor."""
    floors = FLOORS | {"min_grounding_miou": 0.3, "min_object_accumulation": 0.6}
    flag = assess_run("m", _run(), {"trust": floors}, _metrics({"0": 25.0}, miou=0.9, object_accumulation=0.55))
    assert flag.reasons == ["objects mostly transparent: held-out accumulation over object pixels 0.55 < "
                            "trust.min_object_accumulation 0.6 (their colour comes from behind them)"]
    # and the mIoU to its own floor: 0.4 passes 0.3 though it is under the accumulation floor
    assert not assess_run("m", _run(), {"trust": floors}, _metrics({"0": 25.0}, miou=0.4,
                                                                   object_accumulation=0.7)).flagged


def test_a_run_json_without_a_step_count_is_undertrained():
    """An unknown step count cannot be shown to reach min_steps."""
    flag = assess_run("m", {"status": "completed"}, {"trust": FLOORS}, _metrics({"0": 25.0}))
    assert flag.reasons == ["run.json records no step count"] and flag.label == "undertrained"
    flag = assess_run("m", {"status": "completed", "steps": "lots"}, {"trust": FLOORS}, _metrics({"0": 25.0}))
    assert flag.reasons == ["run.json records no step count"]


def test_a_run_above_every_floor_is_not_flagged():
    flag = assess_run("m", _run(steps=1000), {"trust": FLOORS}, _metrics({"0": 20.0}, miou=0.5,
                                                                         object_accumulation=0.5))
    assert not flag.flagged and flag.reasons == [] and flag.floors == FLOORS
    # an evaluation older than the accumulation record (EVALUATE_VERSION < 5) is not judged on it
    assert not assess_run("m", _run(), {"trust": FLOORS}, _metrics({"0": 25.0}, object_accumulation=None)).flagged
    both = assess_run("m", _run(steps=10), {"trust": FLOORS}, _metrics({"0": 10.0}))
    assert both.label == "undertrained and not trustworthy" and len(both.reasons) == 2


def test_a_run_without_a_trust_section_uses_the_trustconfig_defaults(tmp_path):
    defaults = asdict(TrustConfig())
    floors, origin = trust_floors({"method": "livescene"})
    assert floors == defaults and "TrustConfig defaults" in origin
    partial, _ = trust_floors({"trust": {"min_psnr": 12.5}})
    assert partial == defaults | {"min_psnr": 12.5}
    flag = assess_run("m", _run(steps=int(defaults["min_steps"]) - 1), None, _metrics({"0": 99.0}))
    assert flag.flagged and f"< trust.min_steps {int(defaults['min_steps']):,}" in flag.reasons[0]
    with pytest.raises(InputError, match=r"trust\.min_steps is .many."):
        trust_floors({"trust": {"min_steps": "many"}}, tmp_path / "config.yaml")


# -- the page and summary.json --------------------------------------------------------------------------------------


def test_page_and_summary_carry_the_verdict_and_the_flags(tmp_path, tiny_dataset):
    html = build_page(tmp_path, tiny_dataset.root).read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    verdicts = {r["metric"]: r for r in summary["verdict"] if r["baseline"] == "conerf"}
    n_views = len(tiny_dataset.frames_in("test"))
    # the fakes: conerf exactly 1 dB above LiveScene on each view, LiveScene 2 +- 0.4 dB above on 4 unseen renders,
    # grounding IoUs differing both ways on 3 queries x n views
    assert verdicts["held_out_psnr"]["n"] == n_views and verdicts["held_out_psnr"]["mean_difference"] == \
        pytest.approx(-1.0)
    assert verdicts["held_out_psnr"]["verdict"] == "LiveScene behind"
    assert verdicts["unseen_psnr"]["n"] == 4 and verdicts["unseen_psnr"]["verdict"] == "LiveScene ahead"
    lo, hi = verdicts["unseen_psnr"]["ci95"]
    half = T_975[3] * math.sqrt(4 * 0.4**2 / 3) / 2
    assert (lo, hi) == (pytest.approx(2.0 - half), pytest.approx(2.0 + half))
    assert verdicts["grounding_iou"]["verdict"] == f"no measurable difference (n={3 * n_views})"
    assert all(r["rests_on_flagged_run"] == ["conerf"] for r in verdicts.values())
    assert verdicts["held_out_psnr"]["statement"] == \
        "LiveScene behind, but it rests on a flagged run: conerf (undertrained)"

    trust = {m: v["trust"] for m, v in summary["methods"].items()}
    assert not trust["livescene"]["flagged"] and "config.yaml" in trust["livescene"]["floors_from"]
    assert trust["conerf"]["flagged"] and trust["conerf"]["label"] == "undertrained"
    assert trust["conerf"]["reasons"] == [f"401 steps < trust.min_steps {TrustConfig().min_steps:,}"]

    verdict_html = html.split('<section id="verdict">')[1].split("</section>")[0]
    assert "LiveScene behind" in verdict_html and "LiveScene ahead" in verdict_html
    assert "rests on a flagged run: conerf (undertrained)" in verdict_html
    assert "livescene seed 0, conerf seed 0" in verdict_html and "not over training seeds" in verdict_html
    methods_html = html.split('<section id="methods">')[1].split("</section>")[0]
    assert 'class="flag"' in methods_html and "401 steps &lt; trust.min_steps" in methods_html
    assert methods_html.index("&#9888; undertrained") < methods_html.index("21.000")  # the flag sits by the numbers
    assert "2.500" in methods_html and "3.500" in methods_html  # render fps read from timings.json

    index = build_index(load_summaries([tmp_path / "summary.json"]))
    assert "conerf: PSNR 21.00 dB" in index and "&#9888; undertrained" in index
    # the fakes: behind on held-out, ahead on unseen combinations, level on grounding (no split, no locality items)
    assert "vs conerf: 1 ahead, 1 level, 1 behind" in index and "rests on flagged conerf" in index
    assert index.index("Verdicts across scenes") < index.index("<h2>Scenes</h2>")


def test_curves_against_steps_and_wall_time(tmp_path, tiny_dataset):
    results = make_fake_results(tmp_path / "r", tiny_dataset.root)
    steps, psnr, loss_steps, loss = train_curve_by_step(results / "runs" / "livescene" / "train_log.csv")
    assert steps == [50.0 * i for i in range(8)] and psnr == [12.0 + i for i in range(8)]
    assert loss_steps == steps and loss[0] == pytest.approx(0.3)
    html = build_page(tmp_path, tiny_dataset.root).read_text()
    curves = html.split('<section id="curves">')[1].split("</section>")[0]
    assert "held-out error against steps" in curves and "held-out error against run time" in curves
    assert curves.count("<svg") == 4 and "training step" in curves and "training wall time (s)" in curves


def test_locality_verdict_reads_lower_as_better():
    from stages.report.paired import locality_items

    def loc(outside: list[float]) -> dict:
        return {"locality": {"status": "computed", "records": [
            {"frame": f"f{i}", "object": "door", "model_outside_x255": v} for i, v in enumerate(outside)]}}

    ours, theirs = loc([0.4, 0.5, 0.6, 0.5]), loc([10.2, 11.0, 9.8, 10.6])
    assert locality_items(ours)[("f0", "door")] == 0.4
    row = next(r for r in compare({"livescene": ours, "mk-planes": theirs}, {}) if r.metric == "locality_outside")
    assert row.n == 4 and row.mean == pytest.approx(-9.9)
    assert row.verdict == "LiveScene ahead"  # it leaves the rest of the room alone, the baseline does not
    row = next(r for r in compare({"livescene": theirs, "mk-planes": ours}, {}) if r.metric == "locality_outside")
    assert row.verdict == "LiveScene behind"


# -- exposure -----------------------------------------------------------------------------------------------------


def test_the_methods_table_says_how_each_run_treated_the_exposure():
    from types import SimpleNamespace

    from stages.report.scene_page import _exposure_note

    auto = {"mode": "measured", "requested": "auto", "reason": "exposure spread 0.0385 >= 0.01", "spread": 0.0385}
    sd = SimpleNamespace(methods=[SimpleNamespace(name="livescene", run={"appearance": auto}),
                                  SimpleNamespace(name="mk-planes", run={"appearance": auto}),
                                  SimpleNamespace(name="conerf", run={"appearance": {"mode": "affine"}}),
                                  SimpleNamespace(name="k-planes", run=None)])  # not trained: not named
    note = _exposure_note(sd)
    assert "livescene, mk-planes: each training image divided by its measured exposure gains (auto: exposure " \
           "spread 0.0385 &gt;= 0.01)" in note
    assert "conerf: a colour correction learned per training frame" in note
    assert "k-planes" not in note.replace("mk-planes", "")
    # the reference (nothing asked, nothing done) and runs older than the record say nothing
    plain = SimpleNamespace(methods=[SimpleNamespace(name="livescene", run={"appearance": {"mode": "none"}}),
                                     SimpleNamespace(name="conerf", run={})])
    assert _exposure_note(plain) == ""


def test_the_nominal_exposure_row_appears_only_for_runs_that_measured_their_gains():
    plain = {"livescene": _metrics({"a": 25.0, "b": 26.0}), "mk-planes": _metrics({"a": 24.0, "b": 25.5})}
    assert "held_out_psnr_nominal" not in {r.metric for r in compare(plain, {})}
    measured = {m: json.loads(json.dumps(v)) for m, v in plain.items()}
    for m, values in (("livescene", (26.0, 27.0)), ("mk-planes", (25.0, 26.0))):
        for view, value in zip(measured[m]["held_out"]["views"], values, strict=True):
            view["psnr_nominal"] = value
    row = next(r for r in compare(measured, {}) if r.metric == "held_out_psnr_nominal")
    assert row.n == 2 and row.mean == pytest.approx(1.0) and "nominal exposure" in row.label


def test_a_run_without_an_evaluation_is_not_shown_as_passing_its_floors():
    flag = assess_run("mk-planes", {"status": "completed", "steps": 5000}, {"trust": {"min_steps": 100}}, None)
    assert flag.flagged and "not evaluated" in " ".join(flag.reasons)
