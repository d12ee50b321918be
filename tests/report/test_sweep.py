"""The slider images (``livescene report sweep``): each object's states 0..1 rendered at one held-out view, the
other objects held where the run renders that view, saved as RGB under file-safe names."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from stages.model import Trainer, load_config, load_run
from stages.model.run import LoadedRun
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES
from stages.report.sweep import render_sweeps, slug
from stages.scene import InputError, read_scene

TINY = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64",
    "train.warmup_steps=2",
    "train.eval_every=100",
    "train.eval_rays=64",
    "train.checkpoint_every=100",
    "train.render_chunk=256",
    "train.threads=1",
    "train.max_seconds=0",
    "train.max_steps=4",
]


def test_slug_keeps_names_file_safe():
    assert slug("Küchen schublade/2") == "Küchen-schublade-2"
    assert slug("door_1-a") == "door_1-a"
    assert slug("冷蔵庫") == "冷蔵庫"
    assert slug("../..") == "object"
    assert len(slug("x" * 300)) == 80


def test_every_object_gets_its_own_images_whatever_its_name(tiny_dataset, tmp_path, monkeypatch):
    """Names with no ASCII letter, names that differ in letter case only or in punctuation only: before, the two
    non-ASCII names were both 'object' and wrote each other's images, and so did the other pairs on a file
    system that ignores case."""
    names = ["冰箱", "шкаф", "Drawer", "drawer", "kid's drawer", "kid s drawer"]
    ds = tiny_dataset
    (ds.root / "mapping.yaml").write_text("".join(f"{i + 1}: {json.dumps(n)}\n" for i, n in enumerate(names)))

    class Stub:  # renders each object's state as its own grey level, so a file written twice is seen
        objects, state_mode, frame_ids = names, "given", []

        def render(self, camera, c2w, states, frame_index=None):
            k = [n for n in names if states[n] == 1.0 and base[n] != 1.0]
            return {"rgb": np.full((camera.height, camera.width, 3), (names.index(k[0]) + 1) / 10 if k else 0.0)}

    base = {n: 0.0 for n in names}
    monkeypatch.setattr("stages.model.load_run", lambda *a, **k: Stub())
    monkeypatch.setattr("stages.report.sweep.read_scene", lambda root: ds.__class__(
        **{**ds.__dict__, "objects": names, "object_ids": list(range(1, 7)),
           "frames": [dataclasses.replace(f, state=base) for f in ds.frames]}))
    summary = render_sweeps("run", ds.root, tmp_path / "sweep", steps=2, scale=1.0, progress=False)
    files = [summary["objects"][n]["images"][1] for n in names]
    assert len({f.casefold() for f in files}) == len(names), files
    assert files[0].startswith("冰箱") and files[1].startswith("шкаф")
    for i, f in enumerate(files):
        assert cv2.imread(str(tmp_path / "sweep" / f))[0, 0, 0] == int(255 * (i + 1) / 10 + 0.5), f


def test_each_object_is_swept_from_0_to_1_at_the_view(tiny_dataset, tmp_path, monkeypatch):
    run_dir = tmp_path / "run"
    Trainer(
        load_config("cpu-demo", TINY, data=str(tiny_dataset.root), seed=0), run_dir, device="cpu", progress=False
    ).train()
    for bad, message in (({"steps": 1}, "1 states cannot show a change"), ({"scale": 1.5}, "1.5 is not in")):
        with pytest.raises(InputError, match=message):
            render_sweeps(run_dir, tiny_dataset.root, tmp_path / "bad", progress=False, **{"steps": 3} | bad)
    asked = []  # the states of each render, in order (a 4-step run renders every state alike)
    render = LoadedRun.render

    def recording(self, camera, c2w, states=None, **kwargs):
        asked.append(dict(states))
        return render(self, camera, c2w, states, **kwargs)

    monkeypatch.setattr(LoadedRun, "render", recording)
    summary = render_sweeps(run_dir, tiny_dataset.root, tmp_path / "sweep", steps=3, scale=0.5, progress=False)
    assert summary == json.loads((tmp_path / "sweep" / "sweep.json").read_text()) | {"seconds": summary["seconds"]}
    assert summary["renders"] == 3 * 3 and (summary["width"], summary["height"]) == (8, 6)
    ds = read_scene(tiny_dataset.root)
    frame = ds.frames_in("test")[0]
    assert summary["frame"] == frame.frame_id
    monkeypatch.setattr(LoadedRun, "render", render)
    run = load_run(run_dir)
    camera, index = ds.camera_of(frame).scaled(0.5), ds.frames.index(frame)
    base = summary["base_state"]
    assert set(base) == set(run.objects)
    assert asked == [dict(base, **{name: v}) for name in run.objects for v in (0.0, 0.5, 1.0)]
    for name in run.objects:
        entry = summary["objects"][name]
        assert entry["values"] == [0.0, 0.5, 1.0]
        assert entry["images"] == [f"{name}_00.png", f"{name}_01.png", f"{name}_02.png"]
        for value, file in zip(entry["values"], entry["images"], strict=True):
            saved = cv2.imread(str(tmp_path / "sweep" / file))[..., ::-1]  # written as BGR, compared as RGB
            rgb = np.asarray(run.render(camera, frame.c2w, dict(base, **{name: value}), frame_index=index)["rgb"])
            assert np.abs(saved.astype(float) - rgb * 255).max() <= 1.0, (name, value)
