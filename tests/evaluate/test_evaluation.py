"""Evaluation logic on a fake run whose errors are known (see conftest.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from evaluate_fakes import ERROR, FRIDGE_COLS, FakeRun, H, SlidingTruthRenderer, TruthRun, make_eval_dataset
from tiny_language_run import BagOfWordsEncoder

from stages.evaluate import EvaluateConfig, TruthSource, evaluate_run, read_sim3
from stages.evaluate import cli as evaluate_cli
from stages.evaluate.locality import locality
from stages.language import Grounder, ObjectVocabulary
from stages.scene import Frame, InputError, apply_similarity_to_pose

# error +-0.1 on the fridge's 6 of 16 columns, none elsewhere
HELD_OUT_PSNR = 10 * math.log10(1 / (ERROR**2 * 6 / 16))


def _grounder(ds):
    return Grounder(ObjectVocabulary.from_prompts(ds.objects, ds.prompts), BagOfWordsEncoder())


def test_evaluate_run_on_a_fake_run(eval_scene, tmp_path):
    ds, run, truth = eval_scene
    out = tmp_path / "eval"
    metrics = evaluate_run(run, ds, out, truth, _grounder(ds), EvaluateConfig(unseen_views=2))

    held = metrics["held_out"]
    assert [v["frame"] for v in held["views"]] == ["00000", "00002", "00004", "00006"]  # split == test only
    for v in held["views"]:
        assert v["psnr"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
        assert 0 < v["ssim"] < 1
    assert held["psnr"]["mean"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
    assert held["psnr"]["std"] == pytest.approx(0.0, abs=1e-9)
    # the error lies on the fridge, half of the object pixels; static pixels are exact (infinite PSNR: None)
    assert held["region_source"] == "dataset masks"
    for v in held["views"]:
        assert v["psnr_objects"] == pytest.approx(10 * math.log10(1 / (ERROR**2 * 6 / 12)), abs=1e-6)
        assert v["psnr_static"] is None
    assert held["psnr_objects"]["n"] == 4 and held["psnr_static"]["n"] == 0
    # how opaque the objects are, apart from the room: the report's trust check on objects painted behind them
    assert held["accumulation_objects"]["mean"] == pytest.approx(0.4) and held["accumulation_objects"]["n"] == 4
    assert held["accumulation_static"]["mean"] == pytest.approx(0.9)
    assert held["image_size"] == [16, 12]
    assert held["lpips"] is None or held["lpips_status"].startswith("computed")
    # each held-out view was rendered at its own state and frame index
    assert (0, ds.frames[0].state) in run.rendered

    unseen = metrics["unseen_combinations"]
    assert unseen["status"] == "computed" and unseen["truth_pose_source"] == ["source_index"]
    records = unseen["records"]
    assert {r["frame"] for r in records} == {"00000", "00006"}
    assert unseen["n_unseen"] > 0
    for r in records:
        assert r["states"]["fridge"] != r["states"]["drawer"]  # never together on the training diagonal
        assert r["psnr"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
        moved = set(r["moved_objects"])
        if moved == {"fridge"}:
            assert r["psnr_moved"] == pytest.approx(20.0, abs=1e-6)
        elif moved == {"fridge", "drawer"}:
            assert r["psnr_moved"] == pytest.approx(10 * math.log10(1 / (ERROR**2 / 2)), abs=1e-6)
        elif moved == {"drawer"}:
            assert r["psnr_moved"] is None  # no error on the drawer: infinite PSNR is recorded as None
    assert any(set(r["moved_objects"]) == {"fridge", "drawer"} for r in records)

    ground = metrics["grounding"]
    assert ground["status"] == "computed" and ground["sources"] == ["probs"]
    queries = {q["query"]: q for q in ground["queries"]}
    assert set(queries) == {"fridge", "refrigerator", "drawer", "kitchen drawer"}
    assert {q["kind"] for q in ground["queries"]} == {"name", "synonym"}
    for q in queries.values():
        assert q["probs"]["iou"]["mean"] == pytest.approx(1.0)
        assert q["probs"]["iou"]["n"] == 4
    assert ground["miou_probs_name"] == pytest.approx(1.0) and ground["miou_probs_synonym"] == pytest.approx(1.0)

    timings = json.loads((out / "timings.json").read_text())
    assert timings["held_out"]["fps"] > 0 and timings["held_out"]["views"] == 4 and timings["seconds"] > 0
    parts = ("held_out", "unseen_combinations", "grounding", "locality")
    assert timings["seconds"] == pytest.approx(sum(timings[p]["seconds"] for p in parts), rel=1e-3, abs=1e-3)
    assert "fps" not in held and "render_seconds" not in held and "seconds" not in metrics
    written = json.loads((out / "metrics.json").read_text())
    assert written["held_out"]["psnr"]["mean"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
    assert sorted(p.name for p in (out / "renders").iterdir()) == ["00000.png", "00002.png", "00004.png",
                                                                    "00006.png"]
    assert any((out / "unseen").iterdir()) and any((out / "grounding").iterdir())


def test_miou_by_kind_averages_names_and_synonyms_apart(eval_scene, tmp_path):
    """A run whose probabilities leave the fridge's pixels to the background: the fridge's queries score IoU 0
    (an empty map against a 6-column mask), the drawer's 1. Only the fridge has a synonym here, so the names'
    mIoU is (0 + 1) / 2 and the synonyms' is 0; all three queries together average 1/3."""
    ds, run, _ = eval_scene

    class MissesTheFridge(type(run)):
        def render(self, camera, c2w, states, frame_index=None, outputs=None):
            out = super().render(camera, c2w, states, frame_index, outputs)
            probs = out["probs"].copy()
            probs[:, FRIDGE_COLS] = [0.0, 0.0, 1.0]  # background (last channel)
            return out | {"probs": probs}

    vocab = ObjectVocabulary.from_prompts(ds.objects, {"fridge": {"synonyms": ["refrigerator"]}})
    grounder = Grounder(vocab, BagOfWordsEncoder())
    ground = evaluate_run(MissesTheFridge(ds, run.truth), ds, tmp_path / "e", None, grounder,
                          EvaluateConfig(save_renders=False))["grounding"]
    q = {q["query"]: q for q in ground["queries"]}
    assert {k: (v["object"], v["kind"]) for k, v in q.items()} == {
        "fridge": ("fridge", "name"), "refrigerator": ("fridge", "synonym"), "drawer": ("drawer", "name")}
    assert q["fridge"]["probs"]["iou"]["mean"] == 0.0 and q["refrigerator"]["probs"]["iou"]["mean"] == 0.0
    assert q["drawer"]["probs"]["iou"]["mean"] == pytest.approx(1.0)
    assert ground["miou_probs_name"] == pytest.approx(0.5)
    assert ground["miou_probs_synonym"] == pytest.approx(0.0)
    assert ground["miou_probs"] == pytest.approx(1 / 3)


def test_a_synonym_two_objects_share_is_not_scored_as_one_of_them(eval_scene, tmp_path):
    """"cupboard" for two cupboards names neither: scored against one object's mask it read IoU 0 by construction
    (and pulled the room's grounding down); each object's first synonym of its own is scored instead."""
    ds, run, _ = eval_scene
    vocab = ObjectVocabulary.from_prompts(ds.objects, {"fridge": {"synonyms": ["appliance", "refrigerator"]},
                                                       "drawer": {"synonyms": ["appliance"]}})
    grounder = Grounder(vocab, BagOfWordsEncoder())
    metrics = evaluate_run(run, ds, tmp_path / "e", None, grounder, EvaluateConfig(save_renders=False))
    queries = {q["query"]: q["object"] for q in metrics["grounding"]["queries"]}
    assert queries == {"fridge": "fridge", "refrigerator": "fridge", "drawer": "drawer"}
    assert metrics["grounding"]["ambiguous_synonyms"] == ["appliance"]


def test_run_with_other_objects_is_refused(eval_scene, tmp_path):
    ds, run, _ = eval_scene
    run.objects = ["drawer", "fridge"]
    with pytest.raises(InputError, match="differ from the dataset's"):
        evaluate_run(run, ds, tmp_path / "e")
    assert not (tmp_path / "e").exists()


def test_truth_pose_through_the_similarity(tmp_path, eval_scene):
    ds, _, truth = eval_scene
    angle = 0.3
    sim3 = np.eye(4)
    sim3[:3, :3] = 2.5 * np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    sim3[:3, 3] = [1.0, -2.0, 0.5]
    true_c2w = ds.frames[3].c2w
    colmap_frame = Frame(file_path="images/frame_00099.png", c2w=apply_similarity_to_pose(sim3, true_c2w))
    aligned = TruthSource(renderer=truth.renderer, camera=truth.camera, object_ids=truth.object_ids,
                          poses=truth.poses, sim3=sim3, same_world=False)
    pose, how = aligned.pose_for(colmap_frame)
    assert how == "sim3"
    np.testing.assert_allclose(pose, true_c2w, atol=1e-9)
    moved = [Frame(file_path=f.file_path, c2w=apply_similarity_to_pose(sim3, f.c2w), source_index=f.source_index)
             for f in ds.frames]
    assert aligned.alignment_residual(moved)["mean_centre_error"] == pytest.approx(0.0, abs=1e-9)
    unaligned = TruthSource(renderer=truth.renderer, camera=truth.camera, object_ids={}, same_world=False)
    with pytest.raises(InputError, match="--pose-alignment"):
        unaligned.pose_for(colmap_frame)

    path = tmp_path / "pose_error.json"
    path.write_text(json.dumps({"sim3": sim3.tolist()}))
    np.testing.assert_allclose(read_sim3(path), sim3)
    path.write_text(json.dumps({"sim3": np.zeros((4, 4)).tolist()}))
    with pytest.raises(InputError, match="invertible"):
        read_sim3(path)


def test_truth_camera_follows_downscaled_datasets(eval_scene):
    _, _, truth = eval_scene
    big = TruthSource(renderer=truth.renderer, camera=truth.camera.scaled(2.0), object_ids={})
    cam = big.camera_for(16, 12)
    assert (cam.width, cam.height, cam.fx) == (16, 12, 20.0)
    with pytest.raises(InputError, match="not one scale factor"):
        big.camera_for(16, 10)


def test_cli_reports_missing_run_cleanly(tmp_path, capsys, eval_scene):
    ds, _, _ = eval_scene
    code = evaluate_cli.main(["--run", str(tmp_path / "no-run"), "--data", str(ds.root), "--out",
                              str(tmp_path / "e"), "--no-grounding"])
    assert code == 2
    assert "run folder not found" in capsys.readouterr().err


class _LanguageRun:
    """Wraps the fake run and adds a rendered language embedding: the object's name embedding per pixel."""

    def __init__(self, run, encoder, space):
        self.inner, self.objects, self.language_encoder = run, run.objects, space
        self.table = encoder.encode(["fridge", "drawer", "background"])

    def render(self, camera, c2w, states, frame_index=None):
        out = self.inner.render(camera, c2w, states, frame_index)
        out["language"] = self.table[out["probs"].argmax(-1)]
        return out


def test_grounding_from_rendered_language_only_in_the_same_space(eval_scene, tmp_path):
    ds, run, _ = eval_scene
    grounder = _grounder(ds)
    same = _LanguageRun(run, grounder.encoder, grounder.encoder.name)
    metrics = evaluate_run(same, ds, tmp_path / "a", None, grounder, EvaluateConfig(save_renders=False))
    ground = metrics["grounding"]
    assert ground["sources"] == ["probs", "language", "language_objects"]
    q = {q["query"]: q for q in ground["queries"]}
    assert q["fridge"]["language"]["iou"]["mean"] == pytest.approx(1.0)  # pixels carrying "fridge" exactly
    # decoded against the table phrases ("closed fridge", "open fridge", "background"): the fridge's pixels again
    assert q["refrigerator"]["language_objects"]["iou"]["mean"] == pytest.approx(1.0)
    assert 0.0 <= ground["miou_language"] <= 1.0

    other = _LanguageRun(run, grounder.encoder, "some other model")
    metrics = evaluate_run(other, ds, tmp_path / "b", None, grounder, EvaluateConfig(save_renders=False))
    assert metrics["grounding"]["sources"] == ["probs"]
    assert metrics["grounding"]["language_source"].startswith("skipped: run trained with encoder")


def test_a_map_on_the_other_objects_pixels_scores_zero_iou(eval_scene, tmp_path):
    """A run that confuses the fridge and the drawer: each one's probability and rendered language lie on the
    other's columns. The fridge's name then takes the fridge's probability (weight 1) and finds it on the drawer's
    6 columns, none on its own: IoU = 0 / 12 columns. The language map of "fridge" is over the pixels that carry
    the fridge's embedding (exactly them, as the correctly placed run shows), now the drawer's: IoU 0 too."""
    ds, run, _ = eval_scene
    grounder = _grounder(ds)

    class Confused(_LanguageRun):
        def render(self, camera, c2w, states, frame_index=None):
            out = self.inner.render(camera, c2w, states, frame_index)
            probs = out["probs"][..., [1, 0, 2]]
            return out | {"probs": probs, "language": self.table[probs.argmax(-1)]}

    right = evaluate_run(_LanguageRun(run, grounder.encoder, grounder.encoder.name), ds, tmp_path / "right", None,
                         grounder, EvaluateConfig(save_renders=False))["grounding"]
    wrong = evaluate_run(Confused(run, grounder.encoder, grounder.encoder.name), ds, tmp_path / "e", None, grounder,
                         EvaluateConfig(save_renders=False))
    q = {q["query"]: q for q in wrong["grounding"]["queries"]}
    r = {q["query"]: q for q in right["queries"]}
    assert r["fridge"]["probs"]["iou"]["mean"] == pytest.approx(1.0)
    assert r["fridge"]["language"]["iou"]["mean"] == pytest.approx(1.0)
    for query in ("fridge", "refrigerator", "drawer", "kitchen drawer"):
        assert q[query]["probs"]["iou"]["mean"] == 0.0 and q[query]["probs"]["iou"]["n"] == 4
    assert q["fridge"]["language"]["iou"]["mean"] == 0.0
    assert wrong["grounding"]["miou_probs_name"] == 0.0 and wrong["grounding"]["miou_probs_synonym"] == 0.0
    assert wrong["unseen_combinations"]["status"].startswith("skipped")
    assert not (tmp_path / "e" / "renders").exists()


def test_held_out_language_embeddings_are_not_all_held_until_the_grounding(eval_scene, tmp_path):
    """A rendered language embedding is [H, W, 384] floats (0.8 GB a 960x540 view): the evaluation keeps what the
    grounding makes of it (a relevancy map per query, the decoded probabilities), not the embeddings of every held-out
    view. At each render, at most the previous view's embedding may still be alive (the loop's variable); keeping
    them all had 3 alive at the 4th of the 4 held-out views, and 12.7 GiB on a phone video."""
    import weakref

    ds, run, _ = eval_scene
    grounder = _grounder(ds)

    class Counting(_LanguageRun):
        def __init__(self, *args):
            super().__init__(*args)
            self.refs, self.alive = [], []

        def render(self, camera, c2w, states, frame_index=None):
            self.alive.append(sum(r() is not None for r in self.refs))
            out = super().render(camera, c2w, states, frame_index)
            self.refs.append(weakref.ref(out["language"]))
            return out

    counting = Counting(run, grounder.encoder, grounder.encoder.name)
    metrics = evaluate_run(counting, ds, tmp_path / "e", None, grounder, EvaluateConfig(save_renders=False))
    assert len(counting.alive) == 4  # the 4 held-out views (even frames of 8); no truth: nothing else renders
    assert max(counting.alive) <= 1, counting.alive
    q = {q["query"]: q for q in metrics["grounding"]["queries"]}
    assert q["fridge"]["language"]["iou"]["mean"] == pytest.approx(1.0)  # scored as before (the test above)
    assert q["refrigerator"]["language_objects"]["iou"]["mean"] == pytest.approx(1.0)


def _keys(tree) -> set[str]:
    """Every dict key anywhere in a JSON tree."""
    if isinstance(tree, dict):
        return set(tree) | {k for v in tree.values() for k in _keys(v)}
    if isinstance(tree, list):
        return {k for v in tree for k in _keys(v)}
    return set()


def test_metrics_json_is_identical_between_two_evaluations(eval_scene, tmp_path):
    """Wall-clock numbers live in timings.json, so evaluating one model twice writes the same metrics.json bytes."""
    ds, run, truth = eval_scene
    outs = [tmp_path / "first", tmp_path / "second"]
    for out in outs:
        evaluate_run(run, ds, out, truth, _grounder(ds), EvaluateConfig(unseen_views=2))
    first, second = ((o / "metrics.json").read_bytes() for o in outs)
    assert first == second
    metrics = json.loads(first)
    assert not _keys(metrics) & {"seconds", "render_seconds", "fps", "wall_s"}
    # no trace of the output folder or the atomic write's temporary folder next to it (".first.xxxx")
    assert str(outs[0]) not in first.decode() and ".first." not in first.decode()
    timings = [json.loads((o / "timings.json").read_text()) for o in outs]
    assert all(t["held_out"]["render_seconds"] > 0 and t["held_out"]["fps"] > 0 for t in timings)
    per_view = metrics["unseen_combinations"]["n_unseen"] // 2
    assert timings[0]["unseen_combinations"]["model_renders"] == 2 * (1 + per_view)  # seen reference + unseen


def test_only_novel_combinations_are_rendered(eval_scene, tmp_path):
    ds, run, truth = eval_scene
    # training states lie on the diagonal at 1/7, 3/7, 5/7, 1: (0, 1) and (1, 0) are 0.57 away, (0.5, 0) and (0, 0.5)
    # only 0.36, so with novelty_min 0.4 those two are recorded but must not cost a render (level 0, 1/7 from the
    # nearest training state, counts as observed here: observed_within=None)
    cfg = EvaluateConfig(unseen_views=2, novelty_min=0.4, save_renders=False, locality_views=0, observed_within=None)
    metrics = evaluate_run(run, ds, tmp_path / "e", truth, None, cfg)
    assert metrics["grounding"]["status"].startswith("skipped: --no-grounding")  # why, as the user asked it
    unseen = metrics["unseen_combinations"]
    combos = {tuple(c["values"]): c["unseen"] for c in unseen["combinations"]}
    assert combos == {(0.0, 1.0): True, (0.5, 0.0): False, (1.0, 0.0): True, (0.0, 0.5): False}
    assert unseen["n_unseen"] == 4 and unseen["n_not_novel"] == 4  # 2 views x 2 combinations each
    for r in unseen["records"]:
        assert r["rendered"] == r["unseen"]
        if r["unseen"]:
            assert r["psnr"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6) and r["moved_pixels"] > 0
        else:
            assert r["psnr"] is None and r["psnr_moved"] is None and r["ssim"] is None and r["moved_objects"]
    rendered_states = [tuple(st.values()) for _, st in run.rendered if st is not None]
    assert (0.5, 0.0) not in rendered_states and (0.0, 0.5) not in rendered_states
    assert rendered_states.count((0.0, 1.0)) == 2 and rendered_states.count((1.0, 0.0)) == 2
    # held-out: 4 views; unseen: per view the seen reference plus the 2 novel combinations
    assert len(run.rendered) == 4 + 2 * (1 + 2)
    timings = json.loads((tmp_path / "e" / "timings.json").read_text())
    assert timings["unseen_combinations"]["model_renders"] == 2 * (1 + 2)


def test_grounding_per_view_ious_name_their_frames(eval_scene, tmp_path):
    ds, run, _ = eval_scene
    metrics = evaluate_run(run, ds, tmp_path / "e", None, _grounder(ds), EvaluateConfig(save_renders=False))
    for q in metrics["grounding"]["queries"]:
        assert q["probs"]["frames"] == ["00000", "00002", "00004", "00006"]
        assert len(q["probs"]["per_view"]) == len(q["probs"]["frames"])


def test_locality_passes_a_local_run_and_fails_one_that_repaints_the_room(eval_scene, tmp_path):
    ds, run, truth = eval_scene
    cfg = EvaluateConfig(max_views=1, unseen_views=1, save_renders=False, locality_views=2)
    local = evaluate_run(run, ds, tmp_path / "local", truth, None, cfg)["locality"]
    assert local["status"] == "computed" and local["all_local"]
    fridge = local["objects"]["fridge"]
    # the fake moves only the fridge's columns (0..5) by 0.5; the swept region is those columns dilated by 2 px
    # (outside: only the PNG rounding of the one render that falls on a stored image)
    assert fridge["model_outside_x255"]["mean"] == pytest.approx(0.0, abs=0.5)
    assert fridge["model_inside_x255"]["mean"] == pytest.approx(0.5 * 255 * 6 / 8, rel=1e-2)
    assert len(local["records"]) == 2 * 2  # 2 views x 2 objects

    class Repaints(type(run)):
        def render(self, camera, c2w, states, frame_index=None, outputs=None):
            out = super().render(camera, c2w, states, frame_index, outputs)
            return out | {"rgb": out["rgb"] + 0.02 * sum(states.values())}  # every pixel follows the states

    leaky = evaluate_run(Repaints(ds, truth.renderer), ds, tmp_path / "leaky", truth, None, cfg)["locality"]
    assert not leaky["all_local"]
    assert leaky["objects"]["drawer"]["model_outside_x255"]["mean"] == pytest.approx(0.02 * 255, abs=0.5)


def test_locality_renders_each_state_vector_of_a_view_once(eval_scene, monkeypatch):
    """An object at 0 or 1 in the view's own state shares its lo or hi render with every other such object, and
    the swept region's end states are the truth's lo / hi renders: each is rendered once, the records unchanged."""
    ds, _, truth = eval_scene
    frames, objects = ds.frames_in("test")[:2], ds.objects
    calls, truth_calls = [], []

    def render(frame, states):
        calls.append((frame.frame_id, tuple(sorted(states.items()))))
        cam = ds.camera_of(frame)  # an image that follows the states (the fake run would call the truth too)
        return np.full((cam.height, cam.width, 3), 0.1 + 0.2 * states["fridge"] + 0.3 * states["drawer"])

    truth_render = truth.renderer.render

    def counted(c2w, states, camera=None):
        truth_calls.append((np.asarray(c2w).tobytes(), tuple(sorted(states.items()))))
        return truth_render(c2w, states, camera=camera)

    first = locality(render, truth, frames, ds.camera_of, objects)
    monkeypatch.setattr(truth.renderer, "render", counted)
    calls.clear()
    again = locality(render, truth, frames, ds.camera_of, objects)
    assert again["records"] == first["records"]
    assert len(calls) == len(set(calls)) and len(truth_calls) == len(set(truth_calls))
    wanted = set()
    for frame in frames:
        base = {o: float((truth.state_for(frame) or {}).get(o, 0.0)) for o in objects}
        wanted |= {(frame.frame_id, tuple(sorted(dict(base, **{o: v}).items()))) for o in objects for v in (0.0, 1.0)}
    assert set(calls) == wanted
    assert len(wanted) < 2 * len(objects) * len(frames)  # the fixture's views hold an object at 0 or 1


def test_a_turned_copy_of_a_truth_world_dataset_is_aligned_by_its_turn(eval_scene):
    ds, _, truth = eval_scene
    turn = np.eye(4)
    turn[:3, :3] = np.array([[0.0, -1.0, 0.0], [0.6, 0.0, -0.8], [0.8, 0.0, 0.6]])
    turn[:3, 3] = [0.3, -1.0, 2.0]
    meta = {"orientation": {"turned": True, "new_from_old": turn.tolist()}}
    unnamed = Frame(file_path="images/frame_00099.png", c2w=turn @ ds.frames[2].c2w)  # no source_index
    pose, how = truth.after_turn(meta).pose_for(unnamed)
    assert how == "sim3"
    np.testing.assert_allclose(pose, ds.frames[2].c2w, atol=1e-9)
    assert truth.after_turn({"orientation": {"turned": False, "new_from_old": np.eye(4).tolist()}}) is truth
    assert truth.after_turn({}) is truth
    other = TruthSource(renderer=truth.renderer, camera=truth.camera, object_ids={}, same_world=False)
    assert other.after_turn(meta) is other  # estimated poses: aligned by pose_error.json, not by the turn


def test_a_run_trained_on_measured_gains_is_also_scored_at_the_nominal_exposure(eval_scene, tmp_path):
    """The held-out image divided by its measured gains is what such a run renders; views the measurement did
    not tie keep the plain PSNR only, and a run without gains gets no nominal entry at all (bytes unchanged)."""
    ds, run, truth = eval_scene
    plain = evaluate_run(run, ds, tmp_path / "plain", truth, None, EvaluateConfig(unseen_views=0, locality_views=0))
    assert "psnr_nominal" not in plain["held_out"]
    assert all("psnr_nominal" not in v for v in plain["held_out"]["views"])
    run.exposure_gains = {"00000": [0.0, 0.0, 0.0], "00002": [0.2, 0.2, 0.2]}  # frame 00002 filmed 22 % brighter
    config = EvaluateConfig(unseen_views=0, locality_views=0)
    held = evaluate_run(run, ds, tmp_path / "gains", truth, None, config)["held_out"]
    views = {v["frame"]: v for v in held["views"]}
    assert views["00000"]["psnr_nominal"] == pytest.approx(views["00000"]["psnr"], abs=1e-9)
    # the fake run renders the stored image: against that image divided by 1.22 it is further off
    assert views["00002"]["psnr_nominal"] < views["00002"]["psnr"] - 2
    assert "psnr_nominal" not in views["00004"] and held["psnr_nominal"]["n"] == 2
    assert "exposure.json" in held["psnr_nominal_source"]


def test_a_room_of_many_objects_is_tested_at_fewer_poses_within_the_budget(eval_scene, tmp_path):
    """Poses x unseen combinations and poses x objects stay within the budgets (at least one pose each), and the
    metrics say how many poses were used and asked for; within the budget nothing changes."""
    ds, run, truth = eval_scene
    free = EvaluateConfig(max_views=1, unseen_views=3, locality_views=4, save_renders=False)
    full = evaluate_run(run, ds, tmp_path / "full", truth, None, free)
    per_view = full["unseen_combinations"]["n_unseen"] // 3
    assert per_view >= 2 and full["unseen_combinations"]["views"] == 3
    assert full["locality"]["views"] == 4 and full["locality"]["views_asked"] == 4
    assert not full["unseen_combinations"]["views_cut"] and not full["locality"]["views_cut"]

    tight = EvaluateConfig(max_views=1, unseen_views=3, locality_views=4, save_renders=False,
                           max_unseen_renders=2 * per_view, max_locality_pairs=3)  # 2 objects: 1 pose of pairs
    cut = evaluate_run(run, ds, tmp_path / "cut", truth, None, tight)
    unseen, local = cut["unseen_combinations"], cut["locality"]
    assert (unseen["views"], unseen["views_asked"], unseen["max_renders"]) == (2, 3, 2 * per_view)
    assert unseen["n_unseen"] == 2 * per_view and len({r["frame"] for r in unseen["records"]}) == 2
    assert (local["views"], local["views_asked"], local["max_pairs"]) == (1, 4, 3)
    assert unseen["views_cut"] and local["views_cut"]
    assert len(local["records"]) == 2  # one pose x 2 objects

    nothing = EvaluateConfig(max_views=1, unseen_views=3, locality_views=4, save_renders=False,
                             max_unseen_renders=1, max_locality_pairs=1)
    least = evaluate_run(run, ds, tmp_path / "least", truth, None, nothing)
    assert least["unseen_combinations"]["views"] == 1 and least["locality"]["views"] == 1

    more = EvaluateConfig(max_views=1, unseen_views=1, locality_views=50, save_renders=False)
    short = evaluate_run(run, ds, tmp_path / "short", truth, None, more)["locality"]
    assert short["views"] == len(ds.frames_in("test")) < 50 and not short["views_cut"]  # the split, not the budget


def test_the_cli_refuses_a_negative_budget(eval_scene, tmp_path):
    with pytest.raises(InputError, match="max-locality-pairs"):
        evaluate_cli._evaluate(evaluate_cli.build_parser().parse_args(
            ["--run", str(tmp_path), "--out", str(tmp_path / "e"), "--max-locality-pairs", "-1"]))


def test_render_scale_for_takes_the_largest_frame_of_per_frame_cameras(eval_scene):
    """One integer factor for the whole dataset, from its largest frame: every view is scored at one fraction."""
    from dataclasses import replace

    from stages.evaluate.evaluation import render_scale_for

    ds = eval_scene[0]
    w, h = ds.camera.width, ds.camera.height
    assert render_scale_for(ds, max(w, h)) == 1.0
    assert render_scale_for(ds, max(w, h) - 1) == 0.5
    big = replace(ds.frames[0], camera=ds.camera.scaled(3.0))
    mixed = replace(ds, frames=[big, *ds.frames[1:]])
    assert render_scale_for(mixed, max(w, h)) == pytest.approx(1 / 3)


def _truth_of(ds, renderer) -> TruthSource:
    return TruthSource(renderer=renderer, camera=ds.camera, object_ids={"fridge": 1, "drawer": 2},
                       poses={f.source_index: f.c2w for f in ds.frames},
                       states={f.source_index: dict(f.state) for f in ds.frames}, origin="fake capture")


def test_the_seen_reference_scores_each_view_at_its_own_state(eval_scene, tmp_path):
    """The run's render of the view at its own state against the truth's: the +-0.1 error on the fridge's 6 of 16
    columns over the whole image, on 6 of the 12 object columns over the object pixels."""
    ds, _, truth = eval_scene
    run = TruthRun(ds, truth.renderer)
    cfg = EvaluateConfig(max_views=1, unseen_views=2, locality_views=0, save_renders=False)
    seen = evaluate_run(run, ds, tmp_path / "e", truth, None, cfg)["unseen_combinations"]["seen_reference"]
    assert [v["frame"] for v in seen["views"]] == ["00000", "00006"]
    assert seen["psnr"]["mean"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6) and seen["psnr"]["n"] == 2
    assert seen["psnr_objects"]["mean"] == pytest.approx(10 * math.log10(1 / (ERROR**2 * 6 / 12)), abs=1e-6)
    assert seen["psnr_objects"]["n"] == 2
    assert (6, ds.frames[6].state) in run.rendered  # rendered at the view's own state


def test_an_object_that_moves_is_scored_where_it_was_and_where_it_is(tmp_path):
    """The sliding fridge: shut on columns 0..2 in view 00000 (its own state), open on 3..5 in the combination
    (fridge 1, drawer 0). The unseen render's moved region is both, 6 columns; the run's error there is 0.1, so
    20 dB. The locality test's swept region is the fridge at 0, .25, .5, .75, 1 (columns 0..5) and the shadow it
    casts on column 14 once half open, dilated by 2 px: columns 0..7 and 12..15."""
    ds = make_eval_dataset(tmp_path / "scene")
    sliding = SlidingTruthRenderer(shadow_column=14)
    truth = _truth_of(ds, sliding)
    run = TruthRun(ds, sliding)
    cfg = EvaluateConfig(max_views=1, unseen_views=1, novelty_min=0.4, observed_within=None, locality_views=1,
                         save_renders=False)
    metrics = evaluate_run(run, ds, tmp_path / "e", truth, None, cfg)
    records = metrics["unseen_combinations"]["records"]
    opened = next(r for r in records if r["states"] == {"fridge": 1.0, "drawer": 0.0})
    assert opened["frame"] == "00000" and opened["moved_objects"] == ["fridge"]
    assert opened["moved_pixels"] == 6 * H
    assert opened["psnr_moved"] == pytest.approx(20.0, abs=1e-6)
    assert opened["psnr"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
    drawer = next(r for r in records if r["states"] == {"fridge": 0.0, "drawer": 1.0})
    assert drawer["moved_objects"] == ["drawer"] and drawer["moved_pixels"] == 6 * H  # columns 10..15 both times

    local = metrics["locality"]
    fridge = next(r for r in local["records"] if r["object"] == "fridge")
    assert fridge["region_pixels"] == (8 + 4) * H
    # the truth changes only inside that region; so does the run (it adds a fixed error to the truth)
    assert fridge["truth_outside_x255"] == 0.0 and fridge["model_outside_x255"] == pytest.approx(0.0, abs=1e-9)
    assert local["objects"]["fridge"]["local"]


def test_the_nominal_exposure_target_is_the_image_divided_by_its_gains(eval_scene, tmp_path):
    """A run that renders frame 00002 exactly at the nominal exposure (stored image x e^-gain, per channel) plus
    the fake's +-0.1 on the fridge: against the image divided by its gains it scores the fake's PSNR exactly."""
    ds, run, _ = eval_scene
    gains = [0.2, 0.1, 0.0]

    class Nominal(type(run)):
        def __init__(self, *args) -> None:
            super().__init__(*args)
            self.exposure_gains = {"00002": gains}

        def render(self, camera, c2w, states, frame_index=None, outputs=None):
            out = super().render(camera, c2w, states, frame_index, outputs)
            frame = self.ds.frames[frame_index]
            if frame.frame_id in self.exposure_gains:
                stored = self.ds.load_image(frame).astype(np.float64)
                error = out["rgb"] - stored
                out["rgb"] = stored * np.exp(-np.asarray(gains)) + error
            return out

    held = evaluate_run(Nominal(ds, run.truth), ds, tmp_path / "e", None, None,
                        EvaluateConfig(unseen_views=0, locality_views=0, save_renders=False))["held_out"]
    views = {v["frame"]: v for v in held["views"]}
    assert views["00002"]["psnr_nominal"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
    assert views["00002"]["psnr"] < HELD_OUT_PSNR - 2  # against the image as filmed it is off
    assert held["psnr_nominal"]["n"] == 1


def test_a_learned_state_run_renders_held_out_views_at_its_learned_state(eval_scene, tmp_path):
    """Such a run is asked for no state (None): it renders the state it learned for the frame index."""
    ds, run, _ = eval_scene

    class Learned(FakeRun):
        state_mode = "learned"

        def __init__(self, *args) -> None:
            super().__init__(*args)
            self.asked: list[dict | None] = []

        def render(self, camera, c2w, states, frame_index=None, outputs=None):
            self.asked.append(states)
            learned = self.ds.frames[frame_index].state  # it learned each frame's state exactly
            return super().render(camera, c2w, learned if states is None else states, frame_index, outputs)

    learned = Learned(ds, run.truth)
    held = evaluate_run(learned, ds, tmp_path / "e", None, None,
                        EvaluateConfig(unseen_views=0, locality_views=0, save_renders=False))["held_out"]
    assert learned.asked == [None] * 4
    assert held["state_source"] == "run's learned state at the frame index"
    assert held["psnr"]["mean"] == pytest.approx(HELD_OUT_PSNR, abs=1e-6)
