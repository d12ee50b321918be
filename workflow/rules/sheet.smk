# The workflow config and the scene sheet: loaded and validated at workflow start (errors name the
# file, the line and the column), and the scenes this run builds (config key 'only').
import csv
import json
import shlex
import sys
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


SCALAR_TYPES = {"integer": int, "number": (int, float), "boolean": bool}


def _from_command_line(cfg, schema):
    """Typed values for the scalars that `--config` gave as text: Snakemake reads a nested value
    (`--config train='{steps: 3000}'`) with YAML's base loader, so 3000 arrives as '3000'. Only values of
    the command line are read again; a config file's quoted number stays an error."""
    given = dict(workflow.config_settings.config)  # overwrite_config holds the --configfile values too
    for error in list(jsonschema.Draft202012Validator(schema).iter_errors(cfg)):
        path = list(error.absolute_path)
        wanted = SCALAR_TYPES.get(error.validator_value) if error.validator == "type" else None
        node = given
        for key in path:
            node = node.get(key) if isinstance(node, dict) else None
        if wanted is None or not isinstance(error.instance, str) or node != error.instance:
            continue
        value = yaml.safe_load(error.instance)
        if isinstance(value, wanted) and not (wanted is not bool and isinstance(value, bool)):
            target = cfg
            for key in path[:-1]:
                target = target[key]
            target[path[-1]] = value


def _check_config(cfg):
    """Validate the merged config and fill its defaults; an error names the config file(s), every bad key and
    the expected type (snakemake's own message stops at the first)."""
    _from_command_line(cfg, yaml.safe_load((SCHEMAS / "config.schema.yaml").read_text()))
    try:
        validate(cfg, schema=str(SCHEMAS / "config.schema.yaml"), set_default=True)
    except WorkflowError:
        pass
    else:
        _check_preset(cfg["preset"])
        return
    schema = yaml.safe_load((SCHEMAS / "config.schema.yaml").read_text())
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(cfg), key=lambda e: list(e.absolute_path))
    files = [str(f) for f in workflow.configfiles] or ["config/config.yaml"]
    if workflow.config_settings.config:
        files.append("--config")
    lines = "\n".join(f"  - {_schema_problem(e)}" for e in errors)
    raise WorkflowError(f"invalid workflow config in {', '.join(files)}:\n{lines}\n"
                        f"fix: correct these keys (schema: {SCHEMAS / 'config.schema.yaml'})")


def _check_preset(preset):
    """A preset that names no file: Snakemake would drop the trainings it cannot feed and, with a report already
    built, say "Nothing to be done" (the typo silently ignored)."""
    from stages.model.config import preset_path
    from stages.scene import InputError

    try:
        preset_path(str(preset))
    except InputError as exc:
        files = [str(f) for f in workflow.configfiles] or ["config/config.yaml"]
        raise WorkflowError(f"invalid workflow config in {', '.join(files)}: key 'preset': {exc.problem}; "
                            f"fix: {exc.fix}") from None


ITEM_COLUMNS = ("masks", "key_frames", "names", "prompts")
SCENE_SCHEMA = yaml.safe_load((SCHEMAS / "scenes.schema.yaml").read_text())
"""The scene sheet's JSON schema (workflow/schemas/scenes.schema.yaml), read once."""
ITEM_DEFAULTS = {c: SCENE_SCHEMA["properties"][c].get("default", "") for c in ITEM_COLUMNS}
"""The schema's default of each item column: what an empty cell becomes once the sheet is read."""


def frames_assembled(kind, poses):
    """True when a scene's dataset is assembled here from extracted frames (poses estimated or imported), so
    labels and states come from the sheet's masks and key frames (the plan's ``from_frames``)."""
    return kind != "dataset" and poses != "given"


def _names_objects(mapping):
    """True when a dataset's mapping.yaml names at least one object (an unreadable one is scene_validate's to
    report, with its line)."""
    try:
        names = yaml.safe_load(mapping.read_text())
    except (OSError, yaml.YAMLError):  # missing or unreadable
        return False
    return isinstance(names, dict) and bool(names)


def _relative_note(value):
    """Where a relative path of the sheet was looked for: the folder snakemake runs in, not the sheet's."""
    return "" if Path(value).is_absolute() else f" (relative paths are read from {Path.cwd()}, where snakemake runs)"


def _row_problems(record):
    """What the schema cannot say about one row: which values suit its source, and that paths exist."""
    kind, poses = record["source"], record.get("poses", "estimate")
    problems = []
    if not Path(record["path"]).exists():
        problems.append(f"column 'path': {record['path']!r} does not exist{_relative_note(record['path'])}; fix: "
                        "give the capture spec, video, image folder or dataset folder")
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
        if kind in ("video", "images") and (value or ITEM_DEFAULTS[column]) == "yes":
            empty = "" if value else "is empty or absent, so it takes its default 'yes', which "
            problems.append(f"column {column!r}: {empty}'yes' means the source itself holds it (a synthetic capture "
                            f"or a ready dataset); for a {kind} source write 'no' or the path of the file or folder")
        elif value not in ("", "yes", "no") and not Path(value).exists():
            problems.append(f"column {column!r}: {value!r} does not exist{_relative_note(value)}; fix: give an "
                            "existing file or folder, or write 'no'")
    # masks make objects; their states come only from key frames (the states stage, or learned between key
    # frames): refused here rather than by the trainer after frames, COLMAP and labels have run
    if (frames_assembled(kind, poses) or kind == "synthetic") and record.get("masks", "yes") != "no" \
            and record.get("key_frames", "yes") == "no":
        problems.append("column 'key_frames': the masks make objects, but without key frames nothing gives their "
                        "states (docs/labels-states.md); fix: give the key-frame file (key_frame_value.yaml, "
                        "annotations.yml or CSV), or write 'no' in column 'masks' to train the room as a static field")
    # a ready dataset's objects are in its mapping.yaml; 'no' key frames trains them with learned states, which
    # only its key_frame_value.yaml supervises: refused here rather than by the trainer after validation
    root = Path(record["path"])
    if kind == "dataset" and record.get("key_frames", "yes") == "no" and not (root / "key_frame_value.yaml").is_file() \
            and _names_objects(root / "mapping.yaml"):
        problems.append(f"column 'key_frames': 'no' trains the dataset's objects ({root / 'mapping.yaml'}) with "
                        "learned states, which its key_frame_value.yaml supervises, and it has none; fix: write 'yes' "
                        "to train on the states its transforms.json gives every frame, or add key_frame_value.yaml")
    if record.get("state_ranges") and kind == "dataset":
        problems.append("column 'state_ranges': a ready dataset's key frames are normalised by the trainer, which "
                        f"reads fixed ranges from the dataset itself; fix: write them into {root / 'scene.json'} as "
                        "\"state_ranges\": {\"OBJECT\": [LO, HI]} (docs/data-contract.md, \"Key frames and the "
                        "time axis\") and leave the column empty")
    elif record.get("state_ranges") and not (frames_assembled(kind, poses) and record.get("key_frames", "yes") != "no"):
        problems.append("column 'state_ranges': only key frames that the states stage interpolates are normalised "
                        "(a video, image-folder or synthetic source with key frames and estimated or imported poses); "
                        "fix: leave it empty for this row")
    camera = record.get("camera", "")
    if camera and poses != "estimate":
        problems.append(f"column 'camera': {camera!r} is a focal length for COLMAP, which runs only for poses "
                        f"'estimate' (here {poses!r}); fix: leave it empty for this row")
    elif camera and not float(camera.split("=", 1)[1].split(",")[0]) > 0:
        problems.append(f"column 'camera': {camera!r} is not a positive focal length; fix: write e.g. focal35=26 "
                        "(35 mm-equivalent millimetres) or focal=1375 (pixels of the frames), or leave it empty")
    problems += _item_problems(record, kind, poses)
    truth = record.get("truth", "no")
    if truth == "yes" and kind != "synthetic":
        problems.append(f"column 'truth': 'yes' means a synthetic capture's own truth; for a {kind} source write "
                        "'no' or the capture folder holding truth/transforms.json")
    elif truth not in ("yes", "no") and not Path(truth, "truth", "transforms.json").is_file():
        problems.append(f"column 'truth': {truth!r} is not 'yes', 'no' or a capture folder holding "
                        "truth/transforms.json; fix: write 'no' for a capture without truth, or the capture folder")
    return problems


def _item_problems(record, kind, poses):
    """Rows whose items cannot go together, refused before frames and COLMAP run rather than by a stage after them."""
    problems = []
    masks, keys, names = (record.get(c, ITEM_DEFAULTS[c]) for c in ("masks", "key_frames", "names"))
    methods = [m.strip() for m in record.get("methods", ",".join(config["methods"])).split(",") if m.strip()]
    repeated = sorted({m for m in methods if methods.count(m) > 1})
    if repeated:
        problems.append(f"column 'methods': {', '.join(repeated)} listed more than once; fix: list each method once")
    if keys not in ("yes", "no") and Path(keys).is_dir():
        problems.append(f"column 'key_frames': {keys!r} is a folder; fix: give the key-frame file "
                        "(key_frame_value.yaml, annotations.yml or a CSV)")
    if kind == "dataset":  # a ready dataset's masks and prompts are files of it, which the rules read as they are
        if masks != "yes":
            problems.append(f"column 'masks': {masks!r}, but a ready dataset's masks are part of it (masks/); fix: "
                            "write 'yes', or remove masks/ from a copy of the dataset")
        prompts = record.get("prompts", "")
        if prompts not in ("", "yes", "no"):
            problems.append(f"column 'prompts': a ready dataset's prompts are its prompts.yaml, and {prompts!r} "
                            "would not be read; fix: copy it into the dataset folder as prompts.yaml and write 'yes'")
    if not frames_assembled(kind, poses) and kind != "synthetic":  # its dataset leaves out what the row does
        return problems
    needs_masks = sorted(set(methods) & {"livescene", "conerf"})
    if masks == "no" and keys != "no" and needs_masks:
        problems.append(f"column 'masks': 'no', but {needs_masks} learn which pixels each object drives from its "
                        "masks; fix: give the mask folder or file, or list only methods that train without masks "
                        "(mk-planes, mk-planes-star, k-planes) in column 'methods'")
    if masks == "no" and keys == "no" and names != "no":
        problems.append("column 'names': the row has neither masks nor key frames, so it trains as a static room "
                        "with no object to name; fix: write 'no'")
    if names == "no" and masks not in ("yes", "no") and Path(masks).is_dir() and not any(
            (Path(masks) / sub / f"mapping.{ext}").is_file() for sub in ("", "..") for ext in ("yaml", "yml")) \
            and not any(d.is_dir() and not d.name.startswith(".") for d in Path(masks).iterdir()):
        problems.append(f"column 'names': 'no', but the id maps of {masks!r} number their objects and no "
                        "mapping.yaml beside them names the numbers; fix: give the mapping.yaml ({id: name}) in "
                        "column 'names' (the names also turn on the language rules)")
    known = _mapping_names(names)  # read once for every item
    for item in (i.strip() for i in record.get("state_ranges", "").split(";") if i.strip()):
        name, _, bounds = item.partition("=")
        try:
            lo, hi = (float(b) for b in bounds.split(","))
        except ValueError:
            problems.append(f"column 'state_ranges': {item!r} is not OBJECT=LO,HI; fix: write e.g. fridge=0,110")
            continue
        if not lo < hi:
            problems.append(f"column 'state_ranges': {item!r} has LO {lo:g} not below HI {hi:g}; fix: write the "
                            "closed value first, e.g. fridge=0,110")
        if known is not None and name.strip() != "*" and name.strip() not in known:
            problems.append(f"column 'state_ranges': {name.strip()!r} is no object of {names!r} ({sorted(known)}); "
                            "fix: use the names of the mapping.yaml, or * for every object")
    return problems


def _mapping_names(names):
    """The object names a row's names file gives, or None when it gives none to check against."""
    if names in ("", "yes", "no"):
        return None
    try:
        data = yaml.safe_load(Path(names).read_text())
    except (OSError, yaml.YAMLError):
        return None
    return {str(v) for v in data.values()} if isinstance(data, dict) else None


def _sheet_table(sheet_path):
    """(DataFrame of str cells, the file line of each row, problems) of a tab-separated sheet.

    Only whole lines whose first cell starts with ``#`` are comments (a ``#`` inside a path is kept) and blank
    lines are skipped; a row with more cells than the header is a problem rather than a shift of its columns.
    """
    text = sheet_path.read_text(encoding="utf-8-sig")  # a spreadsheet's "CSV UTF-8" starts with a BOM
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1) if line.strip() and not line.startswith("#")]
    if not lines:
        raise WorkflowError(f"{sheet_path}: the scene sheet is empty; fix: write a tab-separated header line and "
                            "one row per scene (docs/workflow.md, 'The scene sheet')")
    (_, header_line), *body = lines
    header = next(csv.reader([header_line], delimiter="\t"))
    if len(header) == 1 and "," in header_line:
        raise WorkflowError(f"{sheet_path}: the header line has commas but no tab; the scene sheet is tab-separated; "
                            "fix: separate the cells with tabs (a spreadsheet's 'tab-separated values' export)")
    rows, numbers, problems = [], [], []
    for n, line in body:
        cells = next(csv.reader([line], delimiter="\t"))
        if len(cells) > len(header):
            problems.append(f"line {n}: {len(cells)} tab-separated cells but the header has {len(header)} "
                            f"columns {header}; fix: remove the extra cells, or name their column in the header")
            continue
        rows.append(cells + [""] * (len(header) - len(cells)))
        numbers.append(n)
    table = pd.DataFrame(rows, columns=header, dtype=str)
    if "methods" in table:  # "livescene, mk-planes", as one writes a list
        table["methods"] = table["methods"].str.replace(r"\s*,\s*", ",", regex=True).str.strip()
    return table, numbers, problems


def _read_scene_sheet(path):
    """Read and validate the scene sheet; errors name the file, the line, the scene and the column."""
    sheet_path = Path(path)
    if not sheet_path.is_file():
        hint = "" if "/" in str(path) or sheet_path.suffix else \
            f" (to build some scenes of the sheet, name them with --config only={path})"
        raise WorkflowError(f"{sheet_path}: the scene sheet does not exist; fix: write it (see docs/workflow.md) "
                            f"or point config key 'scenes' at it{hint}")
    sheet, numbers, problems = _sheet_table(sheet_path)
    schema = SCENE_SCHEMA
    unknown_columns = [c for c in sheet.columns if c not in schema["properties"]]
    if unknown_columns:
        problems.append(f"header: unknown column(s) {unknown_columns}; known: {list(schema['properties'])}")
    wanted = _wanted_scenes()
    left_out = []  # rows not selected by 'only' whose cells are wrong: they cannot hold up the rows asked for
    for line, row in zip(numbers, sheet.to_dict("records")):
        record = {k: v for k, v in row.items() if v != "" and k in schema["properties"]}
        name = row.get("scene") or f"line {line}"
        errors = list(jsonschema.Draft202012Validator(schema).iter_errors(record))
        found = [f"line {line} (scene {name!r}): {_schema_problem(error)}" for error in errors]
        if not errors:
            found += [f"line {line} (scene {name!r}): {p}" for p in _row_problems(record)]
        if found and wanted and row.get("scene") not in wanted and not unknown_columns:
            left_out.append((line, found))
        else:
            problems += found
    if "scene" in sheet:
        for name in sheet["scene"][sheet["scene"].duplicated()].unique():
            at = [str(n) for n, s in zip(numbers, sheet["scene"]) if s == name]
            problems.append(f"column 'scene': {name!r} names the rows of lines {', '.join(at)}; fix: give each row "
                            "its own scene name (results/<scene>/ and the report pages are named after it)")
    if sheet.empty:
        problems.append("no scene rows")
    if problems:
        lines = "\n".join(f"  - {p}" for p in problems)
        raise WorkflowError(f"invalid scene sheet {sheet_path}:\n{lines}\nfix: correct these cells "
                            f"(schema: {SCHEMAS / 'scenes.schema.yaml'})")
    for line, found in left_out:
        sys.stderr.write(f"warning: {sheet_path}: line {line} is left out of this run (not named by 'only'), its "
                         f"cells are wrong: {'; '.join(p.split(': ', 1)[1] for p in found)}\n")
    sheet = sheet[~sheet.index.isin([numbers.index(line) for line, _ in left_out])]
    # the schema's defaults fill empty cells and missing columns (snakemake skips empty, i.e. NaN, cells)
    sheet = sheet.replace("", float("nan"))
    validate(sheet, schema=str(SCHEMAS / "scenes.schema.yaml"), set_default=True)
    sheet = sheet.reindex(columns=list(schema["properties"])).fillna("")
    return sheet.set_index("scene", drop=False)


def _wanted_scenes():
    """The scenes config key 'only' names (comma-separated, spaces allowed), each once, in order."""
    return list(dict.fromkeys(s.strip() for s in str(config.get("only") or "").split(",") if s.strip()))


def _selected_scenes(sheet):
    """Scenes this run builds: config key 'only' (comma-separated, e.g. --config only=kitchen), else all."""
    wanted = _wanted_scenes()
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


