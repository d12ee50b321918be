"""Bad input at every stage boundary (group ``bad_input``): a clear message naming the file and the fix,
nothing on disk changed.

Each check builds a tiny valid input, breaks one thing, and calls the stage's
CLI ``main(argv)`` exactly as ``livescene <stage>`` does. It then checks the
exit status (2), that the message (``error: <file>: <problem>; fix: <fix>``)
names the broken file and carries a fix, and that every file under the check's
folder (inputs AND the outputs of an earlier good run in the same ``--out``)
is byte-identical to before: a refused run changes nothing on disk.

The frames, poses, labels and states CLIs are imported inside the checks that
call them: importing all of them (COLMAP, open3d, scipy) would cost seconds
on every ``livescene stability --list``. The check that dry-runs the workflow
copies the checkout named by ``--workflow`` (the ``ctx`` fixture), never this
package's surroundings: installed, the package has no repository around it.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from stages.model.train_cli import main as train_main
from stages.scene.cli import main as scene_main
from stages.stability.collector import Outcome

from .case_context import CaseContext
from .tiny_scenes import hand_built_dataset

pytestmark = pytest.mark.stability_group("bad_input")


# -- the refusal check ----------------------------------------------------------------------------------------


def snapshot(root: Path) -> dict[str, str]:
    """sha256 of every file under ``root`` (hidden temp files included), keyed by relative path."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def expect_refusal(main: Callable[[list[str]], int], argv: list[str], folder: Path, *names: str,
                   words: tuple[str, ...] = ()) -> str:
    """Run ``main(argv)``; require exit 2, an ``error:`` message naming every one of ``names`` (a file, a key)
    and ``words``, with a fix, and no change under ``folder``. Returns the message."""
    before = snapshot(folder)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse refusals exit by themselves
            rc = exc.code if isinstance(exc.code, int) else 1
    message = err.getvalue().strip()
    line = next((s for s in message.splitlines() if s.startswith("error:")), message)
    assert rc == 2, f"exit status {rc}, expected 2; stderr: {message[-300:]!r}"
    assert line.startswith("error:"), f"no 'error: ...' line on stderr: {message[-300:]!r}"
    for name in names:
        assert name in line, f"the message does not name {name!r}: {line!r}"
    for word in words:
        assert word.lower() in line.lower(), f"the message does not say {word!r}: {line!r}"
    assert "fix:" in line or ("; " in line and any(w in line.lower() for w in ("use", "pass", "write", "re-"))), (
        f"the message gives no fix: {line!r}")
    after = snapshot(folder)
    changed = sorted(k for k in before.keys() & after.keys() if before[k] != after[k])
    added, removed = sorted(after.keys() - before.keys()), sorted(before.keys() - after.keys())
    assert not (changed or added or removed), (
        f"a refused run changed the disk: changed {changed[:3]}, added {added[:3]}, removed {removed[:3]}")
    return line


def short(line: str, n: int = 110) -> str:
    """The message without the scratch-folder prefix of its paths, cut to ``n`` characters for the table."""
    line = re.sub(r"/\S*?/bad-[^/\s]+/", "", line)
    return line if len(line) <= n else line[: n - 3] + "..."


# -- tiny inputs ------------------------------------------------------------------------------------------------


def textured(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A blurred random texture with enough corners for SIFT."""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    return cv2.GaussianBlur(img, (3, 3), 0)


def write_video(path: Path, frames: list[np.ndarray], fps: float = 10.0) -> Path:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def moving_frames(n: int = 8, h: int = 48, w: int = 64) -> list[np.ndarray]:
    """A panning crop of a large texture: what a moving camera over a wall looks like."""
    big = textured(h, w + 4 * n)
    return [np.ascontiguousarray(big[:, 4 * i : 4 * i + w]) for i in range(n)]


@pytest.fixture(scope="module")
def frames_folder(ctx: CaseContext) -> Path:
    """A FRAMES folder (images/ + frames.csv) of 8 frames 64x48, extracted by `livescene frames` once per run."""
    from stages.frames.cli import main
    root = ctx.folder("bad-frames-src")
    video = write_video(root / "pan.mp4", moving_frames())
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["--video", str(video), "--out", str(root / "frames"), "--no-progress"])
    assert rc == 0, "`livescene frames` failed on a valid 8-frame video"
    return root / "frames"


def case_folder(ctx: CaseContext, name: str, frames: Path | None = None) -> Path:
    """A fresh folder ``bad-<name>`` (the table's messages are shown relative to it), with a copy of ``frames``."""
    root = ctx.folder(f"bad-{name}")
    if frames is not None:
        shutil.copytree(frames, root / "frames")
    return root


# -- video -> frames -----------------------------------------------------------------------------------------------


def test_bad_corrupt_video(ctx: CaseContext, frames_folder: Path, outcome: Outcome) -> None:
    """`livescene frames` on a file of random bytes named .mp4 exits 2 naming the video and a fix; an earlier
    frames output in --out is untouched (an mp4 whose first half is overwritten is also tried: what happens is
    recorded in the summary, not required)"""
    from stages.frames.cli import main
    root = case_folder(ctx, "corrupt-video")
    shutil.copytree(frames_folder, root / "out")  # a good earlier result that must survive
    rng = np.random.default_rng(0)
    noise = root / "noise.mp4"
    noise.write_bytes(rng.integers(0, 255, 20000, dtype=np.uint8).tobytes())
    line = expect_refusal(main, ["--video", str(noise), "--out", str(root / "out"), "--no-progress"], root,
                          str(noise))
    damaged = root / "damaged.mp4"
    data = bytearray(write_video(root / "good.mp4", moving_frames()).read_bytes())
    data[: len(data) // 2] = rng.integers(0, 255, len(data) // 2, dtype=np.uint8).tobytes()
    damaged.write_bytes(bytes(data))
    # observed, not required: ffmpeg decodes what it can of a damaged mp4, so the stage may accept a shorter clip
    before = snapshot(root / "out")
    with contextlib.redirect_stderr(io.StringIO()) as err, contextlib.redirect_stdout(io.StringIO()):
        rc = main(["--video", str(damaged), "--out", str(root / "scratch"), "--no-progress"])
    frames_json = root / "scratch" / "frames.json"
    decoded = json.loads(frames_json.read_text())["decoded_frame_count"] if rc == 0 and frames_json.is_file() else 0
    observed = (f"accepted, {decoded} of 8 frames decoded" if rc == 0 else
                f"refused (exit {rc}): {err.getvalue().strip()[-120:]}")
    assert snapshot(root / "out") == before, "the earlier frames output changed"
    outcome.record(short(line), {"damaged_header": observed})


def test_bad_zero_length_video(ctx: CaseContext, outcome: Outcome) -> None:
    """`livescene frames` on an empty (0-byte) file and on a video container with no frames exits 2 naming the
    file and a fix, and writes nothing"""
    from stages.frames.cli import main
    root = case_folder(ctx, "zero-video")
    empty = root / "empty.mp4"
    empty.write_bytes(b"")
    line = expect_refusal(main, ["--video", str(empty), "--out", str(root / "out"), "--no-progress"], root,
                          str(empty))
    no_frames = root / "no-frames.mp4"
    cv2.VideoWriter(str(no_frames), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (64, 48)).release()
    if no_frames.is_file():
        expect_refusal(main, ["--video", str(no_frames), "--out", str(root / "out"), "--no-progress"], root,
                       str(no_frames))
    outcome.record(short(line))


# -- frames -> poses -----------------------------------------------------------------------------------------------


def _frames_of(ctx: CaseContext, root: Path, images: list[np.ndarray]) -> Path:
    from stages.frames.cli import main
    video = write_video(root / "video.mp4", images)
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["--video", str(video), "--out", str(root / "frames"), "--no-progress"])
    assert rc == 0, "`livescene frames` failed on a valid video"
    return root / "frames"


def test_bad_static_camera_video(ctx: CaseContext, outcome: Outcome) -> None:
    """`livescene poses` on frames of a camera that never moves exits 2 with a message that says the camera does
    not move, names the frames and gives a fix; nothing is written"""
    from stages.poses.cli import main
    root = case_folder(ctx, "static-camera")
    still = textured(96, 128, seed=3)
    noise = np.random.default_rng(1)
    images = [np.clip(still.astype(int) + noise.integers(-2, 3, still.shape), 0, 255).astype(np.uint8)
              for _ in range(8)]
    frames = _frames_of(ctx, root, images)
    line = expect_refusal(main, ["--frames", str(frames), "--out", str(root / "poses"), "--threads", "1",
                                 "--no-progress"], root, str(frames))
    assert any(w in line.lower() for w in ("move", "static", "baseline", "parallax")), (
        f"the message does not say the camera did not move: {line!r}")
    outcome.record(short(line))


def test_bad_textureless_sequence(ctx: CaseContext, outcome: Outcome) -> None:
    """`livescene poses` on frames of a blank wall (no features) exits 2 naming the frames and a fix"""
    from stages.poses.cli import main
    root = case_folder(ctx, "textureless")
    images = [np.full((96, 128, 3), 128 + i, dtype=np.uint8) for i in range(8)]
    frames = _frames_of(ctx, root, images)
    line = expect_refusal(main, ["--frames", str(frames), "--out", str(root / "poses"), "--threads", "1",
                                 "--no-progress"], root, str(frames))
    outcome.record(short(line))


# -- masks -> labels -----------------------------------------------------------------------------------------------


def _frame_names(frames: Path) -> list[str]:
    return sorted(p.stem for p in (frames / "images").glob("*.png"))


def test_bad_masks_wrong_size(ctx: CaseContext, frames_folder: Path, outcome: Outcome) -> None:
    """`livescene labels` with masks of a size that is no integer factor of the frames exits 2 naming the mask
    file and a fix; a scene dataset holding a mask of the wrong size is refused by `livescene scene validate`
    and `livescene train` naming that mask"""
    from stages.labels.cli import main
    root = case_folder(ctx, "mask-size", frames_folder)
    frames = root / "frames"
    h, w = cv2.imread(str(next((frames / "images").glob("*.png")))).shape[:2]
    masks = root / "masks"
    masks.mkdir()
    for name in _frame_names(frames):
        ids = np.zeros((h - 5, w - 7), dtype=np.uint8)
        ids[5:15, 5:20] = 1
        cv2.imwrite(str(masks / f"{name}.png"), ids)
    (root / "mapping.yaml").write_text("1: door\n")
    first = masks / f"{_frame_names(frames)[0]}.png"
    line = expect_refusal(main, ["--input", str(masks), "--format", "png", "--mapping", str(root / "mapping.yaml"),
                                 "--frames", str(frames), "--out", str(root / "labels"), "--no-progress"], root,
                          first.name)
    # the same mistake inside a scene dataset: scene validate and train must refuse it too
    ds_root = ctx.folder("bad-mask-size-ds")
    ds = hand_built_dataset(ds_root / "ds", n_frames=4)
    bad = ds.root / "masks" / "00001.npy"
    np.save(bad, np.zeros((ds.camera.height - 2, ds.camera.width, ds.n_objects + 1), dtype=bool))
    line2 = _refused_by_validate_and_train(ds_root, bad)
    outcome.record(short(line), {"dataset": short(line2)})


def test_bad_mask_label_not_in_mapping(ctx: CaseContext, frames_folder: Path, outcome: Outcome) -> None:
    """`livescene labels` with an id map holding a value that mapping.yaml does not name exits 2 naming the mask
    and the mapping, and a fix; a dataset mask with a channel for an object mapping.yaml lacks is refused by
    `livescene scene validate` and `livescene train`"""
    from stages.labels.cli import main
    root = case_folder(ctx, "mask-label", frames_folder)
    frames = root / "frames"
    h, w = cv2.imread(str(next((frames / "images").glob("*.png")))).shape[:2]
    masks = root / "masks"
    masks.mkdir()
    names = _frame_names(frames)
    for k, name in enumerate(names):
        ids = np.zeros((h, w), dtype=np.uint8)
        ids[5:15, 5:20] = 1
        if k == 3:
            ids[20:30, 20:40] = 7  # no object 7 in mapping.yaml
        cv2.imwrite(str(masks / f"{name}.png"), ids)
    (root / "mapping.yaml").write_text("1: door\n2: drawer\n")
    line = expect_refusal(main, ["--input", str(masks), "--format", "png", "--mapping", str(root / "mapping.yaml"),
                                 "--frames", str(frames), "--out", str(root / "labels"), "--no-progress"], root,
                          f"{names[3]}.png", "mapping.yaml")
    # in a scene dataset: a mask with a channel for an object mapping.yaml does not name
    ds_root = ctx.folder("bad-mask-label-ds")
    ds = hand_built_dataset(ds_root / "ds", n_frames=4)
    bad = ds.root / "masks" / "00002.npy"
    np.save(bad, np.zeros((ds.camera.height, ds.camera.width, ds.n_objects + 2), dtype=bool))
    line2 = _refused_by_validate_and_train(ds_root, bad, "mapping.yaml")
    outcome.record(short(line), {"dataset": short(line2)})


# -- key frames -> states ------------------------------------------------------------------------------------------


def _states_case(ctx: CaseContext, frames_src: Path, name: str, key_text: str, suffix: str = ".yaml",
                 *names: str) -> tuple[str, Path]:
    from stages.states.cli import main
    root = case_folder(ctx, name, frames_src)
    good = root / "good_key_frames.yaml"
    frames = sorted((root / "frames" / "images").glob("*.png"))
    good.write_text(yaml.safe_dump({frames[0].stem: {"door": 0.0}, frames[-1].stem: {"door": 1.0}}))
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["--key-frames", str(good), "--frames", str(root / "frames"), "--out", str(root / "states")])
    assert rc == 0, "`livescene states` failed on valid key frames"
    bad = root / f"key_frames{suffix}"
    bad.write_text(key_text)
    line = expect_refusal(main, ["--key-frames", str(bad), "--frames", str(root / "frames"), "--out",
                                 str(root / "states")], root, str(bad), *names)
    return line, root


def test_bad_key_frame_nan(ctx: CaseContext, frames_folder: Path, outcome: Outcome) -> None:
    """`livescene states` with a NaN key-frame value exits 2 naming the key-frame file and a fix; the earlier
    states output is untouched"""
    line, _ = _states_case(ctx, frames_folder, "key-nan",
                           "frame_00000: {door: 0.0}\nframe_00003: {door: .nan}\nframe_00007: {door: 1.0}\n")
    outcome.record(short(line))


def test_bad_key_frame_conflict(ctx: CaseContext, frames_folder: Path, outcome: Outcome) -> None:
    """`livescene states` with one frame annotated twice with different values (YAML duplicate key, and CSV rows)
    exits 2 naming the file and a fix"""
    line, _ = _states_case(ctx, frames_folder, "key-dup", "frame_00000: {door: 0.0}\nframe_00004: {door: 0.2}\n"
                           "frame_00004: {door: 0.9}\nframe_00007: {door: 1.0}\n")
    line2, _ = _states_case(ctx, frames_folder, "key-dup-csv",
                            "frame,object,value\n0,door,0.0\n4,door,0.2\n4,door,0.9\n7,door,1.0\n", ".csv")
    outcome.record(short(line), {"csv": line2})


def test_bad_key_frame_missing_frame(ctx: CaseContext, frames_folder: Path, outcome: Outcome) -> None:
    """`livescene states` with a key frame on a frame that was not extracted exits 2 naming the file, the frame
    and a fix"""
    line, _ = _states_case(ctx, frames_folder, "key-missing",
                           "frame_00000: {door: 0.0}\nframe_00099: {door: 1.0}\n", ".yaml", "99")
    outcome.record(short(line))


# -- scene dataset -> scene validate / train --------------------------------------------------------------------


def _broken_dataset(ctx: CaseContext, name: str, edit: Callable[[dict], None]) -> tuple[Path, Path]:
    root = ctx.folder(f"bad-{name}")
    ds = hand_built_dataset(root / "ds", n_frames=4)
    tpath = ds.root / "transforms.json"
    data = json.loads(tpath.read_text())
    edit(data)
    tpath.write_text(json.dumps(data, allow_nan=True))
    return root, tpath


def _refused_by_validate_and_train(root: Path, tpath: Path, *names: str) -> str:
    """``tpath``: the broken file inside ``root/ds``; both commands must name it."""
    data = root / "ds"
    line = expect_refusal(scene_main, ["validate", str(data)], root, str(tpath), *names)
    expect_refusal(train_main, ["--data", str(data), "--out", str(root / "run"), "--max-steps", "1",
                                "--device", "cpu", "--no-progress"], root, str(tpath), *names)
    return line


def test_bad_transforms_missing_fields(ctx: CaseContext, outcome: Outcome) -> None:
    """a transforms.json frame without transform_matrix, and one without intrinsics, are refused by `livescene
    scene validate` and `livescene train` (exit 2, file and field named, a fix); no run folder appears"""
    root, tpath = _broken_dataset(ctx, "transforms-missing", lambda d: d["frames"][1].pop("transform_matrix"))
    line = _refused_by_validate_and_train(root, tpath, "transform_matrix")

    def no_intrinsics(d: dict) -> None:
        for key in ("fl_x", "fl_y"):
            d.pop(key)

    root2, tpath2 = _broken_dataset(ctx, "transforms-intrinsics", no_intrinsics)
    line2 = _refused_by_validate_and_train(root2, tpath2)
    outcome.record(short(line), {"no_intrinsics": line2})


def test_bad_transforms_nonfinite(ctx: CaseContext, outcome: Outcome) -> None:
    """a transforms.json matrix holding NaN or inf is refused by `livescene scene validate` and `livescene train`
    (exit 2, frame named, a fix)"""
    def poison(d: dict) -> None:
        d["frames"][2]["transform_matrix"][0][3] = float("nan")
        d["frames"][3]["transform_matrix"][1][3] = float("inf")

    root, tpath = _broken_dataset(ctx, "transforms-nan", poison)
    line = _refused_by_validate_and_train(root, tpath, "frame_00002")
    outcome.record(short(line))


# -- configuration -------------------------------------------------------------------------------------------------


def test_bad_config_wrong_type(ctx: CaseContext, outcome: Outcome) -> None:
    """a model preset with a key of the wrong type (train.batch_rays: lots) is refused by `livescene train`
    naming the preset file, the key and the expected type; nothing is written"""
    root = ctx.folder("bad-config-type")
    ds = hand_built_dataset(root / "ds", n_frames=4)
    preset = root / "my-preset.yaml"
    preset.write_text("train:\n  batch_rays: lots\n")
    line = expect_refusal(train_main, ["--data", str(ds.root), "--preset", str(preset), "--out", str(root / "run"),
                                       "--device", "cpu", "--no-progress"], root, str(preset), "batch_rays",
                          words=("int",))
    outcome.record(short(line))


def test_bad_workflow_config_wrong_type(ctx: CaseContext, outcome: Outcome) -> None:
    """`snakemake -n` with a config.yaml whose seed is a string stops before any job, naming the config file, the
    key and the expected type (workflow/schemas/config.schema.yaml)"""
    if ctx.workflow is None:
        pytest.skip("no workflow checkout to dry-run: pass `livescene stability --workflow PATH` (the folder holding "
                    "Snakefile, workflow/ and config/) to run this check")
    root = ctx.folder("bad-workflow-config")
    for part in ("Snakefile", "workflow", "config"):
        src = ctx.workflow / part
        if not src.exists():
            pytest.fail(f"{src} is missing")
        (shutil.copytree if src.is_dir() else shutil.copy2)(src, root / part)
    config = yaml.safe_load((ctx.workflow / "config" / "config.yaml").read_text()) or {}
    config["seed"] = "zero"
    bad = root / "config" / "bad-config.yaml"
    bad.write_text(yaml.safe_dump(config))
    before = snapshot(root)
    done = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--configfile", str(bad)],
                          cwd=root, capture_output=True, text=True, timeout=120)
    said = done.stdout + done.stderr
    assert done.returncode != 0, "snakemake accepted a config whose seed is a string"
    assert "seed" in said and "integer" in said, f"the error does not name the key and type: {said[-300:]!r}"
    after = {k: v for k, v in snapshot(root).items() if not k.startswith(".snakemake")}
    assert after == before, "a refused snakemake run changed files outside .snakemake/"
    assert "bad-config.yaml" in said, (
        "the error does not name the config file (bad-config.yaml): "
        f"{said.strip().splitlines()[:2]}")
    lines = [s.strip() for s in said.splitlines()]
    named = next((s for s in lines if "bad-config.yaml" in s), "")
    key = next((s for s in lines if "seed" in s), "")
    outcome.record(short(f"{named.replace(str(root) + '/', '')} {key}".strip(), 160))
