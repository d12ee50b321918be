"""Training throughput of every method on the demo capture (or ``--capture``), with and without the language table
(issue 16).

For each method and language setting, a fresh subprocess builds the shared ``Trainer`` on the capture's truth
dataset (generated once into ``--work``) and runs real training steps (ray batch, every level, every
loss term, backward, finite checks, Adam). It prints one JSON line per configuration and a table:

- ``step_ms``: median wall time of one step (CUDA: synchronised around each step), timed from step
  ``--start-step`` on (default: 100 steps after the preset's proposal warm-up, 300 for cpu-demo and 5100 for
  gpu-paper) so the proposal schedule is that of a typical step;
- ``rays_per_s``: batch rays / median step time; ``mean_step_ms`` and ``mean_rays_per_s`` (JSON lines only): the
  mean over the timed steps, the rate a run trains at when ``--steps`` covers whole cycles of the schedule (the
  proposal nets take a gradient every ``update_every``-th step, and the median is the step without);
- ``ops``: aten ops dispatched by one step, forward and backward;
- ``syncs``: host-device synchronisations of one step that is not a logging step
  (``.item()``, ``bool(t)``, ``float(t)``, ``.tolist()``, ...);
- ``peak_mib``: CUDA max_memory_allocated, or the subprocess's max RSS on the CPU;
- ``load``: the 1-minute load average before and after (figures on a busy machine are pessimistic).

CPU (the default: cpu-demo, 2 threads)::

    .venv/bin/python benchmarks/train_throughput.py

Ratios between methods on a machine whose speed drifts (``--paired``: every configuration in one process,
one step of each in turn; the ratio is taken per round)::

    .venv/bin/python benchmarks/train_throughput.py --paired --steps 100

More objects (MK-Planes' planes grow as C(3 + alpha, 2), LiveScene's stay at 6)::

    .venv/bin/python benchmarks/train_throughput.py --paired --capture config/captures/kitchen.yaml

CUDA, paper settings::

    .venv/bin/python benchmarks/train_throughput.py --preset gpu-paper --device cuda --rays 4096
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from demo_dataset import DEMO_SPEC, ROOT, cached_demo_dataset

from stages.scene.machine import contention, machine_info, machine_line

METHODS = ["livescene", "mk-planes", "conerf"]


def language_targets(work: Path, dataset: Path) -> Path:
    out = work / "targets.npz"
    if not out.is_file():
        env = dict(os.environ, HF_HUB_OFFLINE="1")
        subprocess.run([sys.executable, "-m", "stages.language", "targets", "--data", str(dataset), "--out",
                        str(out)], check=True, env=env, cwd=ROOT, stdout=subprocess.DEVNULL)
    return out


LANGUAGE_SETTINGS = {"both": [False, True], "on": [True], "off": [False]}
"""--language -> the language settings measured per method."""


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """The options that build a measured trainer, shared with ``profile_step.py``."""
    p.add_argument("--preset", default="cpu-demo")
    p.add_argument("--device", default="cpu")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--rays", type=int, default=0, help="rays per step (default: the preset's)")
    p.add_argument("--warmup", type=int, default=10)
    p.add_argument("--start-step", type=int, default=None,
                   help="step counter the timed steps start from (default: 100 after the preset's proposal warm-up, "
                        "from which the proposal fields get gradients every 5th step: 300 for cpu-demo, 5100 for "
                        "gpu-paper; the GPU tables of 27-28 Nov in docs/model.md were timed from 300)")
    p.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    p.add_argument("--capture", type=Path, default=DEMO_SPEC,
                   help="capture spec to train on (default: the demo's); e.g. config/captures/kitchen.yaml for four "
                        "objects, where MK-Planes has 21 planes per scale")
    p.add_argument("--work", type=Path, default=None,
                   help="where the capture and its dataset are cached (default: a temp folder named after the spec)")


def resolve_start_step(args: argparse.Namespace) -> None:
    """``--start-step`` by default: 100 steps into the preset's schedule after its proposal warm-up."""
    if args.start_step is None:
        from stages.model import load_config

        args.start_step = load_config(args.preset, args.overrides).model.sampling.update_warmup + 100


def bench_inputs(args: argparse.Namespace) -> tuple[Path, Path]:
    """(truth dataset, language targets) of ``--capture``, made once in ``--work``."""
    if args.work is None:
        args.work = Path(tempfile.gettempdir()) / f"livescene-bench-{args.capture.stem}"
    args.work.mkdir(parents=True, exist_ok=True)
    _, dataset = cached_demo_dataset(args.work, spec=args.capture)
    return dataset, language_targets(args.work, dataset)


def bench_config(args: argparse.Namespace, method: str, with_language: bool, dataset: Path, targets: Path):
    """The run config of one measured configuration: the preset, no evaluation or checkpoints, enough steps."""
    from stages.model import load_config

    overrides = [f"train.threads={args.threads}", "train.eval_every=0", "train.checkpoint_every=0",
                 f"train.max_steps={args.start_step + args.warmup + args.steps + 10}", *args.overrides]
    if args.rays:
        overrides.append(f"train.batch_rays={args.rays}")
    return load_config(args.preset, overrides, method=method, data=str(dataset),
                       language_targets=str(targets) if with_language else "")


def per_round_ratio(a: list[float], b: list[float]) -> tuple[float, float, float]:
    """Median, 25th and 75th percentile of ``a[i] / b[i]``: step times taken in the same round, so the machine's
    drift between rounds cancels."""
    import statistics

    per_round = sorted(x / y for x, y in zip(a, b, strict=True))
    lo, hi = (per_round[min(int(f * len(per_round)), len(per_round) - 1)] for f in (0.25, 0.75))
    return statistics.median(per_round), lo, hi


def print_ratios(ratio) -> None:
    """The issue's two step-time ratios; ``ratio(a, b)`` formats a / b of two (method, language) keys, or None."""
    pairs = [("language tax (LiveScene on / off)", ("livescene", True), ("livescene", False))]
    pairs += [(f"LiveScene with language / {base} without", ("livescene", True), (base, False))
              for base in ("mk-planes", "conerf")]
    print()
    for label, a, b in pairs:
        text = ratio(a, b)
        if text is not None:
            print(f"{label}: {text}")


def measure_one(args: argparse.Namespace) -> dict:
    """Runs in the child process: one method, one language setting."""
    import torch

    from stages.model.step_counters import count_host_syncs, count_torch_ops
    from stages.model.trainer import Trainer

    cfg = bench_config(args, args.method, args.language, args.dataset, args.targets)
    with tempfile.TemporaryDirectory() as out:
        trainer = Trainer(cfg, out, device=args.device, progress=False)
        device = trainer.device
        cuda = device.type == "cuda"

        trainer.step = args.start_step  # the schedule (proposal updates) of a typical step, not of the first ones

        def step() -> None:
            trainer.train_step()
            trainer.step += 1

        for _ in range(args.warmup):
            step()
        if cuda:
            torch.cuda.synchronize(device)
            torch.cuda.reset_peak_memory_stats(device)
        times = []
        for _ in range(args.steps):
            t0 = time.perf_counter()
            step()
            if cuda:
                torch.cuda.synchronize(device)
            times.append(time.perf_counter() - t0)
        with count_host_syncs(device) as syncs:
            step()
        ops = None  # a dispatch mode would make compiled fields recompile (fullgraph: fail); it sees eager ops only
        if not cfg.train.compile:
            with count_torch_ops() as ops:
                step()
    step_s = sorted(times)[len(times) // 2]
    reserved = None
    if cuda:
        peak, kind = torch.cuda.max_memory_allocated(device) / 2**20, "cuda max_memory_allocated"
        # what the caching allocator holds, CUDA graphs' private pools included (their replays allocate nothing)
        reserved = round(torch.cuda.max_memory_reserved(device) / 2**20, 1)
    else:
        peak, kind = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, "process max RSS"
    return {
        "method": args.method, "language": args.language, "preset": args.preset, "device": str(device),
        "threads": torch.get_num_threads(), "rays": cfg.train.batch_rays,
        "step_ms": round(step_s * 1000, 1), "rays_per_s": round(cfg.train.batch_rays / step_s),
        # the mean over whole cycles of the proposal schedule: after its warm-up, most steps skip proposal gradients
        "mean_step_ms": round(sum(times) / len(times) * 1000, 1),
        "mean_rays_per_s": round(cfg.train.batch_rays * len(times) / sum(times)),
        "ops": None if ops is None else int(sum(ops.values())), "syncs": int(sum(syncs.values())),
        "sync_calls": dict(syncs),
        "peak_mib": round(peak, 1), "peak_kind": kind, "reserved_mib": reserved,
        "machine": machine_line(machine_info(str(device))),
    }


def measure_paired(args: argparse.Namespace, dataset: Path, targets: Path) -> int:
    """Every configuration in one process, one step of each in turn: ratios immune to the machine's drift."""
    import statistics

    import torch

    from stages.model.trainer import Trainer

    configs = list(itertools.product(args.methods, LANGUAGE_SETTINGS[args.language]))
    trainers, folders = {}, []
    for method, lang in configs:
        folders.append(tempfile.TemporaryDirectory())
        trainer = Trainer(bench_config(args, method, lang, dataset, targets), folders[-1].name, device=args.device,
                          progress=False)
        trainer.step = args.start_step
        trainers[(method, lang)] = trainer
    cuda = args.device.startswith("cuda")

    def step(trainer: Trainer) -> float:
        t0 = time.perf_counter()
        trainer.train_step()
        trainer.step += 1
        if cuda:
            torch.cuda.synchronize()
        return time.perf_counter() - t0

    for trainer in trainers.values():
        for _ in range(args.warmup):
            step(trainer)
    before = contention()
    times: dict[tuple[str, bool], list[float]] = {c: [] for c in configs}
    for _ in range(args.steps):
        for c in configs:
            times[c].append(step(trainers[c]))
    after = contention()
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # every configuration in one process
    for f in folders:
        f.cleanup()
    print(f"\npaired: capture {args.capture.stem}, {args.device}, {torch.get_num_threads()} threads, preset "
          f"{args.preset}, {args.steps} rounds of one step per configuration; before: {before}; after: {after}; "
          f"peak RSS {peak_mib:.0f} MiB (all configurations)"
          + (f", CUDA peak {torch.cuda.max_memory_allocated() / 2**20:.0f} MiB" if cuda else "") + "\n"
          f"machine: {machine_line(machine_info(args.device))}\n")
    print("| method | language | step ms (median) | rays/s |")
    print("|---|---|---|---|")
    rays = next(iter(trainers.values())).config.train.batch_rays
    for (method, lang), t in times.items():
        ms = statistics.median(t) * 1000
        print(f"| {method} | {'on' if lang else 'off'} | {ms:.1f} | {rays / ms * 1000:.0f} |")

    def ratio(a: tuple[str, bool], b: tuple[str, bool]) -> str | None:
        if a not in times or b not in times:
            return None
        median, lo, hi = per_round_ratio(times[a], times[b])
        return f"{median:.2f}x (median of per-round ratios; 25-75 %: {lo:.2f}-{hi:.2f})"

    print_ratios(ratio)
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_arguments(p)
    p.add_argument("--methods", nargs="+", default=METHODS)
    p.add_argument("--steps", type=int, default=60, help="timed steps (the median is reported)")
    p.add_argument("--rounds", type=int, default=2, help="passes over every configuration (the fastest is kept; "
                   "not with --paired, which times --steps rounds of one step each)")
    p.add_argument("--language", choices=["both", "on", "off"], default="both")
    p.add_argument("--paired", action="store_true",
                   help="one process, one step of each configuration in turn (step time ratios that the machine's "
                        "drift does not move; no ops, syncs or peak memory columns)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--method", help=argparse.SUPPRESS)
    p.add_argument("--dataset", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--targets", type=Path, help=argparse.SUPPRESS)
    p.add_argument("--with-language", dest="with_language", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    for flag in ("steps", "rounds", "warmup"):
        if getattr(args, flag) < (0 if flag == "warmup" else 1):
            p.error(f"--{flag} must be at least {0 if flag == 'warmup' else 1}, got {getattr(args, flag)}")
    resolve_start_step(args)
    if args.child:
        args.language = args.with_language
        print(json.dumps(measure_one(args)), flush=True)
        return 0
    dataset, targets = bench_inputs(args)
    if args.paired:
        return measure_paired(args, dataset, targets)
    settings = LANGUAGE_SETTINGS[args.language]
    rows: dict[tuple[str, bool], dict] = {}
    # rounds over every configuration in turn: a burst of load on a shared machine hits one round, and the
    # fastest round's median is kept for each configuration
    for _round, method, lang in itertools.product(range(args.rounds), args.methods, settings):
        load0 = os.getloadavg()[0]
        cmd = [sys.executable, __file__, "--child", "--method", method, "--dataset", str(dataset), "--targets",
               str(targets), "--preset", args.preset, "--device", args.device, "--threads", str(args.threads),
               "--rays", str(args.rays), "--steps", str(args.steps), "--warmup", str(args.warmup),
               "--start-step", str(args.start_step)]
        cmd += ["--with-language"] if lang else []
        for o in args.overrides:
            cmd += ["--set", o]
        done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
        if done.returncode != 0:
            sys.stderr.write(done.stderr)
            raise SystemExit(f"{method} (language {'on' if lang else 'off'}) failed with exit status "
                             f"{done.returncode}: its error is above")
        out = done.stdout
        row = json.loads(out.strip().splitlines()[-1])
        row["load_before_after"] = [round(load0, 2), round(os.getloadavg()[0], 2)]
        print(json.dumps(row), flush=True)
        if (method, lang) not in rows or row["step_ms"] < rows[(method, lang)]["step_ms"]:
            rows[(method, lang)] = row
    rows = list(rows.values())
    head = rows[0]
    print(f"\ncapture {args.capture.stem}, {head['device']}, {head['threads']} threads, {head['rays']} rays per step, "
          f"preset {args.preset}\nmachine: {head['machine']}\n")
    print("| method | language | step ms | rays/s | ops/step | host syncs/step | peak MiB | load |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        lang = "on" if r["language"] else "off"
        load = "-".join(str(v) for v in r["load_before_after"])
        print(f"| {r['method']} | {lang} | {r['step_ms']} | {r['rays_per_s']} | {r['ops']} | {r['syncs']} | "
              f"{r['peak_mib']} | {load} |")
    by = {(r["method"], r["language"]): r["step_ms"] for r in rows}
    print_ratios(lambda a, b: f"{by[a] / by[b]:.2f}x" if a in by and b in by else None)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
