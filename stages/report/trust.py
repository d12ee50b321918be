"""Whether a trained run's numbers are results: the trust floors of its config against what it measured.

A run is flagged when it trained fewer steps than ``trust.min_steps`` (undertrained), when its held-out
PSNR, its grounding mIoU (rendered probabilities, object names) or its held-out accumulation over object
pixels is below the floor, or when training did not end with status "completed" (not trustworthy). The
floors come from the run's config.yaml (``trust`` section); a run written before that section existed uses
the defaults of ``stages.model.config.TrustConfig``, so an old run is judged by the same floors as a new one.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stages.scene import InputError


@dataclass
class TrustFlag:
    """The trust verdict on one method's run."""

    method: str
    reasons: list[str] = field(default_factory=list)
    """Why the run is flagged (empty: its numbers can be read as results)."""
    kinds: list[str] = field(default_factory=list)
    """'undertrained' (too few steps) and/or 'not trustworthy' (low scores, unfinished training)."""
    floors: dict[str, float] = field(default_factory=dict)
    """The floors applied: min_steps, min_psnr, min_grounding_miou, min_object_accumulation."""
    floors_from: str = ""
    """Where the floors came from: the run's config.yaml or the TrustConfig defaults."""

    @property
    def flagged(self) -> bool:
        return bool(self.reasons)

    @property
    def label(self) -> str:
        return " and ".join(self.kinds)

    def to_dict(self) -> dict[str, Any]:
        return {"flagged": self.flagged, "label": self.label, "reasons": list(self.reasons),
                "floors": dict(self.floors), "floors_from": self.floors_from}


def default_floors() -> dict[str, float]:
    """TrustConfig's defaults (imported here only: stages.model pulls in torch)."""
    from stages.model.config import TrustConfig

    return dataclasses.asdict(TrustConfig())


def trust_floors(config: dict | None, where: str | Path = "config.yaml") -> tuple[dict[str, float], str]:
    """The run's trust floors and their origin; keys the run's section lacks take the defaults."""
    floors = default_floors()
    section = config.get("trust") if isinstance(config, dict) else None
    if section is None:
        return floors, "TrustConfig defaults (the run's config.yaml has no trust section)"
    if not isinstance(section, dict):
        raise InputError(where, f"trust is {section!r}, not a mapping",
                         "write trust: {min_steps: N, min_psnr: dB, min_grounding_miou: x, "
                         "min_object_accumulation: a}, or delete it")
    for key in floors:
        if key not in section:
            continue
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError(where, f"trust.{key} is {value!r}, not a number",
                             "write a number there, or delete the key to use the default")
        floors[key] = float(value)
    return floors, f"the run's config.yaml ({where})"


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(
        value) else None


def assess_run(method: str, run: dict | None, config: dict | None, metrics: dict | None,
               where: str | Path = "config.yaml") -> TrustFlag:
    """Flag ``method``'s run (run.json, config.yaml, metrics.json as dicts; None where absent)."""
    floors, origin = trust_floors(config, where)
    flag = TrustFlag(method=method, floors=floors, floors_from=origin)
    undertrained, untrusted = [], []
    if run is None:
        untrusted.append("no run.json: training did not finish")
    else:
        status = run.get("status")
        if status != "completed":
            untrusted.append(f"training status {status!r}, not 'completed'" if status is not None
                             else "run.json records no training status")
        steps = _number(run.get("steps"))
        if steps is None:
            undertrained.append("run.json records no step count")
        elif steps < floors["min_steps"]:
            undertrained.append(f"{int(steps):,} steps < trust.min_steps {int(floors['min_steps']):,}")
    if metrics is None:  # no floor on what it measured was checked: not a pass
        untrusted.append("no metrics.json: the run was not evaluated")
    held = ((metrics or {}).get("held_out") or {}).get("psnr") or {}
    psnr = _number(held.get("mean"))
    if psnr is not None and psnr < floors["min_psnr"]:
        untrusted.append(f"held-out PSNR {psnr:.2f} dB < trust.min_psnr {floors['min_psnr']:g} dB")
    grounding = (metrics or {}).get("grounding") or {}
    miou = _number(grounding.get("miou_probs_name")) if grounding.get("status") == "computed" else None
    if miou is not None and miou < floors["min_grounding_miou"]:
        untrusted.append(f"grounding mIoU (probs, names) {miou:.3f} < trust.min_grounding_miou "
                         f"{floors['min_grounding_miou']:g}")
    held_acc = ((metrics or {}).get("held_out") or {}).get("accumulation_objects") or {}
    acc = _number(held_acc.get("mean"))
    if acc is not None and acc < floors["min_object_accumulation"]:
        untrusted.append(f"objects mostly transparent: held-out accumulation over object pixels {acc:.2f} < "
                         f"trust.min_object_accumulation {floors['min_object_accumulation']:g} (their colour comes "
                         "from behind them)")
    flag.reasons = undertrained + untrusted
    flag.kinds = (["undertrained"] if undertrained else []) + (["not trustworthy"] if untrusted else [])
    return flag
