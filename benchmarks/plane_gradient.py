"""What the planes' gradient costs, and which way of writing it is cheapest (issue 16).

With the training step replayed as CUDA graphs, ``grid_sampler_2d_backward`` is 41 % of a gpu-paper step on
an H200 (docs/model.md, "Whole-step CUDA graphs"): every sample adds its gradient into four vertices of each
plane by atomic adds, and many samples share the vertices of a small plane (a k-plane has 32 rows along k, and
a batch's rays show few distinct states). Here one plane stack of gpu-paper's shapes is sampled as the fields
sample it (border padding, aligned corners) and its forward and backward are timed, the gradient written by:

- ``grid_sample``: grid_sample's own backward, the stack channels-last as the fields store it;
- ``nchw``: the same with the stack contiguous (channels first);
- ``index_add``: grid_sample's forward, the gradient by one ``index_add_`` per cell vertex into the stack's
  channels-last rows (consecutive threads take consecutive channels of one sample: distinct addresses);
- ``replicas:R``: the stack expanded to R copies, the samples split into R runs, each run sampling its own
  copy; autograd sums the copies' gradients, so R times fewer samples meet on one vertex.

All give the same gradient up to the order of the additions (``grad_max_rel_diff`` against the first).
Measured on two H200s (docs/model.md, "The planes' gradient, measured"): none is cheaper on every stack, and
in the whole replayed training step grid_sample's own backward stays the fastest.
``--k-values K`` gives the k axis (the second coordinate of the non-spatial stacks) K distinct values, as a
batch of rays from K frames does (0: uniform). It prints one JSON line per configuration: median ms of
forward + backward (CUDA: synchronised), samples per second, peak memory and the 1-minute load::

    python3 benchmarks/plane_gradient.py --device cuda
    .venv/bin/python benchmarks/plane_gradient.py --device cpu --samples-scale 0.05   # a smoke run
"""

from __future__ import annotations

import argparse
import json
import os
import time

import this_checkout  # noqa: F401  (this checkout's stages)
import torch
import torch.nn.functional as F

from stages.model.encodings import axis_cells

# gpu-paper, LiveScene (stages/model/presets/gpu-paper.yaml): (name, planes, channels, H, W, samples, k-plane)
STACKS = [
    ("field x4 spatial", 3, 32, 512, 512, 4096 * 48, False),
    ("field x4 k-planes", 3, 32, 32, 512, 4096 * 48, True),
    ("field x1 k-planes", 3, 32, 32, 128, 4096 * 48, True),
    ("proposal 0 k-planes", 3, 8, 32, 64, 4096 * 256, True),
    ("proposal 1 k-planes", 3, 8, 32, 128, 4096 * 128, True),
]


OPTIONS = {"mode": "bilinear", "padding_mode": "border", "align_corners": True}


class IndexAddSample(torch.autograd.Function):
    """grid_sample's forward; the stack's gradient [G, C, H, W] by ``index_add_`` into channels-last rows, at
    grid_sample's cells and weights (``axis_cells``). Measured in a whole training step and not adopted
    (docs/model.md, "Whole-step CUDA graphs")."""

    @staticmethod
    def forward(ctx, stack: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(stack, grid)
        return F.grid_sample(stack, grid, **OPTIONS)

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor) -> tuple[torch.Tensor, None]:  # type: ignore[override]
        stack, grid = ctx.saved_tensors
        n_planes, channels, height, width = stack.shape
        u = axis_cells(grid[:, :, 0, 0], width)  # [3, G, N]: cell start, weight of the next vertex, of the first
        v = axis_cells(grid[:, :, 0, 1], height)
        first = (v[0] * width + u[0]).long()
        first += torch.arange(n_planes, device=first.device)[:, None] * (height * width)
        dx, dy = min(1, width - 1), min(1, height - 1)
        go = grad_out[..., 0].transpose(1, 2).contiguous()  # [G, N, C]: a sample's channels in one row
        rows = torch.zeros(n_planes * height * width, channels, dtype=stack.dtype, device=stack.device)
        for offset, weight in ((0, v[2] * u[2]), (dx, v[2] * u[1]), (dy * width, v[1] * u[2]),
                               (dy * width + dx, v[1] * u[1])):
            rows.index_add_(0, (first + offset).view(-1), (go * weight[..., None]).view(-1, channels))
        return rows.view(n_planes, height, width, channels).permute(0, 3, 1, 2), None


def sample_planes(stack: torch.Tensor, grid: torch.Tensor, variant: str) -> torch.Tensor:
    """``stack`` [G, C, H, W] at ``grid`` [G, N, 1, 2] -> [G, C, N], the gradient written as ``variant`` says."""
    if variant == "grid_sample":
        return F.grid_sample(stack, grid, **OPTIONS)[..., 0]
    if variant == "index_add":
        return IndexAddSample.apply(stack, grid)[..., 0]
    if variant == "nchw":
        return F.grid_sample(stack.contiguous(), grid, **OPTIONS)[..., 0]
    replicas = int(variant.split(":")[1])
    g, c, h, w = stack.shape
    n = grid.shape[1]
    pad = (-n) % replicas
    if pad:
        grid = torch.cat([grid, grid[:, :pad]], dim=1)
    copies = stack.unsqueeze(1).expand(g, replicas, c, h, w).reshape(g * replicas, c, h, w)
    out = F.grid_sample(copies, grid.reshape(g * replicas, -1, 1, 2), **OPTIONS)[..., 0]  # [G R, C, N / R]
    return out.reshape(g, replicas, c, -1).permute(0, 2, 1, 3).reshape(g, c, -1)[..., :n]


def make_grid(planes: int, n: int, k_plane: bool, k_values: int, device: torch.device,
              gen: torch.Generator) -> torch.Tensor:
    grid = torch.rand(planes, n, 1, 2, generator=gen, device=device) * 2 - 1
    if k_plane and k_values > 0:
        levels = torch.rand(k_values, generator=gen, device=device) * 2 - 1
        pick = torch.randint(0, k_values, (n,), generator=gen, device=device)
        grid[..., 1] = levels[pick][None, :, None]  # the k axis runs along H
    return grid


def time_one(stack: torch.Tensor, grid: torch.Tensor, weights: torch.Tensor, variant: str,
             repeats: int) -> list[float]:
    """Forward and backward of ``sum(weights * sample)``, timed ``repeats`` times after two warm-up passes."""
    times = []
    for i in range(repeats + 2):  # two warm-up passes
        if stack.device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        stack.grad = None
        (sample_planes(stack, grid, variant) * weights).sum().backward()
        if stack.device.type == "cuda":
            torch.cuda.synchronize()
        if i >= 2:
            times.append(time.perf_counter() - t0)
    return times


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--variants", nargs="+", default=["grid_sample", "index_add", "nchw", "replicas:4", "replicas:16"])
    p.add_argument("--k-values", type=int, nargs="+", default=[8, 0])
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--samples-scale", type=float, default=1.0, help="fraction of gpu-paper's samples (smoke runs)")
    args = p.parse_args()
    device = torch.device(args.device)
    for name, planes, channels, h, w, samples, k_plane in STACKS:
        n = max(int(samples * args.samples_scale), 1)
        for k_values in args.k_values if k_plane else [0]:
            gen = torch.Generator(device=device).manual_seed(0)
            grid = make_grid(planes, n, k_plane, k_values, device, gen)
            stack = torch.rand(planes, channels, h, w, device=device, generator=gen)
            stack = stack.contiguous(memory_format=torch.channels_last).requires_grad_(True)
            weights = torch.randn(planes, channels, n, device=device, generator=gen)  # the upstream gradient
            reference = None
            for variant in args.variants:
                if device.type == "cuda":
                    torch.cuda.reset_peak_memory_stats(device)
                times = time_one(stack, grid, weights, variant, args.repeats)
                grad = stack.grad.clone()
                reference = grad if reference is None else reference
                ms = sorted(times)[len(times) // 2] * 1000
                print(json.dumps({
                    "stack": name, "planes": planes, "channels": channels, "height": h, "width": w, "samples": n,
                    "k_values": k_values if k_plane else None, "variant": variant, "ms": round(ms, 3),
                    "samples_per_s": round(planes * n / (ms / 1000)),
                    "grad_max_rel_diff": round(float((grad - reference).abs().max() / reference.abs().max()), 9),
                    "peak_mib": round(torch.cuda.max_memory_allocated(device) / 2**20, 1)
                    if device.type == "cuda" else None,
                    "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
                    "load": round(os.getloadavg()[0], 2),
                }), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
