"""The machine a wall time or a throughput figure was measured on.

The same computation ran 2.2x (training) to 3.1x (rendering) slower on one 2-core VM than on another
(docs/workflow.md, "Machines"), so a time means little without the CPU it ran on: run.json, timings.json,
the stability summary and the benchmarks record this next to the load.
"""

from __future__ import annotations

import os
import platform
import sys
from typing import Any


def cpu_model() -> str:
    """The CPU's model name (Linux: /proc/cpuinfo), else what ``platform`` knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_info(device: str | None = None) -> dict[str, Any]:
    """CPU model, logical cores, Python, and where torch is loaded its version, CPU kernels and GPU.

    torch is read only if the caller already imported it (this module costs nothing to import).
    """
    info: dict[str, Any] = {"cpu": cpu_model(), "logical_cores": os.cpu_count(), "python": platform.python_version(),
                            # spinning OpenMP threads make a busy machine's steps 2-5x slower (docs/model.md)
                            "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "unset (spin)")}
    torch = sys.modules.get("torch")
    if torch is not None:
        info["torch"] = torch.__version__
        # the vectorised kernels torch picked for this CPU (e.g. AVX2, AVX512)
        info["torch_cpu_capability"] = torch.backends.cpu.get_cpu_capability()
        if device is not None and str(device).startswith("cuda") and torch.cuda.is_available():
            info["gpu"] = torch.cuda.get_device_name(torch.device(device))
    return info


def machine_line(info: dict[str, Any] | None = None) -> str:
    """One line for a benchmark's header: ``Intel(R) Xeon(R) ... @ 2.50GHz, 2 logical cores, torch 2.13.0 (AVX512)``."""
    info = info or machine_info()
    text = f"{info['cpu']}, {info['logical_cores']} logical cores"
    if "torch" in info:
        text += f", torch {info['torch']} ({info['torch_cpu_capability']})"
    if "gpu" in info:
        text += f", {info['gpu']}"
    if "omp_wait_policy" in info:
        text += f", OMP_WAIT_POLICY {info['omp_wait_policy']}"
    return text


def contention() -> str:
    """The machine's load now, for a benchmark's figure: the 1-minute load average and, where Linux tells it
    (/proc/pressure/cpu), the share of the last 10 s in which some runnable task waited for a CPU (the load
    average alone did not tell a slow run from a fast one on a shared VM)."""
    text = f"load {os.getloadavg()[0]:.2f}"
    try:
        with open("/proc/pressure/cpu", encoding="ascii") as fh:
            some = fh.readline().split()
        avg10 = next(float(f.split("=", 1)[1]) for f in some if f.startswith("avg10="))
        text += f", cpu pressure {avg10:.0f} %"
    except (OSError, StopIteration, ValueError, IndexError):
        pass
    return text
