"""benchmarks/plane_gradient.py in a smoke run: every way of writing the planes' gradient gives grid_sample's."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_variant_gives_grid_samples_gradient():
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "plane_gradient.py"), "--device", "cpu",
                          "--samples-scale", "0.0005", "--repeats", "1", "--k-values", "8",
                          "--variants", "grid_sample", "index_add", "nchw", "replicas:3"],
                         check=True, capture_output=True, text=True, cwd=ROOT).stdout
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert len(lines) == 5 * 4  # every stack, every variant
    assert {line["variant"] for line in lines} == {"grid_sample", "index_add", "nchw", "replicas:3"}
    for line in lines:
        assert line["ms"] > 0 and line["load"] >= 0
        assert line["grad_max_rel_diff"] <= 1e-5, line
