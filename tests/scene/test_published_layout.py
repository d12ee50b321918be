"""Datasets in the published LiveScene layout (OmniSim / InterReal): no split, no per-frame states, key frames in
the annotator's unit and keyed on frame numbers, frames in any order (docs/data-contract.md, "Key frames and the
time axis")."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
import torch
import yaml
from published_dataset import UNITS, published

from stages.model.fields.conerf_latent_states import FrameLatentStates
from stages.scene import SceneError, make_split, read_scene
from stages.scene.key_frame_states import frame_times, key_frame_states, match_key_frames
from stages.stability.checks.tiny_scenes import hand_built_dataset


def test_a_dataset_without_a_split_gets_the_references(tmp_path):
    ds = read_scene(published(tmp_path / "blender", blender=True))
    assert [f.split for f in ds.frames] == make_split(12, "alternate") and ds.split_note
    # nerfstudio form: nerfstudio's 90/10 over the frames sorted by name, whatever their order in the file
    ds = read_scene(published(tmp_path / "ns", n_frames=30, shuffle=True))
    held_out = sorted(int(f.frame_id) for f in ds.frames_in("test"))
    train = np.linspace(0, 29, math.ceil(30 * 0.9), dtype=int)  # nerfstudio's get_train_eval_split_fraction
    assert held_out == sorted(set(range(30)) - set(train.tolist())) == [9, 19, 28]


def test_a_split_in_the_file_is_kept(tiny_dataset):
    ds = read_scene(tiny_dataset.root)
    assert ds.split_note is None and [f.split for f in ds.frames] == [f.split for f in tiny_dataset.frames]


def test_published_key_values_are_min_max_normalised_and_matched_by_number(tmp_path):
    root = published(tmp_path / "ds")
    ds = read_scene(root)
    keys = key_frame_states(ds)
    assert {o: (r["lo"], r["hi"]) for o, r in keys.rescaled.items()} == {
        o: (min(v[o] for v in ds.key_frames.values()), max(v[o] for v in ds.key_frames.values())) for o in UNITS}
    values = np.array([[v[o] for o in UNITS] for v in keys.by_frame.values()])
    assert values.min(axis=0).tolist() == [0.0, 0.0] and values.max(axis=0).tolist() == [1.0, 1.0]
    # the keys say frame_0, frame_3, ...: the images are frame_00000, frame_00003 (the reference compares numbers)
    matched, unmatched = match_key_frames({"frame_3": {}, "frame_00006": {}, "frame_77": {}}, ds.frames)
    assert {k: ds.frames[i].frame_id for k, i in matched.items()} == {"frame_3": "00003", "frame_00006": "00006"}
    assert unmatched == ["frame_77"]


def test_key_frames_of_a_dataset_with_states_are_kept_as_given(tmp_path):
    ds = hand_built_dataset(tmp_path / "ds", n_frames=6)
    path = ds.root / "key_frame_value.yaml"
    path.write_text(yaml.safe_dump({"frame_00000": {"object0": 0.0}, "frame_00003": {"object0": 0.03}}))
    keys = key_frame_states(read_scene(ds.root))
    # a shut door annotated with a little noise stays shut (min-max would make 0.03 fully open)
    assert keys.rescaled == {} and keys.by_frame[3]["object0"] == 0.03


def test_scene_json_state_ranges_fix_the_range(tmp_path):
    root = published(tmp_path / "ds")
    (root / "scene.json").write_text(json.dumps({"state_ranges": {"object0": [0, 180]}}))
    keys = key_frame_states(read_scene(root))
    assert keys.ranges["object0"]["source"] == "scene.json state_ranges"
    assert max(v["object0"] for v in keys.by_frame.values()) <= 0.5
    (root / "scene.json").write_text(json.dumps({"state_ranges": {"object0": [0, 10]}}))
    with pytest.raises(SceneError, match="outside its range"):
        read_scene(root)


def test_one_value_outside_the_unit_range_on_every_key_frame_is_named(tmp_path):
    root = published(tmp_path / "ds", keys={"frame_00000": {"object0": 90.0}, "frame_00003": {"object0": 90.0}})
    with pytest.raises(SceneError, match=r"single value 90\.0") as err:
        read_scene(root)
    assert "state_ranges" in str(err.value)


def test_a_key_frame_on_an_unposed_image_is_left_out_and_a_typo_refused(tmp_path):
    root = published(tmp_path / "ds")
    tpath = root / "transforms.json"
    data = json.loads(tpath.read_text())
    data["frames"] = [f for f in data["frames"] if not f["file_path"].endswith("frame_00003.png")]
    tpath.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="no pose for"):
        ds = read_scene(root)
    assert 3 not in {int(ds.frames[i].frame_id) for i in key_frame_states(ds).by_frame}
    keys = yaml.safe_load((root / "key_frame_value.yaml").read_text())
    (root / "key_frame_value.yaml").write_text(yaml.safe_dump(keys | {"frame_00099": {"object0": 1.0}}))
    with warnings.catch_warnings(), pytest.raises(SceneError, match="frame id '00099' matches no frame"):
        warnings.simplefilter("ignore")
        read_scene(root)


def test_frame_times_follow_the_frame_numbers_not_the_file_order(tmp_path):
    ordered = read_scene(published(tmp_path / "a"))
    shuffled = read_scene(published(tmp_path / "b", shuffle=True))
    t_a = dict(zip([f.frame_id for f in ordered.frames], frame_times(ordered.frames), strict=True))
    t_b = dict(zip([f.frame_id for f in shuffled.frames], frame_times(shuffled.frames), strict=True))
    assert t_a == t_b
    assert np.array_equal(frame_times(ordered.frames), np.linspace(0.0, 1.0, 12))  # bit for bit: earlier runs'
    # a video's frames keep their spacing in time (every frame of 0..9 but 1..4 dropped)
    for f, src in zip(ordered.frames, [0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 20], strict=True):
        f.source_index = src
    assert frame_times(ordered.frames)[1] == pytest.approx(0.25)


def test_conerf_latents_are_looked_up_by_the_frames_times():
    times = [0.0, 0.25, 0.3, 1.0]
    states = FrameLatentStates(4, 2, 8, 16, frame_times=times)
    assert states.frame_index(torch.tensor([0.0, 0.26, 0.31, 0.99])).tolist() == [0, 1, 2, 3]
    assert "times" not in states.state_dict()  # the run's SceneInfo holds them



def test_a_key_frame_only_dataset_gives_its_training_states_at_the_key_frames(tmp_path):
    """What a learned run was told: the unseen test's seen states, control's and the sliders' training ranges."""
    ds = read_scene(published(tmp_path / "ds"))
    matrix = ds.state_matrix()
    keyed = {ds.frames[i].frame_id for i in key_frame_states(ds).by_frame}
    rows = {f.frame_id: row for f, row in zip(ds.frames, matrix, strict=True)}
    assert all(np.isfinite(rows[fid]).all() for fid in keyed)
    assert all(np.isnan(row).all() for fid, row in rows.items() if fid not in keyed)
    assert ds.state_ranges(ds.frames) == {"object0": [0.0, 1.0], "object1": [0.0, 1.0]}  # normalised, not units


def test_the_truth_is_not_compared_with_a_run_on_rescaled_key_values(tmp_path):
    from stages.evaluate.evaluation import Evaluator

    rescaled = Evaluator(object(), read_scene(published(tmp_path / "units")))
    assert rescaled._other_scale().startswith("skipped: the dataset's key values were mapped to [0, 1]")
    keys = {"frame_00000": {"object0": 0.0, "object1": 0.0}, "frame_00006": {"object0": 1.0, "object1": 1.0}}
    assert Evaluator(object(), read_scene(published(tmp_path / "unit", keys=keys)))._other_scale() is None


def test_masks_as_downloads_save_them_are_read_or_refused_with_the_fix(tmp_path):
    """uint8 0/1 masks read as the bool ones; channels first (C, H, W) and masks named by number but not by the
    images' zero-padded id are refused, each naming the file and the fix (docs/data-contract.md)."""
    root = published(tmp_path / "ds")
    ds = read_scene(root)
    frame = ds.frames[0]
    path = root / "masks" / f"{frame.frame_id}.npy"
    own = np.load(path)
    assert own.shape == (18, 24, 3) and own.dtype == bool
    np.save(path, own.astype(np.uint8))
    assert np.array_equal(read_scene(root).load_mask(frame), own)

    np.save(path, np.moveaxis(own, -1, 0))  # (3, 18, 24)
    with pytest.raises(SceneError, match=r"3 x 18 x 24: channels first.*np\.moveaxis") as err:
        read_scene(root)
    assert str(path) in str(err.value)
    np.save(path, own)

    path.rename(root / "masks" / "0.npy")  # the image is frame_00000
    with pytest.raises(SceneError, match=r"has no mask, but 0\.npy carries the frame's number.*0\.npy -> 00000\.npy"):
        read_scene(root)
    with pytest.raises(SceneError, match=r"0\.npy -> 00000\.npy"):
        ds.load_mask(frame)


def test_a_frame_is_found_by_its_number_padded_otherwise(tmp_path):
    """`render --pose DS:7`, `control --frame 7`: the one frame whose id is 7 padded otherwise (00007), as key frames
    pair with frames; an id no frame has, by any padding, is refused with the ids there are."""
    ds = hand_built_dataset(tmp_path / "ds", n_frames=8)
    assert [f.frame_id for f in ds.frames][:2] == ["00000", "00001"]
    assert ds.frame_by_id("00007").frame_id == "00007"
    assert ds.frame_by_id("7").frame_id == "00007" and ds.frame_by_id("0007").frame_id == "00007"
    with pytest.raises(SceneError, match=r"no frame with id '8'.*pick one of the dataset's frame ids: 00000"):
        ds.frame_by_id("8")
