# Config and scene-sheet loading, schema validation and the input functions that decide per
# scene which rules it needs. Everything here runs at workflow start, before any job.
import json
from pathlib import Path

import jsonschema
import pandas as pd
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

SCHEMAS = Path(workflow.current_basedir.get_path_or_uri(secret_free=True)).parent / "schemas"
METHODS = ["livescene", "mk-planes", "mk-planes-star", "conerf", "k-planes"]


def _schema_problem(error):
    """One line naming the key path, the bad value and what the schema expects."""
    where = ".".join(str(p) for p in error.absolute_path) or "(top level)"
    expected = {k: error.schema[k] for k in ("type", "enum", "pattern", "minimum", "exclusiveMinimum")
                if k in error.schema}
    return f"key {where!r}: {error.message}" + (f" (expected {expected})" if expected else "")


def _check_config(cfg):
    """Validate the merged config; the error names the config file(s), the key and the expected type."""
    schema = yaml.safe_load((SCHEMAS / "config.schema.yaml").read_text())
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(cfg), key=lambda e: list(e.absolute_path))
    if errors:
        files = [str(f) for f in workflow.configfiles] or ["config/config.yaml"]
        lines = "\n".join(f"  - {_schema_problem(e)}" for e in errors)
        raise WorkflowError(f"invalid workflow config in {', '.join(files)}:\n{lines}\n"
                            f"fix: correct these keys (schema: {SCHEMAS / 'config.schema.yaml'})")
    validate(cfg, schema="../schemas/config.schema.yaml")  # fills the defaults


def _read_scene_sheet(path):
    """Read and validate the scene sheet; errors name the file, the line, the scene and the column."""
    sheet_path = Path(path)
    if not sheet_path.is_file():
        raise WorkflowError(f"{sheet_path}: the scene sheet does not exist; fix: write it (see docs/workflow.md) "
                            "or point config key 'scenes' at it")
    sheet = pd.read_csv(sheet_path, sep="\t", dtype=str, comment="#", keep_default_na=False)
    schema = yaml.safe_load((SCHEMAS / "scenes.schema.yaml").read_text())
    problems = []
    unknown = [c for c in sheet.columns if c not in schema["properties"]]
    if unknown:
        problems.append(f"header: unknown column(s) {unknown}; known: {list(schema['properties'])}")
    for i, row in enumerate(sheet.to_dict("records")):
        record = {k: v for k, v in row.items() if v != "" and k in schema["properties"]}
        name = row.get("scene") or f"row {i + 1}"
        for error in jsonschema.Draft202012Validator(schema).iter_errors(record):
            problems.append(f"line {i + 2} (scene {name!r}): {_schema_problem(error)}")
        if record.get("source") == "dataset" and record.get("poses", "given") != "given":
            problems.append(f"line {i + 2} (scene {name!r}): key 'poses': a ready dataset carries its poses; "
                            "write 'given'")
        if record.get("source") in ("video", "images") and record.get("poses") == "given":
            problems.append(f"line {i + 2} (scene {name!r}): key 'poses': a {record['source']} source has no poses "
                            "to give; write 'estimate'")
    dupes = sheet["scene"][sheet["scene"].duplicated()].tolist() if "scene" in sheet else []
    if dupes:
        problems.append(f"column 'scene': duplicate scene name(s) {dupes}")
    if sheet.empty:
        problems.append("no scene rows")
    if problems:
        lines = "\n".join(f"  - {p}" for p in problems)
        raise WorkflowError(f"invalid scene sheet {sheet_path}:\n{lines}\nfix: correct these cells "
                            f"(schema: {SCHEMAS / 'scenes.schema.yaml'})")
    for column, prop in schema["properties"].items():
        default = prop.get("default", "")
        if column not in sheet:
            sheet[column] = default
        sheet[column] = sheet[column].replace("", default)
    return sheet.set_index("scene", drop=False)


_check_config(config)
scenes = _read_scene_sheet(config["scenes"])
RESULTS = config["results"]
REPORTS = config["reports"]


wildcard_constraints:
    scene="|".join(scenes.index),
    method="|".join(METHODS),


# --- what a scene carries ---------------------------------------------------------------


def row(scene):
    return scenes.loc[scene]


def source(scene):
    return row(scene)["source"]


def carries(scene, column):
    """True when the scene has this item (the source carries it, or a path is given)."""
    return row(scene)[column] != "no"


def estimates_poses(scene):
    return row(scene)["poses"] == "estimate"


def has_truth(scene):
    return carries(scene, "truth")


def has_names(scene):
    return carries(scene, "names")


def methods(scene):
    listed = row(scene)["methods"]
    return listed.split(",") if listed else list(config["methods"])


def R(scene, *parts):
    """A path under results/<scene>/."""
    return str(Path(RESULTS, scene, *parts))


def capture_dir(scene):
    return R(scene, "capture")


def truth_dir(scene):
    """Folder holding truth/ (a synthetic capture, or the row's truth path)."""
    value = row(scene)["truth"]
    return capture_dir(scene) if value == "yes" else value


def dataset_dir(scene):
    """The scene dataset every model rule reads."""
    kind = source(scene)
    if kind == "dataset":
        return row(scene)["path"]
    if kind == "synthetic" and not estimates_poses(scene):
        return R(scene, "truth_dataset")
    return R(scene, "dataset")


def dataset_input(wildcards):
    """The dataset plus, for a ready dataset, the marker of its validation."""
    scene = wildcards.scene
    files = {"data": dataset_dir(scene)}
    if source(scene) == "dataset":
        files["valid"] = R(scene, "dataset_valid.json")
    return files


def item_path(scene, column, in_capture):
    """Path of masks / key frames / names: inside the capture for 'yes' on synthetic, else the row's path."""
    value = row(scene)[column]
    if value == "yes":
        if source(scene) == "synthetic":
            return str(Path(capture_dir(scene), in_capture))
        raise WorkflowError(f"{config['scenes']}: scene {scene!r}, column {column!r}: 'yes' needs a synthetic or "
                            f"dataset source; for a {source(scene)} source write the path of the file or folder")
    return value


# --- the plan: which rules a scene needs, and why the others are left out ----------------------


def plan(scene):
    """Rule name -> (needed, reason). The report shows it; all_targets follows it."""
    kind, est = source(scene), estimates_poses(scene)
    made = kind != "dataset"
    p = {}
    p["capture"] = (kind == "synthetic", "synthetic spec" if kind == "synthetic" else f"source is {kind}")
    p["capture_dataset"] = (kind == "synthetic" and not est,
                            "poses given: dataset written from the capture truth" if kind == "synthetic" and not est
                            else "poses are estimated" if kind == "synthetic" else f"source is {kind}")
    p["frames"] = (made and est, "frames from the video" if made and est else "poses come with the data")
    p["poses"] = (made and est, "COLMAP poses" if made and est else "poses come with the data")
    p["pose_compare"] = (made and est and has_truth(scene),
                         "estimated poses vs truth" if made and est and has_truth(scene)
                         else "no truth" if not has_truth(scene) else "poses were not estimated")
    labels = made and est and carries(scene, "masks")
    p["labels"] = (labels, "masks given" if labels else "poses come with the data" if not (made and est)
                   else "scene has no masks")
    states = made and est and carries(scene, "key_frames")
    p["states"] = (states, "key frames given" if states else "poses come with the data" if not (made and est)
                   else "scene has no key frames")
    p["assemble"] = (made and est, "joins frames, poses, labels, states" if made and est
                     else "dataset comes ready" if kind == "dataset" else "dataset written from the capture truth")
    p["scene_validate"] = (kind == "dataset", "ready dataset checked against the contract" if kind == "dataset"
                           else "dataset written by this workflow (validated when written)")
    p["language_targets"] = (has_names(scene), "object names given" if has_names(scene) else "scene has no names")
    for m in METHODS:
        chosen = m in methods(scene)
        p[f"train[{m}]"] = (chosen, "listed for this scene" if chosen else "method not listed for this scene")
        p[f"evaluate[{m}]"] = (chosen, ("with truth (unseen combinations)" if has_truth(scene) else
                                        "held-out views only: no truth") if chosen else "method not trained")
    for m in methods(scene):
        sweep = m in config["report"]["sweep_methods"]
        p[f"sweep[{m}]"] = (sweep, "state sweeps for the sliders" if sweep else "not in report.sweep_methods")
        control = sweep and has_names(scene)
        p[f"control[{m}]"] = (control, "language commands" if control
                              else "scene has no names" if not has_names(scene) else "not in report.sweep_methods")
    p["stability"] = (config["stability"]["run"], "stability suite (once for all scenes)"
                      if config["stability"]["run"] else "stability.run is false")
    return p


def needed(scene, rule_name):
    return plan(scene)[rule_name][0]


def scene_outputs(scene):
    """Everything the scene's report page reads, following the plan."""
    out = {}
    if needed(scene, "capture"):
        out["capture"] = capture_dir(scene)
    if needed(scene, "poses"):
        out["poses"] = R(scene, "poses")
    if needed(scene, "pose_compare"):
        out["pose_error"] = R(scene, "pose_error.json")
    if needed(scene, "labels"):
        out["labels"] = R(scene, "labels")
    if needed(scene, "states"):
        out["states"] = R(scene, "states")
    out.update({f"dataset_{k}": v for k, v in dataset_input(type("W", (), {"scene": scene})).items()})
    if needed(scene, "language_targets"):
        out["targets"] = R(scene, "language", "targets.npz")
    for m in methods(scene):
        out[f"run_{m}"] = R(scene, "runs", m, "run.json")
        out[f"eval_{m}"] = R(scene, "eval", m)
        if needed(scene, f"sweep[{m}]"):
            out[f"sweep_{m}"] = R(scene, "sweep", m)
        if needed(scene, f"control[{m}]"):
            out[f"control_{m}"] = R(scene, "control", m)
    if config["stability"]["run"]:
        out["stability"] = str(Path(RESULTS, "stability", "summary.json"))
    return out


def all_targets():
    """Final outputs: the index page (which pulls in every scene page and all it needs)."""
    return [str(Path(REPORTS, "index.html"))]


def log_path(name):
    return str(Path(RESULTS, "{scene}", "logs", f"{name}.log"))


def bench_path(name):
    return str(Path(RESULTS, "{scene}", "benchmarks", f"{name}.tsv"))


# --- input functions and parameters of the stage rules ------------------------------------


def evaluate_input(wildcards):
    scene = wildcards.scene
    files = dataset_input(wildcards)
    files["run"] = R(scene, "runs", wildcards.method, "run.json")
    if has_truth(scene):
        files["truth"] = truth_dir(scene)
        if needed(scene, "pose_compare"):
            files["pose_error"] = R(scene, "pose_error.json")
    return files


def run_folder(wildcards, input):
    """The run folder of a run.json input (the trainer writes run.json last: it marks a finished run)."""
    return str(Path(input.run).parent)


def evaluate_args(wildcards, input):
    keys = input.keys()
    args = []
    if "truth" in keys:
        args.append(f"--truth {input.truth}")
    if "pose_error" in keys:
        args.append(f"--pose-alignment {input.pose_error}")
    if not has_names(wildcards.scene):
        args.append("--no-grounding")
    return " ".join(args)


def frames_input(wildcards):
    """A synthetic scene's capture folder, or the row's video / image folder."""
    scene = wildcards.scene
    return capture_dir(scene) if source(scene) == "synthetic" else row(scene)["path"]


def frames_video(wildcards, input):
    return str(Path(input[0], "video.mp4")) if source(wildcards.scene) == "synthetic" else input[0]


def labels_input(wildcards):
    scene = wildcards.scene
    files = {"frames": R(scene, "frames")}
    if source(scene) == "synthetic":
        files["capture"] = capture_dir(scene)
    else:
        files["masks"] = row(scene)["masks"]
        if carries(scene, "names"):
            files["names"] = row(scene)["names"]
    return files


def labels_args(wildcards, input):
    if "capture" in input.keys():
        return f"--input {Path(input.capture, 'masks')} --mapping {Path(input.capture, 'mapping.yaml')}"
    names = f" --mapping {input.names}" if "names" in input.keys() else ""
    return f"--input {input.masks}{names}"


def control_commands(wildcards):
    return config["commands"]


def train_input(wildcards):
    files = dataset_input(wildcards)
    if wildcards.method == "livescene" and has_names(wildcards.scene):
        files["targets"] = R(wildcards.scene, "language", "targets.npz")
    return files


def train_args(wildcards, input):
    args = []
    if "targets" in input.keys():
        args.append(f"--language-targets {input.targets}")
    # Without key frames a scene has no per-frame states to give: LiveScene learns them.
    if not carries(wildcards.scene, "key_frames"):
        args.append("--state-mode learned")
    return " ".join(args)


def poses_input(wildcards):
    scene = wildcards.scene
    files = {"frames": R(scene, "frames")}
    if source(scene) == "synthetic":
        files["capture"] = capture_dir(scene)
    elif carries(scene, "masks") and Path(row(scene)["masks"]).is_dir():
        files["masks"] = row(scene)["masks"]
    return files


def poses_masks(wildcards, input):
    """PNG id maps that keep SIFT features off the moving objects (when the scene has them as a folder)."""
    if "capture" in input.keys():
        return f"--masks {Path(input.capture, 'masks')}"
    return f"--masks {input.masks}" if "masks" in input.keys() else ""


def assemble_input(wildcards):
    scene = wildcards.scene
    files = {"frames": R(scene, "frames"), "poses": R(scene, "poses")}
    if needed(scene, "labels"):
        files["labels"] = R(scene, "labels")
    if needed(scene, "states"):
        files["states"] = R(scene, "states")
    if source(scene) == "synthetic":
        files["capture"] = capture_dir(scene)
    return files


def assemble_args(wildcards, input):
    keys = input.keys()
    args = [f"--{k} {input[k]}" for k in ("labels", "states") if k in keys]
    if "capture" in keys:
        args.append(f"--prompts {Path(input.capture, 'prompts.yaml')}")
    return " ".join(args)


def states_input(wildcards):
    scene = wildcards.scene
    files = {"frames": R(scene, "frames")}
    if source(scene) == "synthetic":
        files["capture"] = capture_dir(scene)
    else:
        files["key_frames"] = row(scene)["key_frames"]
        if carries(scene, "names"):
            files["names"] = row(scene)["names"]
    return files


def states_args(wildcards, input):
    if "capture" in input.keys():
        return (f"--key-frames {Path(input.capture, 'key_frame_value.yaml')}"
                f" --mapping {Path(input.capture, 'mapping.yaml')}")
    names = f" --mapping {input.names}" if "names" in input.keys() else ""
    return f"--key-frames {input.key_frames}{names}"
