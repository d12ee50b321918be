"""What LiveScene's own work costs in a step, against MK-Planes' (issue 16's "<= 0.8x MK-Planes" line).

LiveScene does two things MK-Planes does not: it runs the probability field at the proposal level (the
k-projection of every proposal sample) and, in the default job, trains the language table. This benchmark takes
them out one at a time, in one process, one step of each configuration in turn (the ratio is taken per round, as
``train_throughput.py --paired`` does), and prints each configuration's step time against MK-Planes' with
language. "no proposal probabilities" replaces the probability field's output by zeros wherever it runs without
a gradient (the proposal level; every sample then takes object 0's state): a diagnostic, not a method.

    .venv/bin/python benchmarks/livescene_share.py --steps 80
"""

from __future__ import annotations

import argparse
import resource
import statistics
import tempfile
import time
from contextlib import contextmanager

from train_throughput import add_run_arguments, bench_config, bench_inputs, per_round_ratio, resolve_start_step

from stages.scene.machine import contention, machine_info, machine_line

CONFIGS = {
    # name: (method, language table, proposal-level probability field)
    "LiveScene": ("livescene", True, True),
    "LiveScene, no proposal probabilities": ("livescene", True, False),
    "LiveScene, no language": ("livescene", False, True),
    "LiveScene, neither": ("livescene", False, False),
    "MK-Planes": ("mk-planes", True, True),
}


@contextmanager
def no_proposal_probabilities(active: bool):
    """While active, the probability field returns zeros when it runs without a gradient (the proposal level)."""
    import torch

    from stages.model.fields.probability_field import ProbabilityField

    forward = ProbabilityField.forward

    def zeros(self, positions, states, cache=None):
        if torch.is_grad_enabled():
            return forward(self, positions, states, cache)
        return torch.zeros(positions.shape[0], self.n_objects + 1, device=positions.device)

    if active:
        ProbabilityField.forward = zeros
    try:
        yield
    finally:
        ProbabilityField.forward = forward


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_arguments(p)
    p.add_argument("--steps", type=int, default=80, help="rounds of one step per configuration")
    args = p.parse_args()
    resolve_start_step(args)


    import torch

    from stages.model.trainer import Trainer

    torch.set_num_threads(args.threads)
    dataset, targets = bench_inputs(args)
    trainers, folders = {}, []
    for name, (method, language, _) in CONFIGS.items():
        folders.append(tempfile.TemporaryDirectory())
        trainer = Trainer(bench_config(args, method, language, dataset, targets), folders[-1].name,
                          device=args.device, progress=False)
        trainer.step = args.start_step
        trainers[name] = trainer

    cuda = args.device.startswith("cuda")

    def step(name: str) -> float:
        with no_proposal_probabilities(not CONFIGS[name][2]):
            if cuda:  # a CUDA step only queues its kernels: time the device's work, not the queueing
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            trainers[name].train_step()
            trainers[name].step += 1
            if cuda:
                torch.cuda.synchronize()
            return time.perf_counter() - t0

    for name in CONFIGS:
        for _ in range(args.warmup):
            step(name)
    before = contention()
    times: dict[str, list[float]] = {name: [] for name in CONFIGS}
    for _ in range(args.steps):
        for name in CONFIGS:
            times[name].append(step(name))
    after = contention()
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    for f in folders:
        f.cleanup()
    print(f"\ncapture {args.capture.stem}, {args.device}, {args.threads} threads, preset {args.preset}, {args.steps} "
          f"rounds; before: {before}; after: {after}; peak RSS {peak_mib:.0f} MiB (every configuration)\n"
          f"machine: {machine_line(machine_info(args.device))}\n")
    print("| configuration | step ms (median) | / MK-Planes (median of per-round ratios; 25-75 %) |")
    print("|---|---|---|")
    base = times["MK-Planes"]
    for name, t in times.items():
        median, lo, hi = per_round_ratio(t, base)
        print(f"| {name} | {statistics.median(t) * 1000:.1f} | {median:.2f}x ({lo:.2f}-{hi:.2f}) |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
