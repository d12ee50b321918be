"""``livescene control``: set object states from a language command, and render the result.

    livescene control --run RUN "open the fridge and half open the drawer" [--out control.png]
    livescene control --data DS "close everything"                     # parse only, no trained run
    livescene control --data DS --from-frame --frame FID "close everything except the drawer"
    livescene control --objects fridge,drawer --prompts prompts.yaml "open the refrigerator"

Prints the new state vector as JSON. With --run the result is rendered at a
dataset frame's pose (default: the first test frame) through the model API;
--from-frame starts from that frame's states (with --run or --data).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import yaml

from stages.scene import InputError, SceneDataset
from stages.scene.cli_errors import cli_errors
from stages.scene.dataset import STATE_SEEN_WITHIN
from stages.scene.state_values import parse_state_assignments

from .cli import add_encoder_arguments, encoder_from_args


def build_parser(prog: str = "livescene control") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", help='e.g. "open the fridge", "close everything", "open the drawer to 30%%"')
    p.add_argument("--run", default=None, help="trained run folder: render the result through the model")
    p.add_argument("--data", default=None, help="scene dataset for object names and prompts (default: the run's)")
    p.add_argument("--objects", default=None, help="comma-separated object names (parse-only use, without a dataset)")
    p.add_argument("--prompts", default=None, help="prompts.yaml with synonyms/descriptions (with --objects)")
    p.add_argument("--state", action="append", default=[], metavar="OBJECT=VALUE",
                   help="starting state of an object (repeatable; default: all closed, or the frame's state)")
    p.add_argument("--from-frame", action="store_true", help="start from the state of the rendered frame")
    p.add_argument("--frame", default=None, help="frame id whose pose is rendered (default: first test frame)")
    p.add_argument("--out", default=None, help="output PNG with --run (default: control.png)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--no-encoder", action="store_true",
                   help="resolve objects by name, synonym and spelling only (no text model is loaded)")
    add_encoder_arguments(p)
    return p


def _beyond_training(ds: SceneDataset, states: dict[str, float]) -> dict[str, dict[str, Any]]:
    """Objects set farther than ``STATE_SEEN_WITHIN`` from every state of the training frames (a drawer the capture
    only half opened, asked to open fully), with the state and the training range."""
    ranges = ds.state_ranges()
    out = {}
    for name, value in states.items():
        lo_hi = ranges.get(name)
        if lo_hi and not lo_hi[0] - STATE_SEEN_WITHIN <= value <= lo_hi[1] + STATE_SEEN_WITHIN:
            out[name] = {"state": value, "training_range": lo_hi}
    return out


@cli_errors(sigterm=True)
def main(argv: list[str] | None = None) -> int:
    return _control(build_parser().parse_args(argv))


def _control(args: argparse.Namespace) -> int:
    from .commands import CommandParser
    from .vocabulary import ObjectVocabulary

    data = args.data
    if args.run and not data:
        from stages.model.run import dataset_of_run  # imported on use: commands without --run need no torch

        data = dataset_of_run(args.run)
    if args.objects:
        prompts = {}
        if args.prompts:
            try:
                prompts = yaml.safe_load(Path(args.prompts).read_text()) or {}
            except (OSError, yaml.YAMLError) as exc:
                raise InputError(args.prompts, f"cannot read prompts ({exc})", "pass a readable prompts.yaml") from exc
        vocabulary = ObjectVocabulary.from_prompts([o.strip() for o in args.objects.split(",") if o.strip()],
                                                   prompts, args.prompts or "--objects")
    elif data is not None:
        vocabulary = ObjectVocabulary.from_dataset(data)
    else:
        raise InputError("--run/--data/--objects", "no object names to control",
                         "pass --data DS (or a --run whose config.yaml names its dataset), or --objects a,b")
    encoder = None if args.no_encoder else encoder_from_args(args)
    parser = CommandParser(vocabulary, encoder)

    ds = frame = None
    if data is not None:
        # also without a run: --from-frame starts from a frame's states, and commands beyond the training states
        # are named
        from stages.scene import read_scene

        ds = read_scene(data)
        frames = ds.frames_in("test") or ds.frames
        frame = ds.frame_by_id(args.frame) if args.frame else frames[0]
    elif args.from_frame or args.frame:
        raise InputError("--from-frame/--frame", "a frame needs a scene dataset, and none was given",
                         "pass --data DS or --run RUN instead of --objects, or the starting states with --state")
    run = None
    if args.out and not args.run:
        raise InputError("--out", "a render needs a trained run, and none was given (without --run the command only "
                         "prints the states)", "pass --run RUN, or leave --out out")
    if args.run:
        assert ds is not None
        from stages.model.run import open_run
        from stages.scene import guard_output_file

        guard_output_file(args.out or "control.png", "the control render", suffixes=(".png",),
                          inputs=[args.run, ds.root])

        run = open_run(args.run, args.device)
        # the run's frames are the dataset's: a frame's index (its learned state, its time) means the same frame
        if run.frame_ids and [f.frame_id for f in ds.frames] != run.frame_ids:
            raise InputError(ds.root, "is not the dataset the run was trained on (its frames differ from the run's)",
                             "pass --data the run's dataset, or leave --data out to use it")
    current = dict.fromkeys(vocabulary.objects, 0.0)
    if args.from_frame and frame is not None and run is not None:  # the states the run renders there (learned too)
        assert ds is not None
        vector = run.state_vector(None, ds.frames.index(frame))
        current.update({k: float(v) for k, v in zip(run.objects, vector, strict=True) if k in current})
    elif args.from_frame and frame is not None and frame.state:
        current.update({k: v for k, v in frame.state.items() if k in current})
    current.update(parse_state_assignments(args.state))
    result = parser.parse(args.command, current)
    report = result.to_json(vocabulary.objects)
    report["command"] = args.command

    if ds is not None:
        beyond = _beyond_training(ds, result.states)
        if beyond:
            report["beyond_training"] = beyond
            for name, b in beyond.items():
                lo, hi = b["training_range"]
                print(f"note: {name} at {b['state']:.2f} is beyond the states its training frames show "
                      f"({lo:.2f} to {hi:.2f}): the render extrapolates", file=sys.stderr)
    if run is not None:
        assert ds is not None and frame is not None
        import cv2
        import numpy as np

        from stages.scene import atomic_path

        path = Path(args.out or "control.png")
        run.warn_if_states_unread(result.states)
        out = run.render(ds.camera_of(frame), frame.c2w, result.states, frame_index=ds.frames.index(frame))
        rgb = np.clip(np.asarray(out["rgb"])[..., ::-1] * 255 + 0.5, 0, 255).astype(np.uint8)
        with atomic_path(path, suffix=".png") as tmp:
            if not cv2.imwrite(str(tmp), rgb):
                raise OSError(f"could not write {path}")
        report["image"] = str(path)
        report["frame"] = frame.frame_id
    print(json.dumps(report, indent=2, ensure_ascii=False))  # object names as written: "Küchenschrank"
    return 0
