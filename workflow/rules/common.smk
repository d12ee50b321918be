# Config and scene-sheet loading, schema validation and the input functions that decide per
# scene which rules it needs. Everything here runs at workflow start, before any job.
import json
import shlex
from pathlib import Path

import jsonschema
import pandas as pd
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

SCHEMAS = Path(workflow.current_basedir.get_path_or_uri(secret_free=True)).parent / "schemas"
# The method names, once for the workflow (tests/workflow/test_method_names.py holds them equal to the
# model stage's registry and to the scene sheet's pattern).
METHODS = yaml.safe_load((SCHEMAS / "config.schema.yaml").read_text())["properties"]["methods"]["items"]["enum"]


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


ITEM_COLUMNS = ("masks", "key_frames", "names", "prompts")


def _row_problems(record):
    """What the schema cannot say about one row: which values suit its source, and that paths exist."""
    kind, poses = record["source"], record.get("poses", "estimate")
    problems = []
    if not Path(record["path"]).exists():
        problems.append(f"column 'path': {record['path']!r} does not exist; fix: give the capture spec, video, "
                        "image folder or dataset folder")
    if kind == "dataset" and poses != "given":
        problems.append("column 'poses': a ready dataset carries its poses; write 'given'")
    if kind in ("video", "images") and poses == "given":
        problems.append(f"column 'poses': a {kind} source has no poses to give; write 'estimate', or "
                        "'colmap:<folder>' to import a COLMAP model")
    if poses.startswith("colmap:"):
        folder = poses.split(":", 1)[1]
        if kind != "images":
            problems.append(f"column 'poses': a COLMAP model is matched to an image folder by image name; the source "
                            f"is {kind}; fix: use source 'images' with the folder the model was made from, or "
                            "'estimate'")
        elif not Path(folder).is_dir():
            problems.append(f"column 'poses': COLMAP model folder {folder!r} does not exist; fix: give the folder "
                            "holding cameras/images/points3D (.bin or .txt), or one holding sparse/0")
    for column in ITEM_COLUMNS:
        value = record.get(column, "")
        if value == "yes" and kind in ("video", "images"):
            problems.append(f"column {column!r}: 'yes' means the source itself holds it (a synthetic capture or "
                            f"a ready dataset); for a {kind} source write 'no' or the path of the file or folder")
        elif value not in ("", "yes", "no") and not Path(value).exists():
            problems.append(f"column {column!r}: {value!r} does not exist; fix: give an existing file or folder, "
                            "or write 'no'")
    truth = record.get("truth", "no")
    if truth == "yes" and kind != "synthetic":
        problems.append(f"column 'truth': 'yes' means a synthetic capture's own truth; for a {kind} source write "
                        "'no' or the capture folder holding truth/transforms.json")
    elif truth not in ("yes", "no") and not Path(truth, "truth", "transforms.json").is_file():
        problems.append(f"column 'truth': {truth!r} is not 'yes', 'no' or a capture folder holding "
                        "truth/transforms.json; fix: write 'no' for a capture without truth, or the capture folder")
    return problems


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
        errors = list(jsonschema.Draft202012Validator(schema).iter_errors(record))
        for error in errors:
            problems.append(f"line {i + 2} (scene {name!r}): {_schema_problem(error)}")
        if not errors:
            problems += [f"line {i + 2} (scene {name!r}): {p}" for p in _row_problems(record)]
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


def _selected_scenes(sheet):
    """Scenes this run builds: config key 'only' (comma-separated, e.g. --config only=kitchen), else all."""
    wanted = [s for s in str(config.get("only") or "").split(",") if s]
    unknown = [s for s in wanted if s not in sheet.index]
    if unknown:
        raise WorkflowError(f"config key 'only': scene(s) {unknown} are not in the scene sheet {config['scenes']} "
                            f"(its scenes: {list(sheet.index)}); fix: name scenes of the sheet")
    return wanted or list(sheet.index)


_check_config(config)
scenes = _read_scene_sheet(config["scenes"])
SELECTED = _selected_scenes(scenes)
RESULTS = config["results"]
REPORTS = config["reports"]


wildcard_constraints:
    scene="|".join(scenes.index),
    method="|".join(METHODS),


def scene_pattern(keep):
    """Wildcard constraint matching the sheet's scenes for which keep(scene) holds (never matches if none)."""
    names = [s for s in scenes.index if keep(s)]
    return "|".join(names) if names else "(?!)"


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


def imported_model(scene):
    """The COLMAP model folder of a 'colmap:<folder>' poses cell, else None."""
    value = row(scene)["poses"]
    return value.split(":", 1)[1] if value.startswith("colmap:") else None


def from_frames(scene):
    """True when the dataset is assembled here from extracted frames (poses estimated or imported)."""
    return source(scene) != "dataset" and row(scene)["poses"] != "given"


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
    if kind == "synthetic" and not from_frames(scene):
        return R(scene, "truth_dataset")
    return R(scene, "dataset")


def dataset_files(scene):
    """The dataset plus, for a ready dataset, the marker of its validation."""
    files = {"data": dataset_dir(scene)}
    if source(scene) == "dataset":
        files["valid"] = R(scene, "dataset_valid.json")
    return files


def dataset_input(wildcards):
    return dataset_files(wildcards.scene)


def prompts_file(scene):
    """prompts.yaml of the scene's names (synonyms, descriptions), or None."""
    value = row(scene)["prompts"]
    if value == "no":
        return None
    if value in ("", "yes"):
        return str(Path(capture_dir(scene), "prompts.yaml")) if source(scene) == "synthetic" else None
    return value


# --- the plan: which rules a scene needs, and why the others are left out ----------------------


def plan(scene):
    """Rule name -> (needed, reason). The report shows it; all_targets follows it."""
    kind, est, model = source(scene), estimates_poses(scene), imported_model(scene)
    framed = from_frames(scene)
    given = "poses come with the data"
    p = {}
    p["capture"] = (kind == "synthetic", "synthetic spec" if kind == "synthetic" else f"source is {kind}")
    p["capture_dataset"] = (kind == "synthetic" and not framed,
                            "poses given: dataset written from the capture truth" if kind == "synthetic" and not framed
                            else "poses are estimated" if kind == "synthetic" else f"source is {kind}")
    p["frames"] = (framed, "frames from the video or image folder" if framed else given)
    p["poses"] = (framed and est, "COLMAP poses" if framed and est else
                  "COLMAP model given: imported instead" if model else given)
    p["poses_import"] = (model is not None, f"COLMAP model imported from {model} (no SfM)" if model
                         else "no COLMAP model given")
    p["pose_compare"] = (framed and has_truth(scene),
                         "estimated poses vs truth" if framed and has_truth(scene)
                         else "no truth" if not has_truth(scene) else "poses were not estimated")
    labels = framed and carries(scene, "masks")
    p["labels"] = (labels, "masks given" if labels else given if not framed else "scene has no masks")
    states = framed and carries(scene, "key_frames")
    p["states"] = (states, "key frames given" if states else given if not framed else "scene has no key frames")
    p["assemble"] = (framed, "joins frames, poses, labels, states" if framed
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
    if needed(scene, "poses") or needed(scene, "poses_import"):
        out["poses"] = R(scene, "poses")
    if needed(scene, "pose_compare"):
        out["pose_error"] = R(scene, "pose_error.json")
    if needed(scene, "labels"):
        out["labels"] = R(scene, "labels")
    if needed(scene, "states"):
        out["states"] = R(scene, "states")
    out.update({f"dataset_{k}": v for k, v in dataset_files(scene).items()})
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


def earlier_summaries(scene=None):
    """summary.json of the sheet's unselected scenes whose pages an earlier run wrote (or just that scene's)."""
    names = [scene] if scene else [s for s in scenes.index if s not in SELECTED]
    return [R(s, "report", "summary.json") for s in names
            if Path(R(s, "report", "summary.json")).is_file() and Path(REPORTS, "scenes", f"{s}.html").is_file()]


def pending_arg():
    """--pending of the index: the sheet's scenes with no page (not built now, nor by an earlier run)."""
    names = [s for s in scenes.index if s not in SELECTED and not earlier_summaries(s)]
    return f"--pending {shlex.quote(','.join(names))}" if names else ""


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
    elif prompts_file(scene) is not None and has_names(scene):
        files["prompts"] = prompts_file(scene)
    return files


def assemble_args(wildcards, input):
    keys = input.keys()
    args = [f"--{k} {input[k]}" for k in ("labels", "states") if k in keys]
    if "prompts" in keys:
        args.append(f"--prompts {input.prompts}")
    elif "capture" in keys and prompts_file(wildcards.scene) is not None and has_names(wildcards.scene):
        args.append(f"--prompts {prompts_file(wildcards.scene)}")  # inside the capture folder (an input)
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
