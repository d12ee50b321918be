"""Throughput of the states stage (`livescene states`: key-frame interaction variables interpolated to every
extracted frame) on the demo capture (or ``--capture``'s).

The capture is rendered and its frames extracted once into ``--work`` (child processes, the workflow's
``livescene frames`` defaults); then this process times, ``--repeats`` times each:

- ``compute_states``: the whole stage as the workflow runs it (the capture's key_frame_value.yaml and
  mapping.yaml, pchip): reading, checks, interpolation, leave-one-out scores, states.csv / states.json /
  key_frame_value.yaml written atomically; per extracted frame;
- ``interpolate <method>``: ``interpolate`` alone, every object, per extracted frame and object;
- ``leave_one_out (every method)``: the leave-one-out error the stage scores every method by, every object,
  per key frame and object (its cost grows with the square of the key frames).

Each row: median seconds, units per call, ms per unit, units/s and the 1-minute load average before and after;
above it the CPU pressure before and after, the peak RSS and the machine. The workflow keeps at most 300 frames
(``livescene frames --count 300``), so the stage sees at most that many. A run is in docs/labels-states.md,
"Benchmark (states)"::

    .venv/bin/python benchmarks/states_throughput.py
    .venv/bin/python benchmarks/states_throughput.py --capture config/captures/tiny.yaml --repeats 1  # smoke
"""

from __future__ import annotations

import argparse
import shutil

import numpy as np
import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import (
    Row,
    add_input_arguments,
    capture_folder,
    check_repeats,
    frames_folder,
    print_table,
    timed,
    work_folder,
)

from stages.scene.machine import contention


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_input_arguments(p, repeats=5)
    args = p.parse_args()
    check_repeats(p, args)
    from stages.states import METHODS, StatesConfig, compute_states, interpolate, leave_one_out, read_states_csv

    work = work_folder(args)
    capture = capture_folder(work, args.capture)
    frames = frames_folder(work, args.capture)
    out = work / "states-bench"
    cfg = StatesConfig(key_frames=capture / "key_frame_value.yaml", frames=frames / "frames.csv", out=out,
                       mapping=capture / "mapping.yaml")
    summary = compute_states(cfg)  # untimed: the inputs below come from its output
    n_frames, objects = summary["n_frames"], summary["objects"]
    table = read_states_csv(out / "states.csv")
    # each object's normalised key frames, as the stage interpolates them, and every extracted frame's index
    keys = {o: table[(table.object == o) & table.is_key_frame].sort_values("source_index") for o in objects}
    keys = {o: (k.source_index.to_numpy(np.float64), k.value.to_numpy(np.float64)) for o, k in keys.items()}
    x = np.sort(table.source_index.unique()).astype(np.float64)
    n_keys = sum(len(kx) for kx, _ in keys.values())
    before = contention()
    rows: list[Row] = [timed("compute_states", lambda: compute_states(cfg), args.repeats, n_frames, "frame")]
    for method in METHODS:
        rows.append(timed(f"interpolate {method}", lambda m=method: [interpolate(kx, ky, x, m) for kx, ky in
                                                                      keys.values()],
                          args.repeats, n_frames * len(objects), "frame x object"))
    rows.append(timed("leave_one_out (every method)", lambda: [leave_one_out(kx, ky, m) for kx, ky in keys.values()
                                                               for m in METHODS],
                      args.repeats, n_keys, "key frame x object"))
    shutil.rmtree(out, ignore_errors=True)
    print_table(f"states: {frames} ({n_frames} frames, {len(objects)} objects, {n_keys} key values)", rows, before,
                args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
