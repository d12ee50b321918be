"""Paired comparison of LiveScene against each baseline on the very same items.

Two methods evaluated on one scene are scored on the same held-out views, the same unseen
(view, state vector) renders and the same (object, view) grounding masks, so the difference per item
removes the item's own difficulty. The mean difference (LiveScene minus baseline) with its 95%
Student-t interval decides the verdict: "LiveScene ahead" or "LiveScene behind" only when the
interval excludes 0, else "no measurable difference". Items present for one method only are left out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from stages.evaluate.metrics import summarize

LIVESCENE = "livescene"

Items = dict[tuple, float]


def _finite(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if value == value and abs(value) != float("inf") else None


def held_out_items(metrics: dict | None, key: str = "psnr") -> Items:
    """Held-out PSNR per view, keyed by frame id; ``key`` "psnr_objects" / "psnr_static" takes the PSNR over
    object pixels / the other pixels (evaluations before EVALUATE_VERSION 3 have neither: no items),
    "psnr_nominal" the PSNR at the nominal exposure (runs trained on measured gains only)."""
    out: Items = {}
    for v in ((metrics or {}).get("held_out") or {}).get("views") or []:
        value = _finite(v.get(key))
        if value is not None:
            out[(str(v.get("frame")),)] = value
    return out


def unseen_items(metrics: dict | None) -> Items:
    """Unseen-combination PSNR per rendered (frame, state vector) record; non-novel records are not scored."""
    out: Items = {}
    unseen = (metrics or {}).get("unseen_combinations") or {}
    for r in unseen.get("records") or []:
        value = _finite(r.get("psnr"))
        if not r.get("unseen") or value is None or not isinstance(r.get("states"), dict):
            continue
        # the state vector, not the combination index: the index depends on each run's list of combinations
        states = tuple(sorted((str(k), round(float(v), 6)) for k, v in r["states"].items()))
        out[(str(r.get("frame")), states)] = value
    return out


def grounding_items(metrics: dict | None, source: str = "probs") -> Items:
    """Grounding IoU per (object, view) of one relevancy source: the mean over the object's queries.

    An object's name and its synonyms are scored on the same view's mask, and a synonym the encoder maps
    to the same object gives (nearly) the same map: counted as items of their own they would repeat one
    measurement and narrow the interval without evidence. Evaluations since EVALUATE_VERSION 2 name the
    frame of each per-view IoU. Older ones list the IoUs in held-out view order (views where the object is
    out of sight left out); those are keyed by position and only pair with an evaluation of the same views
    (see ``compare``).
    """
    per_item: dict[tuple, list[float]] = {}
    grounding = (metrics or {}).get("grounding") or {}
    if grounding.get("status") != "computed":
        return {}
    for q in grounding.get("queries") or []:
        entry = q.get(source) or {}
        ious = entry.get("per_view") or []
        frames = entry.get("frames")
        keys = [str(f) for f in frames] if isinstance(frames, list) and len(frames) == len(ious) \
            else [f"#{i}" for i in range(len(ious))]
        target = str(q.get("object") or q.get("query"))
        for key, value in zip(keys, ious, strict=True):
            value = _finite(value)
            if value is not None:
                per_item.setdefault((target, key), []).append(value)
    return {item: sum(values) / len(values) for item, values in per_item.items()}


def locality_items(metrics: dict | None) -> Items:
    """Mean change outside the object's swept region (x255) per (view, object) of the locality test."""
    out: Items = {}
    locality = (metrics or {}).get("locality") or {}
    if locality.get("status") != "computed":
        return out
    for r in locality.get("records") or []:
        value = _finite(r.get("model_outside_x255"))
        if value is not None:
            out[(str(r.get("frame")), str(r.get("object")))] = value
    return out


@dataclass
class MetricSpec:
    """One paired metric: what it is called, its unit and how to read its items from metrics.json."""

    key: str
    label: str
    unit: str
    items: Callable[[dict | None], Items]
    higher_is_better: bool = True
    only_when_present: bool = False
    """Left out of the comparison when neither method has items (a metric only some evaluations compute)."""


METRICS = [
    MetricSpec("held_out_psnr", "held-out PSNR per view", "dB", held_out_items),
    # where the held-out difference lies: in what the states drive, or in what they should leave alone
    MetricSpec("held_out_psnr_objects", "held-out PSNR per view, object pixels", "dB",
               lambda m: held_out_items(m, "psnr_objects")),
    MetricSpec("held_out_psnr_static", "held-out PSNR per view, static pixels (no object)", "dB",
               lambda m: held_out_items(m, "psnr_static")),
    # runs trained on measured exposure gains: the held-out images at the nominal exposure the renders show
    MetricSpec("held_out_psnr_nominal", "held-out PSNR per view at the nominal exposure (images divided by their "
               "measured gains)", "dB", lambda m: held_out_items(m, "psnr_nominal"), only_when_present=True),
    MetricSpec("unseen_psnr", "unseen-combination PSNR per (view, state vector)", "dB", unseen_items),
    MetricSpec("grounding_iou", "grounding IoU (probs) per (object, view), its queries averaged", "",
               grounding_items),
    MetricSpec("locality_outside", "change outside the moved object's swept region per (view, object), lower "
               "is better", "/255", locality_items, higher_is_better=False),
]


@dataclass
class PairedResult:
    """LiveScene minus one baseline on one metric."""

    baseline: str
    metric: str
    label: str
    unit: str
    n: int
    mean: float | None
    ci95: list[float] | None
    verdict: str
    flagged: dict[str, str] = field(default_factory=dict)
    """Methods of this comparison whose runs are flagged, with the flag's label (e.g. 'undertrained')."""
    note: str = ""

    @property
    def statement(self) -> str:
        """The verdict as a sentence that says when it rests on a flagged run."""
        if not self.flagged:
            return self.verdict
        runs = ", ".join(f"{name} ({label})" for name, label in self.flagged.items())
        return f"{self.verdict}, but it rests on a flagged run: {runs}"

    def to_dict(self) -> dict[str, Any]:
        return {"livescene": LIVESCENE, "baseline": self.baseline, "metric": self.metric, "n": self.n,
                "mean_difference": self.mean, "ci95": self.ci95, "verdict": self.verdict,
                "rests_on_flagged_run": list(self.flagged), "statement": self.statement, "note": self.note}


def verdict(n: int, ci95: list[float] | None, higher_is_better: bool = True) -> str:
    """Ahead / behind only when the 95% interval of the mean difference excludes 0."""
    if n == 0:
        return "no paired items"
    above, below = ("LiveScene ahead", "LiveScene behind") if higher_is_better else ("LiveScene behind",
                                                                                    "LiveScene ahead")
    if ci95 is not None and ci95[0] > 0:
        return above
    if ci95 is not None and ci95[1] < 0:
        return below
    return f"no measurable difference (n={n})"


def paired_difference(ours: Items, theirs: Items) -> tuple[int, float | None, list[float] | None]:
    """n, mean and 95% CI of ``ours[k] - theirs[k]`` over the keys both have."""
    diffs = [ours[k] - theirs[k] for k in sorted(ours.keys() & theirs.keys(), key=repr)]
    s = summarize(diffs)
    return int(s["n"]), s["mean"], s["ci95"]


def _same_views(a: dict | None, b: dict | None) -> bool:
    views = [[v.get("frame") for v in ((m or {}).get("held_out") or {}).get("views") or []] for m in (a, b)]
    return bool(views[0]) and views[0] == views[1]


def compare(metrics: dict[str, dict | None], flags: dict[str, str]) -> list[PairedResult]:
    """Every paired metric of LiveScene against every other method with metrics (method order kept).

    ``flags`` maps a method to its trust flag's label ('' or absent when its run is not flagged).
    """
    ours = metrics.get(LIVESCENE)
    if ours is None:
        return []
    out = []
    for baseline, theirs in metrics.items():
        if baseline == LIVESCENE or theirs is None:
            continue
        on_flagged = {m: flags[m] for m in (LIVESCENE, baseline) if flags.get(m)}
        for spec in METRICS:
            a, b = spec.items(ours), spec.items(theirs)
            if spec.only_when_present and not a and not b:
                continue
            note = ""
            positional = any(k[-1].startswith("#") for k in (*a, *b)) if spec.key == "grounding_iou" else False
            if positional and not _same_views(ours, theirs):
                # per-view IoUs without frame ids pair up only when both evaluations used the same views
                a, b, note = {}, {}, "older evaluation without frame ids per grounding IoU, on other views"
            n, mean, ci = paired_difference(a, b)
            out.append(PairedResult(baseline=baseline, metric=spec.key, label=spec.label, unit=spec.unit, n=n,
                                    mean=mean, ci95=ci, verdict=verdict(n, ci, spec.higher_is_better),
                                    flagged=on_flagged, note=note))
    return out
