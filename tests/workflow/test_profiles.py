"""The execution profiles: config/gpu.yaml with workflow/profiles/gpu plans `gpu=1` on every rule that trains or
renders (and the profile lets one such job run at a time); the SLURM profile parses, takes its account, partitions
and memory cap from the environment, and routes the GPU rules to the GPU partition. The real SLURM run is
scripts/slurm-local.sh (root daemons, outside this suite; its output is in docs/workflow.md)."""

from __future__ import annotations

import importlib.util
import re
import shutil

import pytest
import yaml
from snakemake.profiles import ProfileConfigFileParser
from workflow_copy import REPO, SnakemakeRun, WorkflowCopy

GPU_RULES = {"train", "evaluate", "sweep", "control", "export"}  # every rule that trains a model or renders with one


def resources(text: str) -> dict[str, str]:
    """The `resources:` line of one dry-run job as name -> value."""
    line = re.search(r"^\s*resources: (.*)$", text, flags=re.M)
    assert line, text
    return dict(item.split("=", 1) for item in line.group(1).split(", "))


def profile(name: str) -> dict:
    """A profile as Snakemake reads it (YTE templates evaluated, key-value sections as CLI items)."""
    with open(REPO / "workflow" / "profiles" / name / "config.yaml") as stream:
        return dict(ProfileConfigFileParser().parse(stream))


@pytest.fixture(scope="module")
def gpu_plan(tmp_path_factory) -> SnakemakeRun:
    wf = WorkflowCopy(tmp_path_factory.mktemp("gpu") / "wf")
    run = wf.snakemake("-n", "--cores", "8", "--workflow-profile", "workflow/profiles/gpu",
                       "--configfile", "config/gpu.yaml")
    assert run.code == 0, run.output[-3000:]
    return run


def test_gpu_config_is_the_paper_preset_on_cuda():
    config = yaml.safe_load((REPO / "config" / "gpu.yaml").read_text())
    assert config["preset"] == "gpu-paper" and config["device"] == "cuda" and config["gpus"] == 1
    assert config["train"]["steps"] == 80000


def test_gpu_dry_run_asks_one_gpu_where_it_trains_or_renders(gpu_plan):
    blocks = gpu_plan.blocks()
    planned = {rule for rule, _ in blocks}
    assert planned >= GPU_RULES, sorted(planned)
    for rule, text in blocks:
        gpu = resources(text).get("gpu")
        if rule in GPU_RULES:
            assert gpu == "1", (rule, text)
            assert "--device cuda" in text or rule == "control", (rule, text)  # control is a script: no shell line
        else:
            assert gpu in (None, "0"), (rule, text)
    train = [text for rule, text in blocks if rule == "train"]
    assert len(train) == 3 and all("--preset gpu-paper" in t and "--max-steps 80000" in t for t in train)


def test_gpu_profile_runs_one_gpu_job_at_a_time():
    gpu = profile("gpu")
    assert gpu["resources"] == ["gpu=1"]  # the global limit: two gpu=1 jobs never run together
    assert "executor" not in gpu  # local execution


def test_cpu_config_asks_no_gpu(workflow_copy):
    for rule, text in workflow_copy.dry_run().blocks():
        assert resources(text).get("gpu") in (None, "0"), (rule, text)


def test_slurm_profile_parses_without_environment(monkeypatch):
    for var in ("LIVESCENE_SLURM_ACCOUNT", "LIVESCENE_SLURM_PARTITION", "LIVESCENE_SLURM_GPU_PARTITION",
                "LIVESCENE_SLURM_MAX_MEM_MB"):
        monkeypatch.delenv(var, raising=False)
    slurm = profile("slurm")
    assert slurm["executor"] == "slurm"
    assert not any(r.startswith("slurm_account=") for r in slurm["default-resources"])  # no placeholder account
    assert "slurm_partition=cpu" in slurm["default-resources"]
    for rule in GPU_RULES:
        assert f"{rule}:slurm_partition=gpu" in slurm["set-resources"], rule
        assert f"{rule}:gpu=1" not in slurm["set-resources"]  # the GPU count comes from the config (gpus)
    assert "train:mem_mb=32000" in slurm["set-resources"]


def test_slurm_profile_reads_account_partitions_and_memory_cap(monkeypatch):
    monkeypatch.setenv("LIVESCENE_SLURM_ACCOUNT", "proj42")
    monkeypatch.setenv("LIVESCENE_SLURM_PARTITION", "")  # empty: the cluster's default partition
    monkeypatch.setenv("LIVESCENE_SLURM_GPU_PARTITION", "a100")
    monkeypatch.setenv("LIVESCENE_SLURM_MAX_MEM_MB", "12000")
    slurm = profile("slurm")
    assert "slurm_account=proj42" in slurm["default-resources"]
    assert not any(r.startswith("slurm_partition=") for r in slurm["default-resources"])
    assert "train:slurm_partition=a100" in slurm["set-resources"]
    assert "train:mem_mb=12000" in slurm["set-resources"] and "evaluate:mem_mb=12000" in slurm["set-resources"]


@pytest.mark.skipif(importlib.util.find_spec("snakemake_executor_plugin_slurm") is None,
                    reason="optional extra .[slurm] (snakemake-executor-plugin-slurm) not installed")
def test_slurm_dry_run_routes_gpu_rules(tmp_path, monkeypatch):
    monkeypatch.setenv("LIVESCENE_SLURM_ACCOUNT", "proj42")
    monkeypatch.delenv("LIVESCENE_SLURM_MAX_MEM_MB", raising=False)
    wf = WorkflowCopy(tmp_path / "wf")
    run = wf.snakemake("-n", "--workflow-profile", "workflow/profiles/slurm", "--configfile", "config/gpu.yaml")
    assert run.code == 0, run.output[-3000:]
    for rule, text in run.blocks():
        res = resources(text)
        if rule == "default":
            continue
        assert res.get("slurm_account") == "proj42", (rule, text)
        if rule in GPU_RULES:
            assert res["gpu"] == "1" and res["slurm_partition"] == "gpu", (rule, text)
        else:
            assert res.get("gpu") in (None, "0") and res["slurm_partition"] == "cpu", (rule, text)
    assert all(resources(t)["mem_mb"] == "32000" for r, t in run.blocks() if r == "train")


def test_default_profile_counts_trainings_and_renders_as_one_core_each(workflow_copy):
    """Two of them share 2 cores; the training's torch threads stay config train.threads (the weights depend on it),
    the renders run on the one thread Snakemake gives them (renders are bit-identical whatever the count)."""
    assert profile("default")["set-threads"] == ["train=1", "evaluate=1", "sweep=1", "export=1"]
    blocks = workflow_copy.dry_run().blocks()
    assert {"train", "evaluate", "sweep", "export"} <= {rule for rule, _ in blocks}
    for rule, text in blocks:
        if rule in ("train", "evaluate", "sweep", "export"):  # a dry run prints `threads:` only above 1
            assert not re.search(r"^\s*threads: ", text, flags=re.M), (rule, text)
        if rule == "train":
            assert "--set train.threads=2" in text, text
        if rule == "export":
            assert "--threads" not in text, text


def test_colmap_takes_one_core(workflow_copy):
    """COLMAP runs on one thread in the workflow (deterministic poses), so its rule asks for one core: with two it
    waited for both to be free, behind every one-core training and evaluation of a sheet of scenes."""
    poses = [text for rule, text in workflow_copy.dry_run().blocks() if rule == "poses"]
    assert len(poses) == 1
    assert not re.search(r"^\s*threads: ", poses[0], flags=re.M), poses[0]  # a dry run prints `threads:` above 1
    assert "--threads 1" in poses[0] and "--parallel" not in poses[0], poses[0]
    assert not any(entry.startswith("poses=") for entry in profile("slurm")["set-threads"])


def test_a_slurm_training_asks_for_the_cpus_its_torch_threads_use():
    """The rule's threads are config train.threads (the torch threads a training runs); the SLURM profile asked 8
    CPUs of every training, 6 of them idle for hours."""
    assert not any(entry.startswith("train=") for entry in profile("slurm")["set-threads"])
    rule = (REPO / "workflow" / "rules" / "model.smk").read_text()
    assert 'threads: config["train"]["threads"]' in rule


def test_a_plain_snakemake_run_at_the_root_uses_the_default_profile(tmp_path):
    """Snakemake looks for a workflow profile next to the main Snakefile (the root one): profiles/default there
    links workflow/profiles/default, so `snakemake --cores 2` schedules as `make run` does."""
    link = REPO / "profiles" / "default"
    assert link.is_symlink() and link.resolve() == (REPO / "workflow" / "profiles" / "default").resolve()
    wf = WorkflowCopy(tmp_path / "wf")
    shutil.copytree(REPO / "profiles", wf.root / "profiles", symlinks=True)
    run = wf.snakemake("-n", "--cores", "2")
    assert run.code == 0, run.output[-3000:]
    assert "Using workflow specific profile profiles/default" in run.output
    # the profile's set-threads: a training counts as one core, so two run side by side (a dry run prints the
    # threads of a job only above 1); without the profile each takes the 2 of train.threads
    trains = [text for rule, text in run.blocks() if rule == "train"]
    assert trains and not any("threads:" in text for text in trains)
    (wf.root / "profiles" / "default").unlink()
    bare = wf.snakemake("-n", "--cores", "2")
    assert "Using workflow specific profile" not in bare.output
    assert all("threads: 2" in text for rule, text in bare.blocks() if rule == "train")


@pytest.mark.skipif(importlib.util.find_spec("torch") is None or __import__("torch").cuda.is_available(),
                    reason="checks a machine without a GPU")
def test_the_gpu_config_on_a_machine_without_one_stops_before_any_job(tmp_path):
    """Before, the first training failed after every CPU job of the scene (COLMAP among them) had run."""
    wf = WorkflowCopy(tmp_path / "wf")
    run = wf.snakemake("--cores", "2", "--workflow-profile", "workflow/profiles/gpu", "--configfile", "config/gpu.yaml")
    assert run.code != 0
    assert "config device: cuda, but torch" in run.output and "sees no GPU on this machine" in run.output
    assert "fix: run on a machine with a GPU" in run.output and "--config device=cpu gpus=0" in run.output
    assert not (wf.root / "results").exists()  # no job ran
    assert wf.snakemake("-n", "--cores", "2", "--configfile", "config/gpu.yaml").code == 0  # a dry run plans as before
