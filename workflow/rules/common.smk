# Input functions and parameters of the stage rules, one per rule that needs them. They read the
# scene sheet (sheet.smk) and the plan (plan.smk); everything here runs at workflow start, before any job.


# --- input functions and parameters of the stage rules ------------------------------------


def named(**settings):
    """A rule's scalar settings with their names, as one param. Snakemake compares a job's params as a set of values
    without names, so a setting changed to the value another param has (max_views 1 -> 40 beside max_locality_pairs
    40) would rerun nothing; this one value changes with any of them."""
    return json.dumps(settings, sort_keys=True)


def q(path):
    """A path as one shell word (quoted only when it holds spaces or other shell characters, as Snakemake's :q)."""
    return shlex.quote(str(path))


def evaluate_input(wildcards):
    scene = wildcards.scene
    files = dataset_input(wildcards)
    files["run"] = R(scene, "runs", wildcards.method, "run.json")
    if tests_with_truth(scene):
        files["truth"] = truth_dir(scene)
        if needed(scene, "pose_compare"):
            files["pose_error"] = R(scene, "pose_error.json")
    return files


def capture_dataset_args(wildcards):
    """What the row leaves out of the dataset written from a synthetic capture's truth, as if it had been filmed
    without it: masks, key frames (and the frames' states)."""
    args = []
    if not carries(wildcards.scene, "masks"):
        args.append("--no-masks")
    if not carries(wildcards.scene, "key_frames"):
        args.append("--no-states")
    return " ".join(args)


def run_folder(wildcards, input):
    """The run folder of a run.json input (the trainer writes run.json last: it marks a finished run)."""
    return str(Path(input.run).parent)


def evaluate_args(wildcards):
    files = evaluate_input(wildcards)
    args = []
    if "truth" in files:
        args.append(f"--truth {q(files['truth'])}")
    if "pose_error" in files:
        args.append(f"--pose-alignment {q(files['pose_error'])}")
    if not has_names(wildcards.scene):
        args.append("--no-grounding")
    return " ".join(args)


def folder_files(path):
    """Every file under a folder of the user's (hidden ones left out), as extra inputs: Snakemake watches a folder
    input by its own time stamp only, which a mask or photo overwritten in place does not change."""
    folder = Path(path)
    if not folder.is_dir():
        return []
    return sorted(str(p) for p in folder.rglob("*")
                  if p.is_file() and not any(part.startswith(".") for part in p.relative_to(folder).parts))


def frames_input(wildcards):
    """A synthetic scene's capture folder, or the row's video / image folder (and the folder's files)."""
    scene = wildcards.scene
    if source(scene) == "synthetic":
        return {"source": capture_dir(scene)}
    return {"source": row(scene)["path"], "source_files": folder_files(row(scene)["path"])}


def frames_selection(wildcards):
    """--count / --max-side of config frames, and the scene's mask folder whose frames are kept first. A synthetic
    capture within both limits passes unchanged, so neither is named: changing a limit it does not reach reruns
    nothing (it had rerun COLMAP and every training for the same frames)."""
    c = config["frames"]
    count, max_side = c["count"], c["max_side"]
    scene = wildcards.scene
    if source(scene) == "synthetic":
        from stages.capture.spec import load_spec

        video = load_spec(row(scene)["path"]).video
        count = count if count and count < video.n_frames else 0
        max_side = max_side if max_side and max_side < max(video.width, video.height) else 0
    args = [f" --count {count}"] if count else []
    args += [f" --max-side {max_side}"] if max_side else []
    if source(scene) != "synthetic" and carries(scene, "masks"):  # a mask folder or file: its frames kept first
        args.append(f" --prefer-masked {shlex.quote(row(scene)['masks'])}")
    return "".join(args)


def frames_video(wildcards, input):
    return str(Path(input.source, "video.mp4")) if source(wildcards.scene) == "synthetic" else input.source


def labels_input(wildcards):
    scene = wildcards.scene
    files = {"frames": R(scene, "frames")}
    if source(scene) == "synthetic":
        files["capture"] = capture_dir(scene)
    else:
        files["masks"] = row(scene)["masks"]
        files["masks_files"] = folder_files(row(scene)["masks"])
        if carries(scene, "names"):
            files["names"] = row(scene)["names"]
    return files


def labels_args(wildcards):
    # named only when it is not the stage's own default, so the commands (and Snakemake's params trigger) of
    # existing results stay as they were
    policy = config["labels"]["missing_masks"]
    missing = "" if policy == "propagate" else f" --missing-masks {policy}"
    files = labels_input(wildcards)
    if "capture" in files:
        capture = files["capture"]
        return f"--input {q(Path(capture, 'masks'))} --mapping {q(Path(capture, 'mapping.yaml'))}{missing}"
    names = f" --mapping {q(files['names'])}" if "names" in files else ""
    return f"--input {q(files['masks'])}{names}{missing}"


def control_commands(wildcards):
    return config["commands"]


# the checkout holding workflow/ and config/: two levels above this file; relative, so a moved clone reruns nothing
MODEL_CONFIG_DIR = Path(os.path.relpath(Path(workflow.current_basedir).parents[1])) / "config" / "model"


def model_config_files(method):
    """The preset and the method's overlay on it (config/model/methods/): editing either retrains the method."""
    preset = str(config["preset"])
    files = {"preset": preset if preset.endswith((".yaml", ".yml")) else str(MODEL_CONFIG_DIR / f"{preset}.yaml")}
    overlay = MODEL_CONFIG_DIR / "methods" / f"{method}.yaml"
    if overlay.is_file():
        files["method_config"] = str(overlay)
    return files


def train_input(wildcards):
    files = dataset_input(wildcards) | model_config_files(wildcards.method)
    if wildcards.method == "livescene" and has_names(wildcards.scene):
        files["targets"] = R(wildcards.scene, "language", "targets.npz")
    if needed(wildcards.scene, "exposure"):
        files["exposure"] = R(wildcards.scene, "exposure.json")
    return files


def train_args(wildcards):
    files = train_input(wildcards)
    args = []
    if "targets" in files:
        args.append(f"--language-targets {q(files['targets'])}")
    # Without key frames a scene has no per-frame states to give: LiveScene learns them.
    if not carries(wildcards.scene, "key_frames"):
        args.append("--state-mode learned")
    # always named: a preset file of the user's that sets model.appearance.mode must not win over the workflow key
    args.append(f"--set model.appearance.mode={config['train']['appearance']}")
    if config["train"]["camera_opt"] != "off":  # named only when on: the default job's command stays as it was
        args.append(f"--camera-opt {config['train']['camera_opt']}")
    if "exposure" in files:  # measured once per scene (rule exposure), not once per method
        args.append(f"--exposure {q(files['exposure'])}")
    return " ".join(args)


def poses_input(wildcards):
    scene = wildcards.scene
    files = {"frames": R(scene, "frames")}
    if source(scene) == "synthetic":
        files["capture"] = capture_dir(scene)
    elif carries(scene, "masks") and (maps := id_map_folder(row(scene)["masks"])) is not None:
        files["masks"] = str(maps)
        files["masks_files"] = folder_files(maps)
    elif carries(scene, "masks"):
        # a COCO / LabelMe file or folder, or one folder of masks per object: COLMAP reads the labels stage's id
        # maps of it (docs/poses.md)
        files["labels"] = R(scene, "labels")
    return files


def id_map_folder(path):
    """The folder of per-frame id maps (PNG) or .npy masks that COLMAP reads as it is: ``path`` or its masks/
    subfolder, as the labels stage looks; None for anything else."""
    path = Path(path)
    folder = path / "masks" if (path / "masks").is_dir() else path
    if not folder.is_dir():
        return None
    has_maps = any(p.suffix.lower() in (".png", ".npy") and p.is_file() for p in folder.iterdir())
    return folder if has_maps else None


def poses_masks(wildcards):
    """Id maps that keep SIFT features off the moving objects: the capture's, the user's folder, or the labels
    stage's maps of a mask file."""
    files = poses_input(wildcards)
    if "capture" in files:  # a row filmed without masks gets none: the capture's truth masks are not the row's
        return f"--masks {q(Path(files['capture'], 'masks'))}" if carries(wildcards.scene, "masks") else ""
    if "labels" in files:
        return f"--masks {q(Path(files['labels'], 'masks'))}"
    return f"--masks {q(files['masks'])}" if "masks" in files else ""


def poses_args(wildcards):
    """The masks of ``poses_masks`` and the sheet's known focal length (column ``camera``: focal=PX or focal35=MM,
    ',refine' to let COLMAP refine it). One param, so that the shell text of a row without one stays as it was."""
    args = poses_masks(wildcards)
    camera = row(wildcards.scene).get("camera", "")
    if camera:
        kind, _, value = camera.partition("=")
        value, _, refine = value.partition(",")
        flag = "--focal" if kind == "focal" else "--focal-35mm"
        args += f" {flag} {value}" + (" --refine-focal" if refine else "")
    return args


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


def assemble_args(wildcards):
    files = assemble_input(wildcards)
    args = [f"--{k} {q(files[k])}" for k in ("labels", "states") if k in files]
    if "prompts" in files:
        args.append(f"--prompts {q(files['prompts'])}")
    elif "capture" in files and prompts_file(wildcards.scene) is not None and has_names(wildcards.scene):
        args.append(f"--prompts {q(prompts_file(wildcards.scene))}")  # inside the capture folder (an input)
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


def states_args(wildcards):
    # the sheet's fixed ranges (OBJECT=LO,HI;...), one --range each; quoted: object names may hold spaces
    ranges = "".join(f" --range {shlex.quote(item.strip())}"
                     for item in row(wildcards.scene)["state_ranges"].split(";") if item.strip())
    files = states_input(wildcards)
    if "capture" in files:
        return (f"--key-frames {q(Path(files['capture'], 'key_frame_value.yaml'))}"
                f" --mapping {q(Path(files['capture'], 'mapping.yaml'))}{ranges}")
    names = f" --mapping {q(files['names'])}" if "names" in files else ""
    return f"--key-frames {q(files['key_frames'])}{names}{ranges}"


def report_scene_input(wildcards):
    """Everything the scene page reads: scene_outputs, plus the truth folder (its states check the interpolation)."""
    scene = wildcards.scene
    files = scene_outputs(scene)
    if has_truth(scene):
        files["truth"] = truth_dir(scene)
    return files


# rule input name -> role of the report inputs manifest (docs/workflow.md, "The report"); per-method inputs
# are named <prefix>_<method>
REPORT_ROLES = {"dataset_data": "dataset", "truth": "truth", "capture": "capture", "frames": "frames",
                "poses": "poses", "pose_error": "pose_error", "labels": "labels", "states": "states",
                "targets": "language", "exposure": "exposure", "stability": "stability"}
REPORT_METHOD_ROLES = {"run": "runs", "eval": "eval", "sweep": "sweep", "control": "control",
                       "export": "export"}


def report_manifest(wildcards, input):
    """JSON of `livescene report scene --inputs`: each role -> its path, taken from the rule's named inputs (a
    role whose rule the plan leaves out is absent), plus the benchmark and log folders, which no rule outputs."""
    scene, names = wildcards.scene, input.keys()
    manifest = {role: input[key] for key, role in REPORT_ROLES.items() if key in names}
    for m in methods(scene):
        for prefix, role in REPORT_METHOD_ROLES.items():
            if f"{prefix}_{m}" in names:
                manifest.setdefault(role, {})[m] = input[f"{prefix}_{m}"]
    if "stability" in manifest:
        manifest["stability_benchmark"] = str(rules.stability.benchmark)
    manifest["benchmarks"] = R(scene, "benchmarks")
    manifest["logs"] = R(scene, "logs")
    return json.dumps(manifest)


def export_args(wildcards):
    c = config["export"]
    args = [f"--states {shlex.quote(s)}" for s in c["states"]]
    args += [f"--format {c['format']}", f"--views {c['views']}", f"--scale {c['scale']}"]
    # object parts come from the rendered object probabilities, which the mask losses train
    if carries(wildcards.scene, "masks"):
        args.append("--objects")
    return " ".join(args)
