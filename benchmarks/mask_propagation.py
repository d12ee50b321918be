"""Masks on key frames only: propagated masks against the truth, and LiveScene trained on them.

    python benchmarks/mask_propagation.py [--scenes demo kitchen SPEC.yaml] [--every 8] [--train] [--work DIR]

For each synthetic capture: generate it and extract its frames (`livescene capture`, `livescene frames`),
keep the capture's masks on every EVERY-th frame only (0, EVERY, 2 EVERY, ...), run `livescene labels`
(which propagates them to every frame) and score every propagated frame against the capture's truth masks:
IoU per object (mean over the frames where the object is in the truth or the prediction), pixel accuracy
and mean confidence by distance to the nearest annotated frame, and the stage's own leave-one-out
estimate next to the truth.

With ``--train`` it then runs the rest of the DAG twice on one set of COLMAP poses, states and language
targets, once with the truth masks and once with the propagated ones (LiveScene, cpu-demo preset, STEPS
steps, seed 0), evaluates both runs on the truth-mask dataset (the same 8 held-out views) and prints the
held-out PSNR of each with the paired per-view difference. Every step is skipped when its output exists,
so an interrupted run continues. docs/labels-states.md records the output.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)

from stages.labels import LabelsConfig, ingest_labels
from stages.labels.propagation import iou_per_object
from stages.scene import onehot_to_label_map

ROOT = Path(__file__).resolve().parents[1]
LIVESCENE = [sys.executable, "-m", "stages.cli"]


def sh(args: list[str], log: Path) -> None:
    """Run a livescene command with 2 threads; stop with its log tail when it fails."""
    env = dict(os.environ, HF_HUB_OFFLINE="1", TRANSFORMERS_OFFLINE="1", OMP_NUM_THREADS="2")
    t0 = time.perf_counter()
    with log.open("w") as handle:
        code = subprocess.run(args, cwd=ROOT, env=env, stdout=handle, stderr=subprocess.STDOUT, check=False).returncode
    if code != 0:
        raise SystemExit(f"{' '.join(args)} failed ({code}):\n{log.read_text()[-3000:]}")
    print(f"  [{time.perf_counter() - t0:6.1f} s] {' '.join(args[3:6])} ...", flush=True)


def label_maps(labels: Path) -> dict[str, np.ndarray]:
    """Frame id -> int map, 0 background, k = object k (1-based), from a LABELS folder."""
    out = {}
    for path in sorted((labels / "masks").glob("*.npy")):
        mask = np.load(path)
        lab = onehot_to_label_map(mask) + 1
        lab[lab == mask.shape[-1]] = 0
        out[path.stem] = lab
    return out


def spec_path(scene: str) -> Path:
    """A capture spec of config/captures by name, or a spec file (``.yaml``) given by path."""
    return Path(scene) if scene.endswith((".yaml", ".yml")) else ROOT / "config" / "captures" / f"{scene}.yaml"


def prepare(name: str, work: Path, every: int, spec: Path) -> dict[str, Path]:
    d = work / name
    (d / "logs").mkdir(parents=True, exist_ok=True)
    paths = {"capture": d / "capture", "frames": d / "frames", "keys": d / f"key_masks_every{every}",
             "labels_truth": d / "labels_truth", "labels_prop": d / f"labels_every{every}", "logs": d / "logs"}
    if not (paths["capture"] / "truth" / "transforms.json").is_file():
        sh([*LIVESCENE, "capture", "--spec", str(spec), "--out",
            str(paths["capture"]), "--force", "--no-progress"], d / "logs" / "capture.log")
    if not (paths["frames"] / "frames.csv").is_file():
        sh([*LIVESCENE, "frames", "--video", str(paths["capture"] / "video.mp4"), "--out", str(paths["frames"]),
            "--no-progress"], d / "logs" / "frames.log")
    if not paths["keys"].is_dir():
        tmp = paths["keys"].with_name(paths["keys"].name + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        (tmp / "masks").mkdir(parents=True)
        masks = sorted((paths["capture"] / "masks").glob("*.png"))
        for path in masks[::every]:
            shutil.copy(path, tmp / "masks" / path.name)
        shutil.copy(paths["capture"] / "mapping.yaml", tmp / "mapping.yaml")
        tmp.rename(paths["keys"])
    if not (paths["labels_truth"] / "labels.json").is_file():
        ingest_labels(LabelsConfig(input=paths["capture"] / "masks", frames=paths["frames"],
                                   out=paths["labels_truth"], progress=False))
    return paths


def score(name: str, paths: dict[str, Path]) -> dict:
    t0 = time.perf_counter()
    summary = ingest_labels(LabelsConfig(input=paths["keys"], frames=paths["frames"], out=paths["labels_prop"],
                                         progress=False))
    wall = time.perf_counter() - t0
    names = summary["objects"]
    truth = label_maps(paths["labels_truth"])
    pred = label_maps(paths["labels_prop"])
    conf = {r["frame"]: r for r in _csv(paths["labels_prop"] / "confidence.csv")}
    ious: dict[str, list[float]] = {n: [] for n in names}
    copied: dict[str, list[float]] = {n: [] for n in names}
    by_distance: dict[int, list[tuple[float, float]]] = {}
    for fid in summary["propagated_frames"]:
        for k, v in iou_per_object(pred[fid], truth[fid], len(names)).items():
            if v is not None:
                ious[names[k - 1]].append(v)
        row = conf[fid]
        # the baseline without motion: the nearest annotation copied as it is
        for k, v in iou_per_object(truth[row["nearest_key"]], truth[fid], len(names)).items():
            if v is not None:
                copied[names[k - 1]].append(v)
        by_distance.setdefault(int(row["distance"]), []).append(
            (float(np.mean(pred[fid] == truth[fid])), float(row["mean_confidence"])))
    prop = json.loads((paths["labels_prop"] / "propagation.json").read_text())
    per_object = {n: (float(np.mean(v)), float(np.min(v)), len(v), float(np.mean(copied[n])))
                  for n, v in ious.items() if v}
    return {"scene": name, "objects": names, "n_frames": summary["n_frames"], "annotated": summary["n_labelled"],
            "propagated": len(summary["propagated_frames"]), "wall_s": wall, "per_object": per_object,
            "mean_iou": float(np.mean([v[0] for v in per_object.values()])),
            "copy_iou": float(np.mean([v[3] for v in per_object.values()])),
            "loo": prop["leave_one_out"], "timings": prop["timings"],
            "by_distance": {d: (float(np.mean([a for a, _ in v])), float(np.mean([c for _, c in v])), len(v))
                            for d, v in sorted(by_distance.items())}}


def _csv(path: Path) -> list[dict[str, str]]:
    import csv

    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def train_pair(name: str, paths: dict[str, Path], work: Path, steps: int) -> dict:
    d, logs, cap = work / name, paths["logs"], paths["capture"]
    poses, states = d / "poses", d / "states"
    if not (poses / "transforms.json").is_file():
        sh([*LIVESCENE, "poses", "--frames", str(paths["frames"]), "--out", str(poses), "--masks", str(cap / "masks"),
            "--threads", "2", "--seed", "0", "--no-progress"], logs / "poses.log")
    alignment = d / "pose_error.json"
    if not alignment.is_file():
        sh([*LIVESCENE, "poses", "compare", "--pred", str(poses / "transforms.json"), "--truth",
            str(cap / "truth" / "transforms.json"), "--out", str(alignment)], logs / "pose_compare.log")
    if not (states / "states.csv").is_file():
        sh([*LIVESCENE, "states", "--key-frames", str(cap / "key_frame_value.yaml"), "--mapping",
            str(cap / "mapping.yaml"), "--frames", str(paths["frames"] / "frames.csv"), "--out", str(states)],
           logs / "states.log")
    datasets = {"truth": d / "dataset_truth_masks", "propagated": d / "dataset_propagated_masks"}
    for kind, labels in (("truth", paths["labels_truth"]), ("propagated", paths["labels_prop"])):
        if not (datasets[kind] / "transforms.json").is_file():
            sh([*LIVESCENE, "dataset", "assemble", "--frames", str(paths["frames"]), "--poses", str(poses), "--labels",
                str(labels), "--states", str(states), "--prompts", str(cap / "prompts.yaml"), "--out",
                str(datasets[kind]), "--no-progress"], logs / f"assemble_{kind}.log")
    targets = d / "targets.npz"
    if not targets.is_file():
        sh([*LIVESCENE, "language", "targets", "--data", str(datasets["truth"]), "--out", str(targets)],
           logs / "targets.log")
    out = {}
    for kind, ds in datasets.items():
        run, ev = d / f"run_{kind}_masks", d / f"eval_{kind}_masks"
        if not (run / "run.json").is_file():
            sh([*LIVESCENE, "train", "--data", str(ds), "--method", "livescene", "--preset", "cpu-demo", "--out",
                str(run), "--resume", "--max-steps", str(steps), "--seed", "0", "--device", "cpu",
                "--set", "train.threads=2", "--language-targets", str(targets), "--no-progress"],
               logs / f"train_{kind}.log")
        if not (ev / "metrics.json").is_file():
            # both runs are scored on the truth-mask dataset: same views, grounding against the true masks
            sh([*LIVESCENE, "evaluate", "--run", str(run), "--data", str(datasets["truth"]), "--truth", str(cap),
                "--pose-alignment", str(alignment), "--out", str(ev), "--max-views", "8", "--unseen-views", "3",
                "--device", "cpu"], logs / f"evaluate_{kind}.log")
        metrics = json.loads((ev / "metrics.json").read_text())
        run_info = json.loads((run / "run.json").read_text())
        out[kind] = {"psnr": metrics["held_out"]["psnr"],
                     "views": {v["frame"]: v["psnr"] for v in metrics["held_out"]["views"]},
                     "unseen": (metrics.get("unseen_combinations") or {}).get("psnr"),
                     "grounding": (metrics.get("grounding") or {}).get("miou_probs"),
                     "steps": run_info.get("steps"), "train_s": run_info.get("train_seconds")}
    return out


def paired(a: dict[str, float], b: dict[str, float]) -> tuple[float, float, float, int]:
    """Mean of b - a over common views with a 95 % t interval."""
    from scipy import stats

    diff = np.array([b[k] - a[k] for k in sorted(a) if k in b])
    mean = float(diff.mean())
    half = float(stats.t.ppf(0.975, len(diff) - 1) * diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1 else 0.0
    return mean, mean - half, mean + half, len(diff)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="+", default=["demo", "kitchen"],
                   help="capture specs of config/captures, by name, or spec files (.yaml) by path")
    p.add_argument("--every", type=int, default=8, help="keep the masks of every N-th frame")
    p.add_argument("--work", type=Path, default=Path("/tmp/mask_propagation"), help="folder for everything (reused)")
    p.add_argument("--train", action="store_true", help="also train LiveScene on truth and on propagated masks")
    p.add_argument("--steps", type=int, default=1500, help="training steps per run (the workflow's default)")
    args = p.parse_args()
    results, trained = [], {}
    for scene in args.scenes:
        name = spec_path(scene).stem
        print(f"{name}:", flush=True)
        paths = prepare(name, args.work, args.every, spec_path(scene))
        shutil.rmtree(paths["labels_prop"], ignore_errors=True)
        results.append(score(name, paths))
        if args.train:
            trained[name] = train_pair(name, paths, args.work, args.steps)

    print(f"\nmasks on every {args.every}th frame, propagated to every frame, against the truth masks")
    print("| capture | frames (annotated / propagated) | object | mean IoU | min IoU | frames scored | "
          "leave-one-out IoU (stage's estimate) | nearest annotation copied (no flow) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in results:
        loo = r["loo"].get("mean_iou", {})
        for obj, (mean, low, n, copy) in r["per_object"].items():
            print(f"| {r['scene']} | {r['annotated']} / {r['propagated']} | {obj} | {mean:.3f} | {low:.3f} | {n} | "
                  f"{_f(loo.get(obj))} | {copy:.3f} |")
        print(f"| {r['scene']} | | **all (mean of objects)** | **{r['mean_iou']:.3f}** | | | "
              f"{_f(r['loo'].get('mean_iou_all'))} | {r['copy_iou']:.3f} |")
    print("\npixel accuracy and mean confidence by distance to the nearest annotated frame")
    print("| capture | distance | pixel accuracy | mean confidence | frames |")
    print("|---|---|---|---|---|")
    for r in results:
        for dist, (acc, conf, n) in r["by_distance"].items():
            print(f"| {r['scene']} | {dist} | {acc:.4f} | {conf:.4f} | {n} |")
    print("\ntimings (labels stage with propagation, this machine)")
    for r in results:
        t = r["timings"]
        print(f"  {r['scene']}: {r['wall_s']:.1f} s wall for {r['n_frames']} frames "
              f"({t['per_frame_ms']:.0f} ms per propagated frame, leave-one-out {t['leave_one_out_s']:.1f} s)")
    if trained:
        print(f"\nLiveScene (cpu-demo, {args.steps} steps, seed 0) on the same poses, states and language targets, "
              "evaluated on the truth-mask dataset")
        print("| capture | masks | held-out PSNR (8 views) [95 % CI] | unseen combinations PSNR | grounding mIoU | "
              "steps | train s |")
        print("|---|---|---|---|---|---|---|")
        for name, runs in trained.items():
            for kind, m in runs.items():
                ps = m["psnr"]
                print(f"| {name} | {kind} | {ps['mean']:.2f} [{ps['ci95'][0]:.2f}, {ps['ci95'][1]:.2f}] | "
                      f"{_f((m['unseen'] or {}).get('mean'), 2)} | {_f(m['grounding'])} | {m['steps']} | "
                      f"{_f(m['train_s'], 0)} |")
        print("\npropagated - truth masks, held-out PSNR, paired over views")
        for name, runs in trained.items():
            mean, lo, hi, n = paired(runs["truth"]["views"], runs["propagated"]["views"])
            verdict = "within 1 dB" if abs(mean) <= 1.0 else "NOT within 1 dB"
            print(f"  {name}: {mean:+.2f} dB [{lo:+.2f}, {hi:+.2f}] over {n} views ({verdict})")


def _f(v: float | None, digits: int = 3) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


if __name__ == "__main__":
    main()
