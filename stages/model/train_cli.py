"""``livescene train``: train LiveScene (or a registered baseline) on a scene dataset."""

from __future__ import annotations

import argparse
import json
import signal
import sys

from stages.scene import InputError
from stages.scene.cli_errors import ErrorExit, cli_errors

from .config import load_config
from .trainer import Trainer, TrainingDiverged


def build_parser(prog: str = "livescene train") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__)
    p.add_argument("--data", required=True, help="scene dataset folder (holds transforms.json)")
    p.add_argument("--method", default="livescene", help="registered method name (default livescene)")
    p.add_argument("--preset", default="cpu-demo", help="config/model/<name>.yaml or a YAML path (default cpu-demo)")
    p.add_argument("--out", required=True, help="run folder to write")
    p.add_argument("--state-mode", choices=["auto", "given", "learned"],
                   help="given (every frame's states), learned (key frames supervise a state network) or auto "
                        "(default: given when every frame carries states, else learned)")
    p.add_argument("--language-targets", help="targets .npz from `livescene language targets`: enables the table")
    p.add_argument("--exposure", help="the dataset's exposure estimate from `livescene scene exposure --out` (for "
                   "model.appearance.mode auto / measured): read instead of measured again")
    p.add_argument("--max-seconds", type=float, help="wall-clock budget; training stops and saves when spent")
    p.add_argument("--max-steps", type=int, help="optimisation steps (overrides the preset)")
    p.add_argument("--seed", type=int, help="seed of every random generator (default 0)")
    p.add_argument("--device", default="auto", help="auto | cpu | cuda (default auto)")
    p.add_argument("--camera-opt", choices=["off", "SO3xR3"],
                   help="refine the training cameras while training (SO3xR3: a rotation and a translation per "
                        "training frame; default off, as train.camera_opt; docs/model.md \"Camera refinement\")")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config field, e.g. --set train.batch_rays=2048 (repeatable)")
    p.add_argument("--resume", action="store_true",
                   help="continue from the run folder's latest checkpoint (only one of the same data and config)")
    p.add_argument("--restart-stale", action="store_true",
                   help="with --resume: when the checkpoint was trained on other data or config, discard it and train "
                        "from step 0 instead of stopping with an error (what the workflow does on rerun)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


FLAG_FIELDS = {"preset": "preset", "method": "method", "data": "data"}
"""Top-level config fields whose option always wins (or, for the preset, is read before any --set)."""


@cli_errors(KeyError, ErrorExit(TrainingDiverged, 1, "training diverged: "))  # KeyError: an unknown --method
def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    for item in args.overrides:  # the options below win over a --set of their field: refuse it rather than drop it
        key = item.partition("=")[0].strip()
        if key in FLAG_FIELDS:
            raise InputError("--set", f"{item!r} sets a field that --{FLAG_FIELDS[key]} gives",
                             f"pass --{FLAG_FIELDS[key]} instead")
    if args.device not in ("auto", "cpu", "cuda") and not args.device.startswith("cuda:"):
        raise InputError("--device", f"{args.device!r} is not a device", "pass auto, cpu, cuda or cuda:N")
    overrides = list(args.overrides)
    if args.state_mode:
        overrides.append(f"model.state.mode={args.state_mode}")
    if args.max_seconds is not None:
        overrides.append(f"train.max_seconds={args.max_seconds}")
    if args.max_steps is not None:
        overrides.append(f"train.max_steps={args.max_steps}")
    if args.camera_opt is not None:  # quoted: YAML would read a bare off as false
        overrides.append(f"train.camera_opt='{args.camera_opt}'")
    config = load_config(args.preset, overrides, method=args.method, seed=args.seed, data=args.data,
                         language_targets=args.language_targets, exposure=args.exposure)
    trainer = Trainer(config, args.out, device=args.device, resume=args.resume, progress=not args.no_progress,
                      restart_stale=args.restart_stale)
    summary = trainer.train()
    if summary.get("status") == "sigterm":  # SIGTERM, Ctrl-C or a closed terminal: the run is left resumable
        sig = trainer.stop_signal or signal.SIGTERM
        print(f"stopped by {signal.Signals(sig).name} at step {summary['step']}; checkpoint saved, resume with "
              "--resume", file=sys.stderr)
        return 128 + int(sig)
    print(json.dumps({k: summary[k] for k in ("method", "status", "steps", "train_seconds", "eval_psnr",
                                              "peak_memory_mib")}))
    return 0
