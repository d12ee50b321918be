"""The HTML page of one scene: every section the workflow can fill, each saying why when it cannot."""

from __future__ import annotations

import json
import math
from collections import defaultdict
from datetime import datetime, timezone
from html import escape
from pathlib import Path
from typing import Any

from stages.evaluate.evaluation import grounding_figure
from stages.scene.dataset import spans_closed_to_open
from stages.scene.machine import machine_line

from .export_section import section_export
from .frames_section import section_frames
from .html_parts import fmt, missing, note_list, page, table
from .images import error_map, file_data_uri, png_data_uri, read_rgb
from .labels_section import section_labels
from .paired import LIVESCENE, PairedResult, compare
from .scene_data import MethodData, SceneData, benchmark_stem
from .svg_plot import Series, bar_chart_svg, line_plot_svg
from .trust import TrustFlag, assess_run

SECTIONS = [
    ("rules", "Rules run and skipped"),
    ("timings", "Stage timings"),
    ("frames", "Frames"),
    ("poses", "Pose quality"),
    ("labels", "Object masks"),
    ("states", "Interpolation errors"),
    ("methods", "Methods"),
    ("verdict", "Verdict: LiveScene against each baseline"),
    ("curves", "Error against steps and run time"),
    ("grid", "Held-out views"),
    ("sliders", "Object state sliders"),
    ("relevancy", "Relevancy maps"),
    ("unseen", "Unseen state combinations"),
    ("locality", "Locality of control"),
    ("commands", "Language commands"),
    ("export", "Export: meshes and point clouds"),
    ("stability", "Stability checks"),
    ("digests", "Digests: where two runs part"),
]


def _why_skipped(sd: SceneData, rule: str) -> str:
    entry = sd.plan.get(rule)
    if entry is None:
        return f"rule {rule} is not part of this workflow"
    if entry.get("needed"):
        where = f"see {sd.inputs.logs}/" if sd.inputs.logs is not None else "see the rule's log"
        return f"rule {rule} was planned but its output is missing ({where})"
    return f"rule {rule} skipped for this scene: {entry.get('why', 'not needed')}"


def _section_export(sd: SceneData) -> str:
    planned = [k[len("export["):-1] for k, v in sd.plan.items() if k.startswith("export[") and v.get("needed")]
    why = (f"rule export[{planned[0]}] was planned but its output is missing" if planned
           else "no method of this scene is in export.methods")
    return section_export(dict(sd.inputs.export), why)


def _rule_benchmark(sd: SceneData, rule: str) -> dict | None:
    """Benchmark of a plan entry such as 'train[conerf]' (file train_conerf.tsv)."""
    return sd.benchmarks.get(benchmark_stem(rule))


def section_rules(sd: SceneData) -> str:
    rows = []
    for rule, entry in sd.plan.items():
        bench = _rule_benchmark(sd, rule)
        if entry.get("needed"):
            status = '<span class="ok">ran</span>' if bench else "planned (no benchmark yet)"
            if rule == "stability" and sd.stability:
                status = '<span class="ok">ran</span>'
        else:
            status = '<span class="skip">skipped</span>'
        rows.append([escape(rule), status, escape(entry.get("why", "")), bench["s"] if bench else None])
    return table(["rule", "status", "why", "wall s"], rows)


def _scene_seconds(sd: SceneData) -> float:
    """The scene's own jobs' wall seconds (the shared stability suite left out: the index adds scenes up)."""
    return sum(v["s"] for k, v in sd.benchmarks.items() if k != "stability" and math.isfinite(v["s"]))


def section_timings(sd: SceneData) -> str:
    if not sd.benchmarks:
        folder = f"in {sd.inputs.benchmarks}/" if sd.inputs.benchmarks is not None else "given"
        return missing(f"No benchmark files {folder}: no rule of this scene has run yet.")
    items = sorted(((k, v["s"]) for k, v in sd.benchmarks.items() if math.isfinite(v["s"])), key=lambda kv: -kv[1])
    total = _scene_seconds(sd)
    rows = [[escape(k), v["s"], v["cpu_time"], v["max_rss"]] for k, v in
            sorted(sd.benchmarks.items(), key=lambda kv: -kv[1]["s"])]
    shared = " The stability suite runs once for every scene: listed, not summed." if "stability" in sd.benchmarks \
        else ""
    return (f"<p>Measured by Snakemake's <code>benchmark:</code> directive. Sum of this scene's job wall times: "
            f"<b>{total:.1f} s</b> (jobs may overlap on several cores).{shared}</p>"
            + bar_chart_svg(items) + table(["job", "wall s", "cpu s", "max RSS MiB"], rows))


def section_poses(sd: SceneData) -> str:
    if sd.poses is None:
        return missing(_why_skipped(sd, "poses"))
    p = sd.poses
    rows = [["registered frames", f"{p.get('n_registered')} / {p.get('n_frames')}"],
            ["registered fraction", fmt(p.get("registered_fraction"))],
            ["mean reprojection error (px)", fmt(p.get("mean_reprojection_error", p.get("reprojection_error")))],
            ["3D points", fmt(p.get("n_points3D"))],
            ["matcher", fmt(p.get("matcher"))],
            ["COLMAP seconds", fmt((p.get("timings") or {}).get("total"), 1)]]
    if p.get("source") == "import":
        rows.append(["source", "imported COLMAP model (no SfM)"])
    w = p.get("world_frame")
    if w:  # docs/poses.md, "World frame"
        rows.append(["world frame", f"turned upright: up from {escape(str(w.get('up_source')))} "
                     f"({fmt(w.get('up_tilt_deg'), 1)} deg from the cameras' up), x and y from "
                     f"{escape(str(w.get('yaw_source')))} (strength {fmt(w.get('yaw_strength'), 2)})"])
    elif "world_frame" in p:
        rows.append(["world frame", "COLMAP's, as the mapper left it (--no-orient)"])
    up = p.get("up_check")
    if up:  # docs/poses.md, "World frame": a second up, which only warns
        rows.append(["up check: largest horizontal plane's normal against z (deg)",
                     f"{fmt(up.get('plane_tilt_deg'), 2)} ({up.get('plane_points')} of {up.get('n_points')} points)"
                     if up.get("plane_tilt_deg") is not None else "no horizontal plane found: not checked"])
    given = (p.get("camera") or {}).get("focal_given")
    if given:  # docs/poses.md, "Known focal length"
        rows.append(["focal length given", f"{fmt(given.get('focal_px'), 1)} px ({escape(str(given.get('given')))}; "
                     + ("refined by COLMAP)" if given.get("refined") else "kept fixed)")])
    t = p.get("trajectory") or {}
    if t:  # the numbers the pose gate judged (docs/poses.md, "Quality gate")
        reason = f": {escape(t['reason'])}" if t.get("reason") else ""
        rows += [["gate verdict", escape(str(t.get("verdict"))) + reason],
                 ["baseline ratio (camera spread / median point depth)", fmt(t.get("baseline_ratio"))],
                 ["share of frames in the largest model", fmt(t.get("largest_model_share"))],
                 ["share of cameras resting on one spot", fmt(t.get("still_share"))],
                 ["longest step / typical step", fmt(t.get("max_step_ratio"))],
                 ["frames trimmed as jumps", escape(", ".join(t.get("trimmed") or []) or "none")]]
    html = table(["COLMAP", "value"], rows)
    warnings = p.get("warnings") or []
    if warnings:  # the stage printed them on stderr, where a workflow's log keeps them out of sight
        html += note_list(f"{len(warnings)} warning(s) from the poses stage (poses.json, warnings):",
                          [escape(str(w)) for w in warnings])
    if sd.pose_error is None:
        html += missing(_why_skipped(sd, "pose_compare"))
    else:
        e = sd.pose_error
        fe = e.get("focal_error") or {}
        rows = [["frames matched", fmt(e.get("n_matched"))],
                ["camera-centre error / scene extent (mean, max)",
                 f"{fmt(100 * e['centre_error_relative']['mean'], 2)} %, "
                 f"{fmt(100 * e['centre_error_relative']['max'], 2)} %"],
                ["rotation error deg (mean, max)",
                 f"{fmt(e['rotation_error_deg']['mean'], 2)}, {fmt(e['rotation_error_deg']['max'], 2)}"],
                ["focal error (relative fx)", f"{fmt(100 * fe['relative_fx'], 2)} %" if "relative_fx" in fe else "–"],
                ["alignment scale (truth -> COLMAP)", fmt(e.get("scale"))],
                ["world axes against the truth's (deg, up to relabelling)", fmt(e.get("axes_misalignment_deg"), 2)]]
        html += "<h3>Against the truth</h3>" + table(["pose error", "value"], rows)
    return html


def section_states(sd: SceneData) -> str:
    if sd.states is None:
        return missing(_why_skipped(sd, "states"))
    loo = sd.states.get("leave_one_out") or {}
    methods = sd.states.get("methods") or {}
    rows = []
    for obj, per in loo.items():
        for method, v in per.items():
            chosen = " (used)" if methods.get(obj) == method else ""
            truth = sd.states_vs_truth.get(obj, {}) if chosen else {}
            rows.append([escape(obj), escape(method + chosen), v.get("mae"), v.get("max"), v.get("n"),
                         truth.get("mae"), truth.get("max")])
    html = ("<p>Leave-one-out: each key frame predicted from the others. Against truth: the dense interpolated "
            "states of every frame against the capture's dense truth states.</p>")
    html += table(["object", "interpolation", "leave-one-out MAE", "LOO max", "n", "vs truth MAE", "vs truth max"],
                  rows)
    if not sd.states_vs_truth:
        html += missing("No truth states for this scene: the interpolation is checked by leave-one-out only.")
    return html


def _metric(m: MethodData, *keys: str) -> Any:
    value: Any = m.metrics
    for k in keys:
        if not isinstance(value, dict):
            return None
        value = value.get(k)
    return value


def scene_trust(sd: SceneData) -> dict[str, TrustFlag]:
    """The trust flag of every method that trained or was evaluated."""
    return {m.name: assess_run(m.name, m.run, m.config, m.metrics,
                               m.run_dir / "config.yaml" if m.run_dir is not None else "config.yaml")
            for m in sd.methods if m.run is not None or m.metrics is not None}


def _flag_html(flag: TrustFlag | None) -> str:
    """A visible warning next to a run's numbers (or 'ok' with the floors it passed)."""
    if flag is None:
        return "–"
    if not flag.flagged:
        return (f'<span class="ok">ok</span><br><span class="note">&ge; {flag.floors["min_steps"]:,.0f} steps, '
                f'PSNR &ge; {fmt(flag.floors["min_psnr"], 1)} dB, mIoU &ge; '
                f'{fmt(flag.floors["min_grounding_miou"], 2)}, object accumulation &ge; '
                f'{fmt(flag.floors["min_object_accumulation"], 2)}</span>')
    return (f'<span class="flag">&#9888; {escape(flag.label)}: '
            + "; ".join(escape(r) for r in flag.reasons) + "</span>")


def _flag_banner(flags: dict[str, TrustFlag]) -> str:
    flagged = [f for f in flags.values() if f.flagged]
    if not flagged:
        return ""
    names = ", ".join(f"{escape(f.method)} ({escape(f.label)})" for f in flagged)
    return (f'<p class="flag">&#9888; Not results: {names}. These runs fail the trust checks of their config '
            f"(trust section of config.yaml; the reasons are in the methods table's trust column): their numbers "
            f"are shown for diagnosis only.</p>")


def _ssim_form(sd: SceneData) -> str:
    """Which SSIM the evaluation computed (older metrics.json files predate the record: say so)."""
    forms = {str(_metric(m, "held_out", "ssim_form")) for m in sd.methods if m.metrics is not None}
    forms.discard("None")
    if not forms:
        return "SSIM: form not recorded (metrics.json older than the Gaussian-window SSIM)."
    return "SSIM: " + escape("; ".join(sorted(forms))) + "."


def _scale_note(sd: SceneData) -> str:
    """Which image size the evaluation scored at, when it was not the dataset's own (``evaluate --max-side``)."""
    scales = {_metric(m, "config", "render_scale") for m in sd.methods if m.metrics is not None}
    scales = {float(s) for s in scales if isinstance(s, (int, float)) and s != 1.0}
    if not scales:
        return ""
    sizes = " and ".join(f"1/{round(1 / s)}" if abs(1 / s - round(1 / s)) < 1e-6 else fmt(s, 3) for s in sorted(scales))
    return (f" Every view was rendered and scored at {sizes} of the dataset's image size (evaluate.max_side; "
            "docs/workflow.md, \"Evaluation budget\").")


def _view_alignment_note(sd: SceneData) -> str:
    """Which runs refined their training cameras and so were scored at aligned held-out poses (docs/model.md,
    "Camera refinement"); nothing for runs that did not."""
    parts = []
    for m in sd.methods:
        pa = (m.metrics or {}).get("view_alignment")
        if not isinstance(pa, dict):
            continue
        rot = (pa.get("rotation_deg") or {}).get("mean")
        size = f", mean correction {fmt(rot, 2)} degrees" if isinstance(rot, (int, float)) else ""
        parts.append(f"{escape(m.name)} ({escape(str(pa.get('training_cameras')))}: each held-out pose aligned by "
                     f"{escape(str(pa.get('steps')))} steps against its image, model frozen{size})")
    return (" Refined training cameras: " + "; ".join(parts) + "; their held-out, unseen-combination and grounding "
            "numbers are at those aligned poses, the others' at the dataset's.") if parts else ""


APPEARANCE_WORDS = {"affine": "a colour correction learned per training frame",
                    "measured": "each training image divided by its measured exposure gains",
                    "none": "the images as they are"}


def _machines_note(sd: SceneData) -> str:
    """The machine(s) the runs' wall times come from (run.json): the same steps take 2-3x longer on a slower CPU."""
    said: dict[str, list[str]] = defaultdict(list)
    for m in sd.methods:
        machine = (m.run or {}).get("machine")
        if isinstance(machine, dict) and machine.get("cpu"):
            said[machine_line(machine)].append(m.name)
    if len(said) == 1:
        return f" Training ran on {escape(next(iter(said)))}."
    return "".join(f" {escape(', '.join(names))} trained on {escape(line)}." for line, names in said.items())


def _exposure_note(sd: SceneData) -> str:
    """How the runs treated the frames' exposure, when it was not left alone (docs/model.md, "Exposure")."""
    said: dict[str, list[str]] = defaultdict(list)  # what was done -> methods: said once for all that did it
    for m in sd.methods:
        a = (m.run or {}).get("appearance") or {}
        if a.get("mode", "none") == "none" and "requested" not in a:
            continue
        spread = a.get("spread")
        how = APPEARANCE_WORDS.get(a.get("mode"), str(a.get("mode")))
        why = f" (auto: {a['reason']})" if a.get("requested") == "auto" and a.get("reason") else (
            f" (exposure spread {spread:.4f})" if isinstance(spread, (int, float)) else "")
        said[how + why].append(m.name)
    parts = [f"{escape(', '.join(names))}: {escape(what)}" for what, names in said.items()]
    return (" Exposure: " + "; ".join(parts) + "; renders and scores use the nominal colour.") if parts else ""


def section_methods(sd: SceneData) -> str:
    rows = []
    flags = scene_trust(sd)
    lpips_missing: dict[str, list[str]] = defaultdict(list)  # why LPIPS is absent -> methods: said once, below
    for m in sd.methods:
        if m.run is None and m.metrics is None:
            rows.append([escape(m.name)] + [escape(_why_skipped(sd, f"train[{m.name}]"))] + [None] * 12)
            continue
        lpips = _metric(m, "held_out", "lpips", "mean")
        if lpips is None and m.metrics is not None:
            lpips_missing[str(_metric(m, "held_out", "lpips_status") or "not available")].append(m.name)
        run = m.run or {}
        params = (run.get("params") or {}).get("total")
        grounding = _metric(m, "grounding", "miou_probs")
        fps = ((m.timings or {}).get("held_out") or {}).get("fps")  # wall clock: timings.json, not metrics.json
        rows.append([escape(m.name), _flag_html(flags.get(m.name)), _metric(m, "held_out", "psnr", "mean"),
                     _metric(m, "held_out", "psnr_objects", "mean"), _metric(m, "held_out", "psnr_static", "mean"),
                     _metric(m, "held_out", "ssim", "mean"),
                     lpips, _metric(m, "unseen_combinations", "psnr", "mean"),
                     grounding if isinstance(grounding, (int, float)) else None,
                     # on a GPU the allocator's reserved peak: a CUDA graph's pool is reserved, not allocated
                     params, run.get("peak_reserved_mib") or run.get("peak_memory_mib"), run.get("train_seconds"),
                     run.get("steps"),
                     fps if isinstance(fps, (int, float)) else None])
    return ("<p>Held-out views of the test split; unseen combinations and grounding need truth and names. "
            "PSNR objects / static: the same views' PSNR over the pixels of any object mask and over the rest "
            "(what the states drive, and what they should leave alone). "
            "Memory is the training process's peak (max RSS on a CPU; on a GPU what the CUDA allocator reserved, "
            "CUDA graphs' memory included). Trust: a run under its config's trust "
            "floors (steps, held-out PSNR, grounding mIoU of probabilities on object names, held-out accumulation "
            "over object pixels: objects mostly transparent are painted on what lies behind them) or whose "
            "training did not complete is flagged, and its numbers are not results. "
            + _ssim_form(sd) + _scale_note(sd) + _exposure_note(sd) + _view_alignment_note(sd) + _machines_note(sd)
            + "".join(f" LPIPS of {escape(', '.join(names))}: {escape(why)}." for why, names in lpips_missing.items())
            + "</p>"
            + _flag_banner(flags)
            + table(["method", "trust", "PSNR dB", "PSNR objects dB", "PSNR static dB", "SSIM", "LPIPS",
                     "unseen PSNR dB", "grounding mIoU (probs)", "parameters", "peak memory MiB", "train s",
                     "steps", "render fps"], rows))


def scene_verdict(sd: SceneData, flags: dict[str, TrustFlag] | None = None) -> list[PairedResult]:
    """Paired differences of LiveScene against each evaluated baseline (see stages.report.paired)."""
    flags = scene_trust(sd) if flags is None else flags
    return compare({m.name: m.metrics for m in sd.methods if m.metrics is not None},
                   {name: f.label for name, f in flags.items() if f.flagged})


def _interval(ci: list[float] | None, unit: str) -> str:
    if ci is None:
        return "– (n &lt; 2)"
    return f"[{fmt(ci[0], 3)}, {fmt(ci[1], 3)}]{' ' + unit if unit else ''}"


def section_verdict(sd: SceneData) -> str:
    names = [m.name for m in sd.methods]
    if LIVESCENE not in names:
        return missing("LiveScene is not among this scene's methods: there is nothing to compare.")
    if not any(m.name == LIVESCENE and m.metrics for m in sd.methods):
        return missing("No LiveScene evaluation to compare: " + _why_skipped(sd, f"evaluate[{LIVESCENE}]"))
    flags = scene_trust(sd)
    results = scene_verdict(sd, flags)
    if not results:
        return missing("No evaluated baseline to compare LiveScene against (methods: " + ", ".join(names) + ").")
    rows = []
    for r in results:
        cls = {"LiveScene ahead": "ok", "LiveScene behind": "fail"}.get(r.verdict, "skip")
        cell = f'<span class="{cls}">{escape(r.verdict)}</span>'
        if r.flagged:
            cell += ('<br><span class="flag">&#9888; rests on a flagged run: '
                     + ", ".join(f"{escape(n)} ({escape(label)})" for n, label in r.flagged.items()) + "</span>")
        if r.note:
            cell += f'<br><span class="note">{escape(r.note)}</span>'
        mean = f"{fmt(r.mean, 3)}{' ' + r.unit if r.unit and r.mean is not None else ''}"
        rows.append([escape(r.baseline), escape(r.label), r.n, mean, _interval(r.ci95, r.unit), cell])
    return ("<p>LiveScene minus the baseline on the same items (same views, same unseen state vectors, same "
            "objects and views of the grounding, an object's name and synonyms averaged: they are scored on one "
            "mask): mean difference and its 95% Student-t interval. A verdict says "
            "ahead or behind only when the interval excludes 0; higher is better for every metric "
            "but those marked lower is better.</p>"
            + _seed_caveat(sd)
            + _flag_banner(flags)
            + table(["baseline", "paired metric", "n", "mean difference", "95% CI", "verdict"], rows))


def _seed_caveat(sd: SceneData) -> str:
    """Which training each method's items come from: the interval spans views and queries, not training seeds."""
    seeds = {m.name: (m.run or {}).get("seed", (m.config or {}).get("seed")) for m in sd.methods if m.metrics}
    told = ", ".join(f"{escape(n)} seed {escape(str(s))}" for n, s in seeds.items() if s is not None)
    return ("<p class=\"note\">Each method was trained once" + (f" ({told})" if told else "")
            + ": the intervals cover the spread over views and queries of that training, not over training "
            "seeds. Another seed can move a method's held-out PSNR by a few tenths of a dB (docs/model.md, "
            "\"Locality and the probability field's state input\"), so a verdict by a margin that small is "
            "one training's.</p>")


def _eval_series(sd: SceneData, axis: str) -> list[Series]:
    """Held-out PSNR of every method against ``axis`` ("time": wall seconds, "step": steps), closed by run.json's
    final evaluation."""
    out = []
    for m in sd.methods:
        curve, end_key = (m.curve, "train_seconds") if axis == "time" else (m.step_curve, "steps")
        xs, ys = list(curve[0]), list(curve[1])
        final = (m.run or {}).get("eval_psnr"), (m.run or {}).get(end_key)
        if all(isinstance(v, (int, float)) for v in final) and (not xs or final[1] > xs[-1]):
            xs.append(float(final[1]))  # run.json's final evaluation closes the curve
            ys.append(float(final[0]))
        if xs:
            out.append(Series(m.name, xs, ys))
    return out


def section_curves(sd: SceneData) -> str:
    series = _eval_series(sd, "time")
    if not series:
        return missing("No periodic evaluation in any train_log.csv (training did not run or logged no eval_psnr).")
    loss = [Series(m.name, m.curve[2], m.curve[3]) for m in sd.methods if m.curve[2]]
    by_step = _eval_series(sd, "step")
    loss_by_step = [Series(m.name, m.step_curve[2], m.step_curve[3]) for m in sd.methods if m.step_curve[2]]
    return ("<p>Periodic held-out PSNR logged during training (higher PSNR = lower error), every method on one "
            "plot: against optimisation steps (the fair axis when every method trains the same steps), then "
            "against wall-clock seconds (which also measure the machine and its load)." + _machines_note(sd) + "</p>"
            + line_plot_svg(by_step, x_label="training step", y_label="eval PSNR (dB)",
                            title="held-out error against steps")
            + line_plot_svg(loss_by_step, x_label="training step", y_label="training loss",
                            title="training loss against steps")
            + line_plot_svg(series, x_label="training wall time (s)", y_label="eval PSNR (dB)",
                            title="held-out error against run time")
            + line_plot_svg(loss, x_label="training wall time (s)", y_label="training loss",
                            title="training loss against run time"))


def _img(uri: str | None, alt: str, width: int | None = None) -> str:
    if uri is None:
        return f'<span class="missing">{escape(alt)}: missing</span>'
    w = f' width="{width}"' if width else ""
    return f'<img src="{uri}" alt="{escape(alt)}"{w}>'


def section_grid(sd: SceneData, views: int) -> str:
    evaluated = [m for m in sd.methods if m.metrics and m.eval_dir]
    if not evaluated or sd.data is None:
        return missing("No evaluation with renders: " + _why_skipped(sd, f"evaluate[{sd.methods[0].name}]")
                       if sd.methods else "No methods.")
    frames = [v["frame"] for v in (_metric(evaluated[0], "held_out", "views") or [])][:views]
    paths = {v["frame"]: v.get("file_path") for v in (_metric(evaluated[0], "held_out", "views") or [])}
    if not frames:
        return missing("The evaluation wrote no held-out views.")
    head = ["view", "truth"] + [h for m in evaluated for h in (m.name, f"{m.name} error")]
    rows = []
    for fid in frames:
        truth = read_rgb(sd.data / paths[fid]) if paths.get(fid) else None
        cells = [escape(fid), _img(png_data_uri(truth) if truth is not None else None, f"truth {fid}")]
        for m in evaluated:
            render = read_rgb(m.eval_dir / "renders" / f"{fid}.png")
            psnr = next((v.get("psnr") for v in _metric(m, "held_out", "views") or [] if v["frame"] == fid), None)
            cells.append(_img(png_data_uri(render) if render is not None else None, f"{m.name} {fid}")
                         + f"PSNR {fmt(psnr, 2)}")
            cells.append(_img(png_data_uri(error_map(truth, render)) if truth is not None and render is not None
                              else None, f"{m.name} error {fid}"))
        rows.append(cells)
    return ("<p>Error maps: mean absolute RGB error per pixel, black = 0, yellow = 0.25 or more.</p>"
            + table(head, rows, cls="grid"))


def _beyond_note(obj: str, lo_hi: list[float] | None) -> str:
    """A line above an object's slider when its training frames do not reach both ends of the state range."""
    if lo_hi is None or spans_closed_to_open(lo_hi):
        return ""
    return (f'<p class="note">The training frames hold {escape(obj)} between {lo_hi[0]:.2f} and {lo_hi[1]:.2f}: '
            f"beyond that the renders extrapolate.</p>")


def section_sliders(sd: SceneData) -> tuple[str, dict[str, list[str]]]:
    """The slider HTML and the image lists the page script swaps between."""
    blocks, images = [], {}
    ranges = (sd.dataset_info or {}).get("state_ranges") or {}
    for m in sd.methods:
        if m.sweep is None or m.sweep_dir is None or not m.sweep.get("objects"):  # a static room has no slider
            continue
        blocks.append(f"<h3>{escape(m.name)} (view {escape(str(m.sweep.get('frame')))}, other objects at the "
                      f"view's state)</h3>")
        for obj, entry in (m.sweep.get("objects") or {}).items():
            key = f"sweep-{len(images)}"
            uris = [file_data_uri(m.sweep_dir / f) or "" for f in entry["images"]]
            images[key] = uris
            values = entry["values"]
            blocks.append(_beyond_note(obj, ranges.get(obj)))
            blocks.append(
                f'<div class="slider"><label>{escape(obj)} state: <input type="range" class="sweep" min="0" '
                f'max="{len(uris) - 1}" step="1" value="0" data-target="{key}" '
                f'data-values="{escape(json.dumps(values))}" aria-label="{escape(obj)} state"> '
                f'<output id="{key}-value">{values[0]:.2f}</output></label><br>'
                f'<img id="{key}" src="{uris[0]}" alt="{escape(m.name)} {escape(obj)} sweep"></div>')
    if not blocks:
        if not (sd.dataset_info or {}).get("objects", True):
            return missing("the scene has no objects, so there is no state to slide"), images
        first = sd.methods[0].name if sd.methods else "livescene"
        return missing(_why_skipped(sd, f"sweep[{first}]")), images
    return "".join(blocks), images


SLIDER_SCRIPT = """
const SWEEPS = %s;
document.querySelectorAll('input.sweep').forEach(function (el) {
  el.addEventListener('input', function () {
    const key = el.dataset.target, i = Number(el.value), values = JSON.parse(el.dataset.values);
    document.getElementById(key).src = SWEEPS[key][i];
    document.getElementById(key + '-value').textContent = values[i].toFixed(2);
  });
});
"""


def section_relevancy(sd: SceneData) -> str:
    blocks = []
    for m in sd.methods:
        g = _metric(m, "grounding")
        if not isinstance(g, dict) or g.get("status") != "computed" or m.eval_dir is None:
            continue
        figures = []
        folder = m.eval_dir / "grounding"
        for q in g.get("queries", []):
            query = q.get("query", "")
            for source in g.get("sources", ["probs"]):
                result = q.get(source) or {}
                frames, per_view = result.get("frames") or [], result.get("per_view") or []
                if not frames:
                    continue
                # the evaluation saves the map of the query's first view
                f = folder / grounding_figure(source, query, frames[0])
                if not f.is_file():
                    figures.append(missing(f"{query} ({source}): {f.name} not found"))
                    continue
                mean = (result.get("iou") or {}).get("mean")
                view = per_view[0] if per_view else None
                figures.append(f'<figure>{_img(file_data_uri(f), f"{query} {source}")}'
                               f'<figcaption>"{escape(query)}" ({escape(source)})<br>view {escape(str(frames[0]))}: '
                               f'IoU {fmt(view, 2)} (mean over {len(per_view)} views {fmt(mean, 2)})'
                               f'</figcaption></figure>')
        mious = ", ".join(f"mIoU {src} {fmt(g.get(f'miou_{src}'), 3)}" for src in g.get("sources", []))
        blocks.append(f"<h3>{escape(m.name)}</h3><p>threshold {fmt(g.get('threshold'), 2)}; {mious}</p>"
                      + "".join(figures))
    if not blocks:
        return missing("No grounding results: " + ("the scene has no names (language rules skipped)"
                                                    if not sd.plan.get("language_targets", {}).get("needed")
                                                    else "the evaluations computed no grounding"))
    return "".join(blocks)


def _cut_note(sd: SceneData, key: str, budget: str) -> str:
    """A sentence when the render budget gave an evaluation fewer poses than asked (a room of many objects)."""
    cuts = set()
    for m in sd.methods:
        part = _metric(m, key)
        if isinstance(part, dict) and part.get("views_cut"):
            cuts.add((part["views"], part["views_asked"], part.get(budget)))
    unit = "renders" if budget == "max_renders" else "(pose, object) pairs"
    return "".join(f"<p>{views} of {asked} poses: at {asked}, this room's objects would take more than the "
                   f"evaluation's budget of {limit} {unit} (docs/workflow.md, \"Evaluation budget\").</p>"
                   for views, asked, limit in sorted(cuts))


def _unobserved_note(sd: SceneData) -> str:
    """A sentence naming the levels left out of the unseen test because training never showed an object there."""
    notes = set()
    for m in sd.methods:
        u = _metric(m, "unseen_combinations")
        if not isinstance(u, dict):
            continue
        ranges = u.get("training_range") or {}
        for name, levels in (u.get("levels_not_observed") or {}).items():
            lo_hi = ranges.get(name)
            seen = f" (training: {fmt(lo_hi[0], 2)} to {fmt(lo_hi[1], 2)})" if lo_hi else ""
            notes.add((name, ", ".join(fmt(v, 2) for v in levels), seen, u.get("observed_within")))
    if not notes:
        return ""
    parts = "; ".join(f"{escape(name)} at {levels}{seen}" for name, levels, seen, _ in sorted(notes))
    within = fmt(sorted(notes)[0][3])
    return (f"<p>Left out of this test, as no training frame holds the object within {within} of the level (its "
            f"appearance there was never seen, so no method could recombine it): {parts}.</p>")


def section_unseen(sd: SceneData) -> str:
    rows = []
    for m in sd.methods:
        u = _metric(m, "unseen_combinations")
        if not isinstance(u, dict) or u.get("status") != "computed":
            continue
        rows.append([escape(m.name), (u.get("psnr") or {}).get("mean"), (u.get("psnr_moved") or {}).get("mean"),
                     (u.get("ssim") or {}).get("mean"), sum(1 for c in u.get("combinations", []) if c.get("unseen")),
                     len(u.get("combinations", []))])
    if not rows:
        return missing("No unseen-combination test: it needs the capture truth (no truth for this scene, or the "
                       "evaluation skipped it).")
    none = ""
    if all(r[4] == 0 for r in rows):  # e.g. one object: every state it takes is a training state
        none = ("<p>No candidate state vector is unseen: the training frames already show each of them (or one "
                "close to it), so this room has nothing to test here (as with a single object, objects that only "
                "ever move together, a capture dense in states, or no movable object at all).</p>")
    return ("<p>Held-out poses rendered at state combinations the training never showed, against the truth "
            "renderer; 'moved' = only the pixels of the objects that moved.</p>" + none
            + _cut_note(sd, "unseen_combinations", "max_renders") + _unobserved_note(sd)
            + table(["method", "PSNR dB", "PSNR moved dB", "SSIM", "unseen combinations", "combinations"], rows))


def section_locality(sd: SceneData) -> str:
    rows = []
    limit = None
    for m in sd.methods:
        loc = _metric(m, "locality")
        if not isinstance(loc, dict) or loc.get("status") != "computed":
            continue
        limit = loc.get("outside_limit_x255")
        for name, o in loc.get("objects", {}).items():
            verdict = '<span class="ok">local</span>' if o.get("local") else '<span class="fail">not local</span>'
            mean = {k: (o.get(k) or {}).get("mean") for k in ("model_outside_x255", "truth_outside_x255",
                                                              "model_inside_x255", "truth_inside_x255")}
            rows.append([escape(m.name), escape(name), *mean.values(), (o.get("model_outside_x255") or {}).get("n"),
                         verdict])
    if not rows:
        return missing("No locality test: it needs the capture truth (no truth for this scene, or the evaluation "
                       "skipped it).")
    return (f"<p>Each object set to 0 and to 1 with every other object at the view's own state: mean change of the "
            f"image (in 1/255 steps) outside the object's swept region (its truth pixels and cast shadows at every "
            f"state, dilated 2 px) and inside it. Control is local when the outside change stays at most "
            f"{fmt(limit)} and the inside change is larger. The truth renderer's own change is shown for "
            f"reference.</p>"
            + _cut_note(sd, "locality", "max_pairs") + _partial_range_note(sd)
            + table(["method", "object", "model outside", "truth outside", "model inside", "truth inside", "views",
                     "verdict"], rows))


def _partial_range_note(sd: SceneData) -> str:
    """A sentence naming objects whose training frames do not reach 0 and 1, whose test states then extrapolate."""
    ranges = (sd.dataset_info or {}).get("state_ranges") or {}
    partial = [f"{escape(name)} ({lo_hi[0]:.2f} to {lo_hi[1]:.2f})" for name, lo_hi in sorted(ranges.items())
               if lo_hi is not None and not spans_closed_to_open(lo_hi)]
    if not partial:
        return ""
    return ("<p>The training frames do not take every object from closed to open: " + "; ".join(partial)
            + ". For those the test's states beyond that range are extrapolations: a leak outside the object "
              "still counts against control, but the inside change is the model's guess.</p>")


def section_commands(sd: SceneData) -> str:
    blocks = []
    for m in sd.methods:
        if not m.control:
            continue
        rows = []
        for c in m.control.get("commands", []):
            if "error" in c:
                rows.append([escape(c.get("command", "")), f'<span class="fail">{escape(str(c["error"]))}</span>',
                             ""])
                continue
            states = c.get("states")
            shown = escape(", ".join(f"{k} {v:.2f}" for k, v in states.items()) if isinstance(states, dict) else
                           json.dumps(states))
            for name, b in (c.get("beyond_training") or {}).items():  # the control stage's note, as it printed it
                lo, hi = b["training_range"]
                shown += (f'<br><span class="note">{escape(name)} at {b["state"]:.2f} is beyond the states its '
                          f"training frames show ({lo:.2f} to {hi:.2f}): the render extrapolates</span>")
            image = _command_image(m, c["image"]) if c.get("image") else None
            rows.append([escape(c.get("command", "")), shown, _img(image, c.get("command", ""), 160)])
        blocks.append(f"<h3>{escape(m.name)}</h3>" + table(["command", "resulting states", "render"], rows))
    if not blocks:
        first = sd.methods[0].name if sd.methods else "livescene"
        return missing(_why_skipped(sd, f"control[{first}]"))
    return "".join(blocks)


def _command_image(m: MethodData, recorded: str) -> str | None:
    """A command's render: the control stage writes it next to commands.json, so it is looked up in the given
    folder first (the recorded path only holds where the stage ran)."""
    beside = m.control_dir / Path(recorded).name if m.control_dir is not None else None
    return file_data_uri(beside) if beside is not None and beside.is_file() else file_data_uri(recorded)


def section_stability(sd: SceneData) -> str:
    s = sd.stability
    if not s:
        return missing(_why_skipped(sd, "stability"))
    counts = s.get("counts", {})
    rows = []
    for c in s.get("cases", []):
        result = c.get("result", "")
        cls = {"pass": "ok", "skip": "skip"}.get(result, "fail")
        rows.append([escape(c.get("name", "")), escape(c.get("group", "")), f'<span class="{cls}">{escape(result)}'
                     f"</span>", escape(str(c.get("metric", ""))[:300]), c.get("seconds")])
    return (f"<p>{', '.join(f'{v} {k}' for k, v in counts.items())} in {fmt(s.get('seconds'), 1)} s"
            f"{' (quick mode)' if s.get('quick') else ''}.</p>"
            + table(["case", "group", "result", "metric", "s"], rows))


def section_digests(sd: SceneData) -> str:
    """Each stage output's SHA-256 over its result files (digests.py): the first row that differs from another
    run's page (or digests.csv) is the stage where the two runs part (docs/workflow.md, "Where two runs part")."""
    if not sd.digests:
        return missing("The report inputs name no stage output to digest.")
    rows = [[escape(d.stage), d.files,
             escape(d.left_out) or "–",
             f"<code>{d.digest}</code>" if d.digest else f'<span class="fail">not found: {escape(str(d.path))}</span>']
            for d in sd.digests]
    return ("<p>SHA-256 of each stage's result files (first 12 hex digits), in pipeline order. The same job gives "
            "the same digests on one machine; on another CPU the first row that differs is the stage where the two "
            "runs part, and every stage after it differs too. Compare two machines' <code>digests.csv</code> "
            "(beside the index) with <code>diff</code> (docs/workflow.md, \"Where two runs part\"). Left out: "
            "hidden marker files, and what records time, machine, load or absolute paths.</p>"
            + table(["stage", "files covered", "left out", "digest"], rows))


def scene_summary(sd: SceneData, page: str) -> dict:
    """Headline numbers for the index page, with each run's trust flag and the paired verdict; ``page`` is the
    link from the index to the scene page."""
    flags = scene_trust(sd)
    return {"scene": sd.scene, "page": page,
            "objects": (sd.dataset_info or {}).get("objects", []),
            "frames": (sd.dataset_info or {}).get("frames"),
            "registered_fraction": (sd.poses or {}).get("registered_fraction"),
            "methods": {m.name: {"psnr": _metric(m, "held_out", "psnr", "mean"),
                                 "ssim": _metric(m, "held_out", "ssim", "mean"),
                                 "train_seconds": (m.run or {}).get("train_seconds"),
                                 "steps": (m.run or {}).get("steps"),
                                 "trust": flags[m.name].to_dict() if m.name in flags else None}
                        for m in sd.methods},
            "verdict": [r.to_dict() for r in scene_verdict(sd, flags)],
            "skipped": [k for k, v in sd.plan.items() if not v.get("needed") and _of_scene(k, sd)],
            "job_seconds": round(_scene_seconds(sd), 1),
            "digests": [d.to_dict() for d in sd.digests],
            # when the page was built: the index shows it for pages an earlier run left (summary only, not the page)
            "built": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}


def _of_scene(rule: str, sd: SceneData) -> bool:
    """A plan entry that concerns this scene: not one of a method the scene's row does not list
    (``train[k-planes]``)."""
    method = rule.partition("[")[2].rstrip("]")
    return not method or method in {m.name for m in sd.methods}


def build_scene_page(sd: SceneData, *, views: int = 3, index: str | None = None) -> str:
    """The complete HTML page of one scene; ``index`` is the link back to the index page (none when None)."""
    info = sd.dataset_info or {}
    back = f'<a href="{escape(index)}">all scenes</a> · ' if index is not None else ""
    head = (f"<h1>Scene {escape(sd.scene)}</h1><p>{back}dataset "
            f"{escape(str(sd.data))}: {fmt(info.get('frames'))} frames ({fmt(info.get('train'))} train, "
            f"{fmt(info.get('test'))} test), {fmt(info.get('width'))}x{fmt(info.get('height'))}, objects "
            f"{escape(', '.join(info.get('objects', [])) or '–')}</p>")
    nav = "<nav>" + "".join(f'<a href="#{k}">{escape(t)}</a>' for k, t in SECTIONS) + "</nav>"
    sliders, images = section_sliders(sd)
    bodies = {"rules": section_rules(sd), "timings": section_timings(sd),
              "frames": section_frames(sd.frames, _why_skipped(sd, "frames")), "poses": section_poses(sd),
              "labels": section_labels(sd, _why_skipped(sd, "labels")),
              "states": section_states(sd), "methods": section_methods(sd), "verdict": section_verdict(sd),
              "curves": section_curves(sd),
              "grid": section_grid(sd, views), "sliders": sliders, "relevancy": section_relevancy(sd),
              "unseen": section_unseen(sd), "locality": section_locality(sd),
              "commands": section_commands(sd), "export": _section_export(sd), "stability": section_stability(sd),
              "digests": section_digests(sd)}
    body = head + nav + "".join(f'<section id="{k}"><h2>{escape(t)}</h2>{bodies[k]}</section>' for k, t in SECTIONS)
    script = SLIDER_SCRIPT % json.dumps(images) if images else ""
    return page(f"LiveScene report: {sd.scene}", body, script)
