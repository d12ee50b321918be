# What each scene carries, and the plan: which rules it needs and why the others are left out (the
# report shows the plan; the input functions in common.smk and the targets follow it).


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
    return frames_assembled(source(scene), row(scene)["poses"])


def has_truth(scene):
    return carries(scene, "truth")


def is_static(scene):
    """True when nothing gives the room's objects: no masks and no key frames (it trains as a static field)."""
    return not carries(scene, "masks") and not carries(scene, "key_frames")


def tests_with_truth(scene):
    """True when the evaluation compares with the truth: unseen combinations and locality need objects."""
    return has_truth(scene) and not is_static(scene)


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


def orients_ready_dataset(scene):
    """True when a ready dataset is copied into the upright world (rule dataset_orient) before training."""
    return source(scene) == "dataset" and config["poses"]["orient"]


def dataset_dir(scene):
    """The scene dataset every model rule reads."""
    kind = source(scene)
    if orients_ready_dataset(scene):
        return R(scene, "dataset")
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
    p["labels"] = (labels, "masks given" if labels else "scene has no masks" if not carries(scene, "masks")
                   else given)
    states = framed and carries(scene, "key_frames")
    p["states"] = (states, "key frames given" if states else "scene has no key frames"
                   if not carries(scene, "key_frames") else given)
    p["assemble"] = (framed, "joins frames, poses, labels, states" if framed
                     else "dataset comes ready" if kind == "dataset" else "dataset written from the capture truth")
    p["dataset_orient"] = (orients_ready_dataset(scene),
                           "ready dataset turned upright (if its points show a floor)" if orients_ready_dataset(scene)
                           else "poses.orient is false" if kind == "dataset"
                           else "the poses stage orients the world" if framed else "truth poses are upright")
    p["scene_validate"] = (kind == "dataset", "ready dataset checked against the contract" if kind == "dataset"
                           else "dataset written by this workflow (validated when written)")
    appearance = config["train"]["appearance"]
    exposure = appearance in ("auto", "measured")
    p["exposure"] = (exposure, "frames' exposure measured once for every method (train.appearance: "
                     f"{appearance})" if exposure else f"train.appearance is {appearance}")
    # only LiveScene trains a language table (the baselines' grounding is read from their label fields)
    targets = has_names(scene) and "livescene" in methods(scene)
    p["language_targets"] = (targets, "object names given" if targets else "scene has no names"
                             if not has_names(scene) else "LiveScene is not trained for this scene")
    for m in METHODS:
        chosen = m in methods(scene)
        p[f"train[{m}]"] = (chosen, "listed for this scene" if chosen else "method not listed for this scene")
        p[f"evaluate[{m}]"] = (chosen, ("with truth (unseen combinations)" if tests_with_truth(scene) else
                                        "held-out views only: no objects to test against the truth"
                                        if has_truth(scene) else "held-out views only: no truth")
                               if chosen else "method not trained")
    for m in methods(scene):
        sweep = m in config["report"]["sweep_methods"]
        p[f"sweep[{m}]"] = (sweep, "state sweeps for the sliders" if sweep else "not in report.sweep_methods")
        control = sweep and has_names(scene)
        p[f"control[{m}]"] = (control, "language commands" if control
                              else "scene has no names" if not has_names(scene) else "not in report.sweep_methods")
        export = m in config["export"]["methods"]
        p[f"export[{m}]"] = (export, "meshes at " + " / ".join(config["export"]["states"]) if export
                             else "not in export.methods")
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
    if needed(scene, "frames"):
        out["frames"] = R(scene, "frames")
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
    if needed(scene, "exposure"):
        out["exposure"] = R(scene, "exposure.json")
    for m in methods(scene):
        out[f"run_{m}"] = R(scene, "runs", m, "run.json")
        out[f"eval_{m}"] = R(scene, "eval", m)
        if needed(scene, f"sweep[{m}]"):
            out[f"sweep_{m}"] = R(scene, "sweep", m)
        if needed(scene, f"control[{m}]"):
            out[f"control_{m}"] = R(scene, "control", m)
        if needed(scene, f"export[{m}]"):
            out[f"export_{m}"] = R(scene, "export", m)
    if config["stability"]["run"]:
        out["stability"] = str(Path(RESULTS, "stability", "summary.json"))
    return out


def all_targets():
    """Final outputs: the index page (which pulls in every scene page and all it needs), its verdicts.csv and
    digests.csv, and every file the selected scenes' pages read: Snakemake remakes a missing intermediate only when
    a consumer has to run, so a training killed on its own (a scheduler's SIGTERM, SIGKILL) left no run.json and a
    rerun said "Nothing to be done" over the previous model's pages; named here, a missing one is remade (and what
    reads it)."""
    outputs = [str(Path(REPORTS, name)) for name in ("index.html", "verdicts.csv", "digests.csv")]
    for scene in SELECTED:
        outputs += [str(v) for v in scene_outputs(scene).values() if str(v) not in outputs]
    return outputs


def earlier_summaries(scene=None):
    """summary.json of the sheet's unselected scenes whose pages an earlier run wrote (or just that scene's)."""
    names = [scene] if scene else [s for s in scenes.index if s not in SELECTED]
    return [R(s, "report", "summary.json") for s in names
            if Path(R(s, "report", "summary.json")).is_file() and Path(REPORTS, "scenes", f"{s}.html").is_file()]


def earlier_arg():
    """--earlier of the index: the summaries of the sheet's other scenes that an earlier run wrote a page for."""
    found = earlier_summaries()
    return " ".join(["--earlier", *(q(s) for s in found)]) if found else ""


def pending_arg():
    """--pending of the index: the sheet's scenes with no page (not built now, nor by an earlier run)."""
    names = [s for s in scenes.index if s not in SELECTED and not earlier_summaries(s)]
    return f"--pending {shlex.quote(','.join(names))}" if names else ""


def log_path(name):
    return str(Path(RESULTS, "{scene}", "logs", f"{name}.log"))


def bench_path(name):
    return str(Path(RESULTS, "{scene}", "benchmarks", f"{name}.tsv"))


def check_local_gpu(device):
    """Stop before the first job when the config asks for CUDA on a machine torch sees no GPU on: the trainings and
    renders would fail only after every CPU job of the selected scenes (COLMAP among them) had run."""
    import torch

    if not torch.cuda.is_available():
        raise WorkflowError(f"config device: {device}, but torch {torch.__version__} sees no GPU on this machine (the "
                            "trainings and renders would fail after every CPU job had run); fix: run on a machine "
                            "with a GPU, or leave config/gpu.yaml and the gpu profile out (the defaults train on the "
                            "CPU), or add --config device=cpu gpus=0")


def log_text(logfiles):
    """Snakemake's own log of this run (the ``log`` of onerror), as one text; a file it cannot read counts empty."""
    texts = []
    for name in logfiles or []:
        try:
            texts.append(Path(name).read_text(errors="replace"))
        except OSError:
            continue
    return "\n".join(texts)


def run_stopped(text):
    """Whether the run whose log ``text`` is was stopped (Ctrl-C, or SIGTERM: a user's or a cluster's cancel)
    rather than failed, from what Snakemake logs when it stops on request."""
    marks = ("Terminating processes on user request", "Will exit after finishing currently running jobs")
    return any(mark in text for mark in marks)


def failed_scenes(text):
    """The selected scenes of a run's failed jobs, read from Snakemake's own log ``text``: each error block names
    the failing job's log file, and a scene's job logs are <results>/<scene>/logs/."""
    import re

    # a job's start names its log too: only an error block's line ends with Snakemake's hint
    pattern = re.compile(rf"^\s+log: {re.escape(str(Path(RESULTS)))}/([^/\s]+)/logs/.*\(check log file", re.MULTILINE)
    return [s for s in dict.fromkeys(pattern.findall(text)) if s in SELECTED]
