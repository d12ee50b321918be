"""The machine record that goes with every wall time (stages/scene/machine.py)."""

from __future__ import annotations

import torch

from stages.scene import machine


def test_machine_info_names_the_cpu_and_the_kernels_torch_picked():
    info = machine.machine_info("cpu")
    assert info["cpu"] == machine.cpu_model() and info["cpu"] != ""
    assert info["logical_cores"] >= 1
    assert info["torch"] == torch.__version__
    assert info["torch_cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    assert "gpu" not in info  # asked for the CPU
    line = machine.machine_line(info)
    assert line.startswith(f"{info['cpu']}, {info['logical_cores']} logical cores, torch {torch.__version__} (")


def test_cpu_model_falls_back_where_there_is_no_proc_cpuinfo(monkeypatch):
    def no_file(*args, **kwargs):
        raise OSError("no /proc here")

    monkeypatch.setattr("builtins.open", no_file)
    monkeypatch.setattr(machine.platform, "processor", lambda: "")
    monkeypatch.setattr(machine.platform, "machine", lambda: "arm64")
    assert machine.cpu_model() == "arm64"


def test_machine_line_without_torch():
    info = {"cpu": "Some CPU", "logical_cores": 4, "python": "3.11.7"}
    assert machine.machine_line(info) == "Some CPU, 4 logical cores"


def test_the_wait_policy_and_the_contention_are_recorded(monkeypatch):
    """Spinning or sleeping OpenMP threads change a step's time 2-14x on a shared machine (docs/model.md,
    "OpenMP wait policy"): a figure names the policy, and a benchmark the CPU pressure beside the load."""
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    info = machine.machine_info()
    assert info["omp_wait_policy"] == "PASSIVE" and machine.machine_line(info).endswith(", OMP_WAIT_POLICY PASSIVE")
    monkeypatch.delenv("OMP_WAIT_POLICY")
    assert machine.machine_info()["omp_wait_policy"] == "unset (spin)"
    said = machine.contention()
    assert said.startswith("load ") and float(said.split()[1].rstrip(",")) >= 0
