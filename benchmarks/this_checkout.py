"""Benchmarks run this checkout's code: every benchmark script imports this module before ``stages``.

The venv's editable install points at whichever checkout installed it. A benchmark started in another
worktree (the "before" of a before/after comparison) must run that worktree's ``stages``, in its own
process and in every ``livescene`` or ``python`` subprocess it starts, so this checkout goes first on
``sys.path`` and on ``PYTHONPATH`` (which subprocesses inherit and which comes before the editable install).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# as `livescene` and the workflow do (docs/model.md, "OpenMP wait policy"): before torch loads, or spinning threads
# of a busy machine make one configuration's step 2-5x slower from run to run; recorded by machine_info
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
_paths = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
if str(ROOT) not in _paths:
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), *_paths])
