"""Training throughput of a method and preset: rays/s, step time, parameter count, peak memory (issue 6, item 6).

Builds the model for ``--objects`` interactive objects and times full training steps (every level's forward,
every loss term, backward, Adam) on random rays through the [-1, 1]^3 box with random colours, states and mask
labels, so no dataset is needed. Prints one JSON line per configuration. On a CUDA machine run it at the
paper's batch::

    .venv/bin/python benchmarks/model_throughput.py --preset gpu-paper --device cuda --objects 2 4 8 \
        --rays 4096 --precision auto

CPU figures on the shared development machine are pessimistic (other jobs run at the same time).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time

import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)
import torch

from stages.model import build_model, load_config
from stages.model.methods import SceneInfo
from stages.model.ray_dataset import RayBatch
from stages.model.rays import RayBundle
from stages.model.scene_normalization import aabb_near_far
from stages.model.trainer import autocast_dtype
from stages.scene.machine import machine_info, machine_line


def random_batch(n: int, alpha: int, device: torch.device, gen: torch.Generator) -> RayBatch:
    """Rays from points inside the box towards random directions, with random supervision."""
    origins = (torch.rand(n, 3, generator=gen) * 1.6 - 0.8).to(device)
    dirs = torch.nn.functional.normalize(torch.randn(n, 3, generator=gen), dim=-1).to(device)
    nears, fars = aabb_near_far(origins, dirs, 0.05)
    states = torch.rand(n, alpha, generator=gen).to(device)
    times = torch.rand(n, generator=gen).to(device)
    rgb = torch.rand(n, 3, generator=gen).to(device)
    labels = torch.randint(0, alpha + 1, (n,), generator=gen).to(device)
    return RayBatch(RayBundle(origins, dirs, nears, fars, states, times), rgb, labels,
                    torch.zeros(n, dtype=torch.long, device=device))


def measure(method: str, preset: str, alpha: int, rays: int, steps: int, warmup: int, device: torch.device,
            precision: str, overrides: list[str]) -> dict:
    cfg = load_config(preset, overrides, method=method)
    info = SceneInfo(objects=[f"object{i}" for i in range(alpha)], n_frames=100,
                     key_times=[0.0, 1.0], key_states=[[0.0] * alpha, [1.0] * alpha])
    model = build_model(method, cfg.model, info).to(device).train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3, eps=1e-15)
    amp = autocast_dtype(precision, device)
    scaler = torch.amp.GradScaler(device.type) if amp == torch.float16 else None
    gen = torch.Generator().manual_seed(0)
    jitter = torch.Generator(device=device).manual_seed(1)
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    times = []
    for i in range(warmup + steps):
        batch = random_batch(rays, alpha, device, gen)
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        with torch.autocast(device_type=device.type, dtype=amp or torch.float32, enabled=amp is not None):
            out = model(batch.rays, step=i, generator=jitter)
            loss = sum(model.loss_dict(out, batch, i).values())
        opt.zero_grad(set_to_none=True)
        if scaler is not None:
            scaler.scale(loss).backward()
            scaler.step(opt)
            scaler.update()
        else:
            loss.backward()
            opt.step()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        if i >= warmup:
            times.append(time.perf_counter() - t0)
    step_s = sorted(times)[len(times) // 2]
    if device.type == "cuda":
        peak = torch.cuda.max_memory_allocated(device) / 2**20
        kind = "cuda max_memory_allocated"
        name = torch.cuda.get_device_name(device)
    else:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        kind = "process max RSS (whole process, includes earlier configurations)"
        name = f"{platform.processor() or platform.machine()}, {torch.get_num_threads()} threads"
    s = cfg.model.sampling
    return {
        "method": method, "preset": preset, "objects": alpha, "rays": rays,
        "samples": [*s.num_proposal_samples, s.num_samples], "device": name,
        "precision": str(amp).replace("torch.", "") if amp else "float32",
        "params": int(sum(p.numel() for p in model.parameters())),
        "step_ms_median": round(step_s * 1000, 1), "rays_per_s": round(rays / step_s, 1),
        "peak_memory_mib": round(peak, 1), "peak_memory_kind": kind,
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--method", default="livescene")
    p.add_argument("--preset", default="cpu-demo")
    p.add_argument("--objects", type=int, nargs="+", default=[2])
    p.add_argument("--rays", type=int, help="rays per step (default: the preset's train.batch_rays)")
    p.add_argument("--steps", type=int, default=10, help="timed steps (median reported)")
    p.add_argument("--warmup", type=int, default=3, help="untimed steps first")
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--precision", default="auto", help="auto | bf16 | fp16 | off")
    p.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    rays = args.rays or load_config(args.preset, args.overrides).train.batch_rays
    for alpha in args.objects:
        load0 = os.getloadavg()[0]
        row = measure(args.method, args.preset, alpha, rays, args.steps, args.warmup, device, args.precision,
                      args.overrides)
        print(json.dumps({**row, "load_before_after": [round(load0, 2), round(os.getloadavg()[0], 2)]}), flush=True)
    print(f"machine: {machine_line(machine_info(args.device))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
