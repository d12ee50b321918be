"""The scene page's "Object masks" section: annotated and propagated frames, confidence, leave-one-out IoU.

Reads the labels folder the report inputs name (labels.json, and when masks were propagated from key frames
propagation.json and confidence.csv; docs/labels-states.md, "Masks on key frames only").
"""

from __future__ import annotations

from html import escape

from stages.labels.mask_checks import warning_line

from .html_parts import fmt, missing, note_list, table
from .scene_data import SceneData, csv_number, read_csv_rows, read_json
from .svg_plot import Series, line_plot_svg


def _confidence_plot(rows: list[dict[str, str]], objects: list[str]) -> str:
    x = [float(i) for i in range(len(rows))]
    series = [Series("all pixels", x, [csv_number(r.get("mean_confidence")) or float("nan") for r in rows])]
    for name in objects:
        ys = [csv_number(r.get(f"confidence_{name}")) for r in rows]
        series.append(Series(name, x, [float("nan") if v is None else v for v in ys]))
    return line_plot_svg(series, x_label="frame (position in frames.csv; annotated frames at 1)",
                         y_label="mean pixel confidence", title="Confidence of the propagated masks")


def _loo_table(loo: dict, objects: list[str]) -> str:
    frames = loo.get("frames") or []
    if not frames:
        return missing(f"No leave-one-out estimate: {loo.get('skipped', 'no annotated frame could be held out')}.")
    rows = [[escape(r["frame"]), escape(r.get("previous_key") or "–"), escape(r.get("next_key") or "–"),
             r.get("distance"), *[r["iou"].get(n) for n in objects], r.get("mean_iou")] for r in frames]
    means = loo.get("mean_iou") or {}
    rows.append(["<b>mean</b>", "", "", None, *[means.get(n) for n in objects], loo.get("mean_iou_all")])
    worst = min((r for r in frames if r.get("mean_iou") is not None), key=lambda r: r["mean_iou"], default=None)
    note = ""
    if worst is not None:
        note = (f"<p class=\"note\">Weakest held-out frame: {escape(worst['frame'])} (mean IoU "
                f"{fmt(worst['mean_iou'])}); annotating a frame near it helps most.</p>")
    rule = str(loo.get("rule", ""))
    return (f"<p>{escape(rule[:1].upper() + rule[1:])}.</p>"
            + table(["held-out frame", "from", "and", "frames away", *[f"IoU {n}" for n in objects], "mean IoU"], rows)
            + note)


def section_labels(sd: SceneData, skipped: str = "the labels rule did not run for this scene") -> str:
    """HTML of the section; ``skipped`` says why when the labels folder (labels.json) is absent."""
    labels = sd.labels
    folder = sd.inputs.labels
    if labels is None or folder is None:
        return missing(skipped)
    objects = [str(o) for o in labels.get("objects", [])]
    n_frames, n_labelled = labels.get("n_frames", 0), labels.get("n_labelled", 0)
    head = (f"<p>{n_labelled} of {n_frames} frames annotated ({escape(str(labels.get('format', '?')))}, objects "
            f"{escape(', '.join(objects))}); {len(labels.get('unreliable_frames') or {})} frames with an object under "
            f"H*W/300 pixels and a quarter of its median size (their mask loss is skipped).</p>")
    warnings = labels.get("mask_warnings") or []
    if warnings:  # docs/labels-states.md, "Tracker failures"
        items = [escape(warning_line(w)) for w in warnings[:20]]
        more = [f"... and {len(warnings) - 20} more (labels.json, mask_warnings)"] if len(warnings) > 20 else []
        head += note_list(f"{len(warnings)} warning(s) about the masks, the marks of a tracker's failure (check these "
                          "frames; the stage used the masks as given):", items + more)
    report = read_json(folder / "propagation.json")
    if report is None:
        without = labels.get("frames_without_masks") or []
        if without:
            return head + missing(f"{len(without)} frames have no mask and were not propagated "
                                  "(--missing-masks leave): the mask loss skips them.")
        return head + "<p>Every frame is annotated: nothing was propagated.</p>"
    rows = read_csv_rows(folder / "confidence.csv")
    loo = report.get("leave_one_out") or {}
    by_distance = report.get("confidence_by_distance") or {}
    timings = report.get("timings") or {}
    html = head + (f"<p>{report.get('propagated_frames')} frames propagated from the "
                   f"{len(report.get('annotated_frames', []))} annotated ones: {escape(report.get('method', ''))}. "
                   f"Mean pixel confidence {fmt(report.get('mean_confidence'))}; "
                   f"{fmt(timings.get('total_s'), 1)} s ({fmt(timings.get('per_frame_ms'), 0)} ms per frame).</p>")
    html += "<h3>Leave-one-out IoU</h3>" + _loo_table(loo, objects)
    html += "<h3>Confidence</h3>"
    html += table(["frames from the nearest annotation", "mean pixel confidence"],
                  [[int(d), v] for d, v in sorted(by_distance.items(), key=lambda kv: int(kv[0]))])
    html += _confidence_plot(rows, objects) if rows else missing("confidence.csv is missing from the labels output.")
    html += (f"<p class=\"note\">{escape(report.get('confidence', ''))}. Occlusion check: "
             f"{escape(report.get('occlusion_check', ''))}.</p>")
    return html
