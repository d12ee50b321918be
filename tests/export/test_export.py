"""``livescene export`` on the tiny capture: geometry in the scene box, a moving part that moves, the files, errors."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from export_truth_run import TruthRun

from stages.capture.geometry import build_scene
from stages.export import ExportOptions, export_run, read_glb
from stages.export.cli import main as export_main
from stages.export.geometry_compare import chamfer_distance, inside_box
from stages.export.state_spec import parse_state_string
from stages.export.world_up import world_up_axis
from stages.report.export_section import section_export
from stages.scene import InputError


def _swept_box(spec, index: int) -> np.ndarray:
    """[[min], [max]] of object ``index``'s boxes over states 0..1 (its truth box), metres = dataset units."""
    model = build_scene(spec)
    pts = []
    for s in np.linspace(0, 1, 11):
        states = np.zeros(len(model.joints))
        states[index] = s
        verts, _ = model.mesh(model.part_poses(states))
        pts.append(verts[np.repeat(model.part_object == index + 1, 8)])
    p = np.concatenate(pts)
    return np.stack([p.min(0), p.max(0)])


@pytest.fixture(scope="module")
def drawer_export(tiny_capture_dataset, tmp_path_factory):
    """The tiny capture's truth exported (GLB, with object parts) with the drawer closed and open."""
    _, ds, renderer = tiny_capture_dataset
    out = tmp_path_factory.mktemp("drawer") / "export"
    doc = export_run(TruthRun(renderer), ds, [{"drawer": 0.0}, {"drawer": 1.0}], out,
                     ExportOptions(fmt="glb", objects=True, scale=1.0, resolution=128), progress=False)
    return ds, renderer, out, doc


def test_the_mesh_lies_in_the_scene_box_and_the_drawer_part_moves_with_its_state(drawer_export):
    ds, renderer, out, doc = drawer_export
    closed, opened = (out / r["folder"] for r in doc["exports"])
    box = np.asarray(ds.scene_box)
    for folder in (closed, opened):
        scene = read_glb(folder / "scene_mesh.glb")["positions"]
        assert len(scene) > 1000
        assert np.all(scene >= box[0] - 1e-5) and np.all(scene <= box[1] + 1e-5)

    # the drawer's part, closed and open: apart by the drawer's travel, together once moved by it
    model = build_scene(renderer.spec)
    j = renderer.objects.index("drawer")
    motion = model.object_frames[j] @ model.joints[j].transform(1.0) @ np.linalg.inv(model.object_frames[j])
    shift = motion[:3, 3]
    assert np.linalg.norm(shift) == pytest.approx(0.3)
    part0 = read_glb(closed / "objects" / "drawer_mesh.glb")["positions"]
    part1 = read_glb(opened / "objects" / "drawer_mesh.glb")["positions"]
    assert len(part0) > 50 and len(part1) > 50
    apart, moved = chamfer_distance(part0, part1), chamfer_distance(part0 + shift, part1)
    assert apart > 0.2 and moved < 0.03, (apart, moved)
    # the part is the drawer: inside its swept box
    swept = _swept_box(renderer.spec, j)
    assert inside_box(part1, swept, margin=0.05).mean() > 0.95

    # the cabinet did not move: its part is the same at both drawer states
    cab0 = read_glb(closed / "objects" / "cabinet_mesh.glb")["positions"]
    cab1 = read_glb(opened / "objects" / "cabinet_mesh.glb")["positions"]
    assert chamfer_distance(cab0, cab1) < 0.01

    # outside the drawer's swept box the room is unchanged (<= 1 % of the scene extent)
    a = read_glb(closed / "scene_mesh.glb")["positions"]
    b = read_glb(opened / "scene_mesh.glb")["positions"]
    static = chamfer_distance(a[~inside_box(a, swept, margin=0.05)], b[~inside_box(b, swept, margin=0.05)])
    assert static <= 0.01 * float(np.max(box[1] - box[0]))


def test_export_json_records_sizes_counts_timings_and_thumbnails(drawer_export):
    ds, _, out, doc = drawer_export
    assert json.loads((out / "export.json").read_text()) == json.loads(json.dumps(doc))
    assert doc["objects"] == ["cabinet", "drawer"] and doc["views"] == len(ds.frames_in("train"))
    assert [r["states"] for r in doc["exports"]] == [{"cabinet": 0.0, "drawer": 0.0}, {"cabinet": 0.0, "drawer": 1.0}]
    assert doc["world_up"] == world_up_axis([f.c2w for f in ds.frames])
    for record in doc["exports"]:
        for key, entry in record["files"].items():
            path = out / entry["path"]
            assert path.stat().st_size == entry["bytes"]
            geom = read_glb(path)
            if key.endswith("_mesh"):
                assert len(geom["positions"]) == entry["vertices"] and len(geom["triangles"]) == entry["triangles"]
                assert geom["mode"] == 4 and geom["triangles"].max() < entry["vertices"]
            else:
                assert len(geom["positions"]) == entry["points"] and geom["mode"] == 0
        timings = record["timings_s"]
        assert timings["total"] >= timings["render"] + timings["fuse"] > 0
        thumb = cv2.imread(str(out / record["thumbnail"]))
        assert thumb.shape[1] == 320 and thumb.std() > 10  # a picture, not a blank
    assert not list(out.parent.glob(".export*")), "no temporary folder left behind"


def test_the_report_section_shows_each_state_with_counts_sizes_timings_and_thumbnail(drawer_export, tmp_path):
    _, _, out, doc = drawer_export
    html = section_export({"livescene": out})
    for record in doc["exports"]:
        mesh = record["files"]["scene_mesh"]
        assert f"{mesh['vertices']:,} v / {mesh['triangles']:,} t" in html
        assert f"{mesh['bytes'] / 2**20:.2f} MiB" in html
        assert f"{record['timings_s']['total']:.3f}" in html
    assert "cabinet=0, drawer=0" in html and "cabinet=0, drawer=1" in html
    assert html.count("data:image/png;base64,") == len(doc["exports"])
    assert "drawer part" in html  # object parts get their own column
    assert "export.json is missing" in section_export({"livescene": tmp_path})
    assert "no method" in section_export({})


def test_objects_need_a_probability_field(tiny_capture_dataset, tmp_path):
    _, ds, renderer = tiny_capture_dataset
    with pytest.raises(InputError, match=r"--objects needs per-object probabilities.*fix: .*leave out --objects"):
        export_run(TruthRun(renderer, with_probs=False), ds, [{}], tmp_path / "x", ExportOptions(objects=True),
                   progress=False)
    assert not (tmp_path / "x").exists()


def test_cli_exports_a_real_run_in_each_format(tiny_trained_run, tiny_capture_dataset, tmp_path, capsys):
    ds = tiny_capture_dataset[1]
    out = tmp_path / "obj"
    code = export_main(["--run", str(tiny_trained_run), "--states", "cabinet=1, drawer=0", "--states", "drawer=0.5",
                        "--format", "obj", "--objects", "--views", "2", "--scale", "0.5", "--out", str(out),
                        "--no-progress"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    doc = json.loads((out / "export.json").read_text())
    assert [e["states"] for e in summary["exports"]] == [{"cabinet": 1.0, "drawer": 0.0},
                                                         {"cabinet": 0.0, "drawer": 0.5}]
    assert doc["views"] == 2 and doc["render_size"] == [32, 24] and doc["method"] == "livescene"
    box = np.asarray(ds.scene_box)
    for record in doc["exports"]:
        assert {"scene_mesh", "scene_points", "objects/cabinet_mesh", "objects/drawer_points"} <= set(record["files"])
        text = (out / record["files"]["scene_mesh"]["path"]).read_text()
        verts = np.array([[float(x) for x in line.split()[1:4]] for line in text.splitlines()
                          if line.startswith("v ")]).reshape(-1, 3)
        assert len(verts) == record["files"]["scene_mesh"]["vertices"]
        assert np.all(verts >= box[0] - 1e-4) and np.all(verts <= box[1] + 1e-4)
        assert (out / record["thumbnail"]).is_file()
    for fmt in ("ply", "glb"):
        assert export_main(["--run", str(tiny_trained_run), "--format", fmt, "--views", "2", "--scale", "0.25",
                            "--out", str(tmp_path / fmt), "--no-progress"]) == 0
        assert (tmp_path / fmt / "cabinet-0_drawer-0" / f"scene_mesh.{fmt}").is_file()


@pytest.mark.parametrize(("states", "message"), [
    ("fridge=1", r"unknown object 'fridge'.*fix: use one of \['cabinet', 'drawer'\]"),
    ("cabinet", r"'cabinet' in 'cabinet' is not OBJECT=VALUE"),
    ("cabinet=open", r"'open' is not a number"),
    ("cabinet=1.5", r"state 1.5 is not in \[0, 1\]"),
    ("cabinet=1,cabinet=0", r"object 'cabinet' is given twice"),
])
def test_cli_explains_bad_state_strings(tiny_trained_run, tmp_path, capsys, states, message):
    out = tmp_path / "bad"
    assert export_main(["--run", str(tiny_trained_run), "--states", states, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --states: ")
    assert re.search(message, err), err
    assert not out.exists()


def test_cli_explains_a_missing_run(tmp_path, capsys):
    assert export_main(["--run", str(tmp_path / "none"), "--out", str(tmp_path / "o")]) == 2
    assert "no trained model in this run folder" in capsys.readouterr().err


def test_writers_handle_empty_geometry(tmp_path):
    import open3d as o3d

    from stages.export import write_geometry

    for fmt in ("ply", "obj", "glb"):
        write_geometry(tmp_path / f"empty.{fmt}", o3d.geometry.TriangleMesh())
    assert len(read_glb(tmp_path / "empty.glb")["positions"]) == 0
    assert len(o3d.io.read_triangle_mesh(str(tmp_path / "empty.ply")).vertices) == 0


def test_mesh_formats_round_trip(tmp_path):
    import open3d as o3d

    from stages.export import write_geometry

    mesh = o3d.geometry.TriangleMesh.create_box(1.0, 2.0, 3.0)
    mesh.compute_vertex_normals()
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.linspace(0, 1, 24).reshape(8, 3))
    verts, tris = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    for fmt in ("ply", "obj"):
        write_geometry(tmp_path / f"box.{fmt}", mesh)
        back = o3d.io.read_triangle_mesh(str(tmp_path / f"box.{fmt}"))
        assert np.allclose(np.sort(np.asarray(back.vertices), axis=0), np.sort(verts, axis=0), atol=1e-5)
        assert len(back.triangles) == 12
    ply = o3d.io.read_triangle_mesh(str(tmp_path / "box.ply"))
    assert np.allclose(np.asarray(ply.vertex_colors), np.asarray(mesh.vertex_colors), atol=1 / 255)
    write_geometry(tmp_path / "box.glb", mesh)
    glb = read_glb(tmp_path / "box.glb")
    assert np.allclose(glb["positions"], verts) and np.array_equal(glb["triangles"], tris)
    assert np.allclose(glb["colors"], np.asarray(mesh.vertex_colors), atol=1 / 255)
    # as glTF defines them: linear vertex colours, and an unlit (else matte) material, not the spec's default metal
    doc = _glb_json(tmp_path / "box.glb")
    assert doc["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] == 0.0
    assert "KHR_materials_unlit" in doc["materials"][0]["extensions"]
    assert doc["meshes"][0]["primitives"][0]["material"] == 0
    grey = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(verts[:1]))
    grey.colors = o3d.utility.Vector3dVector(np.full((1, 3), 0.5))
    write_geometry(tmp_path / "grey.glb", grey)
    assert np.allclose(read_glb(tmp_path / "grey.glb")["colors"], 0.5, atol=1e-6)
    assert _glb_color_accessor(tmp_path / "grey.glb") == pytest.approx([0.21404, 0.21404, 0.21404], abs=1e-5)
    trimesh = pytest.importorskip("trimesh")  # an independent glTF reader, where installed
    loaded = trimesh.load(tmp_path / "box.glb", force="mesh")
    assert np.allclose(np.sort(loaded.vertices, axis=0), np.sort(verts, axis=0))
    points = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(verts))
    write_geometry(tmp_path / "points.glb", points)
    assert read_glb(tmp_path / "points.glb")["mode"] == 0
    assert Path(tmp_path / "points.glb").stat().st_size > 96


def test_combinations_that_differ_in_the_seventh_digit_get_folders_of_their_own():
    from stages.export.state_spec import state_slug

    assert state_slug({"cabinet": 1.0, "drawer": 0.0}) == "cabinet-1_drawer-0"  # the usual names are unchanged
    assert state_slug({"cabinet": 0.1234567}) != state_slug({"cabinet": 0.1234568})


def test_all_sets_every_object_the_string_does_not_name():
    objects = ["cabinet", "drawer"]
    assert parse_state_string("all=1", objects) == {"cabinet": 1.0, "drawer": 1.0}
    assert parse_state_string("all=1,drawer=0.25", objects) == {"cabinet": 1.0, "drawer": 0.25}
    assert parse_state_string("", objects) == {}
    # an object really called "all" keeps its name
    assert parse_state_string("all=0.5", ["all", "drawer"]) == {"all": 0.5}
    with pytest.raises(InputError, match="'all' is given twice"):
        parse_state_string("all=1,all=0", objects)
    with pytest.raises(InputError, match=r"not in \[0, 1\]"):
        parse_state_string("all=2", objects)


def test_an_empty_mesh_and_states_a_method_cannot_read_are_said(tiny_capture_dataset, tmp_path, capsys):
    """An undertrained run's empty mesh is not a silent success, and a k-planes run (time, not states, on its fourth
    axis) is said to ignore the states asked of it."""
    import torch

    from stages.model import load_config
    from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES
    from stages.model.trainer import Trainer

    torch.set_num_threads(1)
    run = tmp_path / "kplanes"
    overrides = [*TINY_MODEL_OVERRIDES, "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=100",
                 "train.eval_rays=64", "train.checkpoint_every=100", "train.render_chunk=1024", "train.threads=1",
                 "train.max_steps=2"]
    config = load_config("cpu-demo", overrides, method="k-planes", data=str(tiny_capture_dataset[1].root), seed=0)
    Trainer(config, run, device="cpu", progress=False).train()
    with pytest.warns(UserWarning) as said:
        assert export_main(["--run", str(run), "--states", "cabinet=1", "--views", "2", "--scale", "0.25",
                            "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    messages = " | ".join(str(w.message) for w in said)
    assert "a k-planes run reads no object state" in messages
    assert "the scene mesh is empty at 1 of 1 state combinations" in messages and "train it longer" in messages
    assert "a run of too few steps (this one: 2" in messages and "--resolution too fine" in messages
    # one view can never give a surface (the fusion keeps voxels two views agree on): refused, not "undertrained"
    assert export_main(["--run", str(run), "--views", "1", "--out", str(tmp_path / "one"), "--no-progress"]) == 2
    assert "--views: 1 views; fix: give 0 (all training poses) or 2 or more" in capsys.readouterr().err


def test_a_dataset_that_is_not_the_runs_is_refused_or_named(tiny_trained_run, tiny_capture_dataset, tmp_path,
                                                            capsys):
    """Another dataset's objects would take the run's states and masks; another world frame (a capture's truth/
    where training had COLMAP's units) renders empty space: refused, and warned of."""
    import json
    import shutil
    import warnings

    from stages.model import load_run
    from stages.scene import read_scene

    root = tiny_capture_dataset[1].root
    renamed = tmp_path / "renamed"
    shutil.copytree(root, renamed)
    for name in ("mapping.yaml", "key_frame_value.yaml"):
        (renamed / name).write_text((renamed / name).read_text().replace("cabinet", "fridge"))
    assert export_main(["--run", str(tiny_trained_run), "--data", str(renamed), "--out", str(tmp_path / "a"),
                        "--no-progress"]) == 2
    assert "differ from the run's" in capsys.readouterr().err and not (tmp_path / "a").exists()
    moved = tmp_path / "moved"
    shutil.copytree(root, moved)
    transforms = json.loads((moved / "transforms.json").read_text())
    for frame in transforms["frames"]:
        frame["transform_matrix"][0][3] += 1.0  # the same room, another origin
    (moved / "transforms.json").write_text(json.dumps(transforms))
    with pytest.warns(UserWarning, match=r"its cameras differ from those of the dataset this run was trained on"):
        export_main(["--run", str(tiny_trained_run), "--data", str(moved), "--views", "2", "--scale", "0.25",
                     "--resolution", "32", "--out", str(tmp_path / "b"), "--no-progress"])
    copy = tmp_path / "copy"  # a copy of the run's own dataset is the run's dataset: nothing to say
    shutil.copytree(root, copy)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        load_run(tiny_trained_run).check_dataset(read_scene(copy))


def _glb_json(path: Path) -> dict:
    data = path.read_bytes()
    size = int.from_bytes(data[12:16], "little")
    return json.loads(data[20:20 + size])


def _glb_color_accessor(path: Path) -> list[float]:
    """The first vertex colour as stored in the file (linear)."""
    data = path.read_bytes()
    doc = _glb_json(path)
    size = int.from_bytes(data[12:16], "little")
    body = data[20 + size + 8:]
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"]]
    view = doc["bufferViews"][acc["bufferView"]]
    return np.frombuffer(body, "<f4", 3, view["byteOffset"]).tolist()


def test_glb_files_stand_up_and_export_json_records_units_and_voxel(drawer_export):
    """The tiny capture is z-up in metres; its scene box is 4 m long at most, fused at 128 voxels: 3.125 cm."""
    from stages.export.mesh_io import UP_TO_GLTF_Y

    _, _, out, doc = drawer_export
    assert doc["world_up"] == "+z" and doc["units"] == "m"
    assert doc["voxel"] == pytest.approx(4.0 / 128)
    for record in doc["exports"]:
        for entry in record["files"].values():
            assert _glb_json(out / entry["path"])["nodes"][0]["rotation"] == pytest.approx(UP_TO_GLTF_Y["+z"])


def test_the_probability_threshold_decides_which_pixels_are_an_objects(tiny_capture_dataset, tmp_path):
    """Rendered probabilities of 0.6: an object's part at --prob-threshold 0.5, nothing at 0.7."""
    _, ds, renderer = tiny_capture_dataset

    class Unsure(TruthRun):
        def render(self, *args, **kwargs):
            out = super().render(*args, **kwargs)
            if "probs" in out:
                out["probs"] = out["probs"] * 0.6
            return out

    fused = {}
    for threshold in (0.5, 0.7):
        options = ExportOptions(objects=True, views=2, scale=0.5, resolution=32, prob_threshold=threshold)
        doc = export_run(Unsure(renderer), ds, [{}], tmp_path / str(threshold), options, progress=False)
        fused[threshold] = doc["exports"][0]["pixels_fused"]
    assert fused[0.5]["cabinet"] > 0 and fused[0.5]["drawer"] > 0
    assert fused[0.7]["cabinet"] == 0 and fused[0.7]["drawer"] == 0
    assert fused[0.7]["scene"] == fused[0.5]["scene"] > 0


def test_the_same_combination_twice_is_refused_before_rendering(tiny_capture_dataset, tmp_path):
    _, ds, renderer = tiny_capture_dataset
    run = TruthRun(renderer)
    with pytest.raises(InputError, match="the same state combination is given twice"):
        export_run(run, ds, [{"drawer": 1.0}, {"drawer": 1.0, "cabinet": 0.0}], tmp_path / "x", ExportOptions(),
                   progress=False)
    assert run.calls == [] and not (tmp_path / "x").exists()


@pytest.mark.parametrize(("field", "bad", "good"), [
    ("prob_threshold", [0.0, 1.0, -0.1], [0.01, 0.99]),
    ("resolution", [15, 2049], [16, 2048]),
    ("scale", [0.0, 4.01], [0.05, 4.0]),
    ("views", [1, -1], [0, 2]),
    ("fmt", ["stl"], ["ply", "obj", "glb"]),
])
def test_options_out_of_range_are_refused_with_the_flag(field, bad, good):
    flag = "--format" if field == "fmt" else "--" + field.replace("_", "-")
    for value in bad:
        with pytest.raises(InputError, match=f"^{flag}: "):
            ExportOptions(**{field: value}).check()
    for value in good:
        ExportOptions(**{field: value}).check()


def test_views_are_spread_over_the_training_frames_and_rendered_without_distortion(tiny_capture_dataset):
    from stages.export.exporter import render_camera, training_views
    from stages.scene import Camera

    ds = tiny_capture_dataset[1]
    train = [i for i, f in enumerate(ds.frames) if f.split == "train"]
    assert train == [1, 3, 5, 7, 9, 11]  # the "alternate" split of 12 frames
    picked = [i for i, _, _ in training_views(ds, 3)]
    assert picked[0] == 1 and picked[-1] == 11 and len(set(picked)) == 3  # both ends of the training frames
    assert [i for i, _, _ in training_views(ds, 0)] == train
    lens = Camera(fx=100.0, fy=90.0, cx=64.0, cy=48.0, width=128, height=96, distortion={"k1": 0.1, "p1": 0.01})
    half = render_camera(lens, 0.5)
    assert half == Camera(fx=50.0, fy=45.0, cx=32.0, cy=24.0, width=64, height=48) and not half.has_distortion
    assert not render_camera(lens, 1.0).has_distortion


def test_folder_and_file_names_stay_inside_the_export():
    from stages.export.exporter import file_stem
    from stages.export.state_spec import full_state, state_slug

    assert state_slug({"top/drawer": 1.0, "a b": 0.5}) == "top-drawer-1_a-b-0.5"
    assert state_slug({}) == "no-objects"  # a room without objects still gets a folder
    assert file_stem("top/drawer") == "top-drawer" and file_stem("a\\b") == "a-b"
    assert file_stem("..") == "_" and file_stem(".") == "_"
    assert full_state({"drawer": 1.0}, ["cabinet", "drawer"]) == {"cabinet": 0.0, "drawer": 1.0}


def test_without_a_scene_box_the_export_is_cropped_to_the_runs_normalisation_cube(tmp_path):
    from types import SimpleNamespace

    from stages.export.exporter import export_box

    dataset = SimpleNamespace(scene_box=None, root=tmp_path)
    # x_unit = 0.5 x - (1, 0.5, 0.5): the cube [-1, 1]^3 is the world's (2, 1, 1) +- 2
    transform = np.array([[0.5, 0, 0, -1.0], [0, 0.5, 0, -0.5], [0, 0, 0.5, -0.5], [0, 0, 0, 1.0]])
    box = export_box(dataset, SimpleNamespace(norm=SimpleNamespace(transform=transform)))
    assert np.allclose(box, [[0.0, -1.0, -1.0], [4.0, 3.0, 3.0]])
    with pytest.raises(InputError, match=r"scene.json: no scene_box, and the run has no scene normalisation"):
        export_box(dataset, SimpleNamespace())


def test_the_volume_is_fused_at_the_voxel_export_json_records(tiny_capture_dataset, tmp_path, monkeypatch):
    """Voxel = the scene box's longest side / --resolution: 4 m / 16 = 25 cm for the tiny capture."""
    import stages.export.exporter as exporter

    _, ds, renderer = tiny_capture_dataset
    used = []

    class Recording(exporter.TSDFFusion):
        def __init__(self, box, settings, *args, **kwargs) -> None:
            used.append(settings)
            super().__init__(box, settings, *args, **kwargs)

    monkeypatch.setattr(exporter, "TSDFFusion", Recording)
    doc = export_run(TruthRun(renderer), ds, [{}], tmp_path / "x",
                     ExportOptions(views=2, scale=0.25, resolution=16), progress=False)
    assert doc["voxel"] == pytest.approx(0.25)
    assert [s.voxel for s in used] == pytest.approx([0.25])


def test_objects_need_one_probability_per_object_and_the_background(tiny_capture_dataset, tmp_path):
    """A run whose probs lack the background channel is not LiveScene's probability field: refused up front."""
    _, ds, renderer = tiny_capture_dataset

    class NoBackground(TruthRun):
        def render(self, *args, **kwargs):
            out = super().render(*args, **kwargs)
            if "probs" in out:
                out["probs"] = out["probs"][..., :-1]
            return out

    with pytest.raises(InputError, match=r"--objects needs per-object probabilities"):
        export_run(NoBackground(renderer), ds, [{}], tmp_path / "x", ExportOptions(objects=True), progress=False)


def test_an_object_whose_name_holds_a_comma_can_be_given_a_state():
    """--states splits at commas: "left, top drawer=1" was refused ("'left' ... is not OBJECT=VALUE"), so such an
    object could only be exported with every other object at its state (all=V)."""
    objects = ["left, top drawer", "cabinet"]
    assert parse_state_string("left, top drawer=1, cabinet=0", objects) == {"left, top drawer": 1.0, "cabinet": 0.0}
    assert parse_state_string(",cabinet=1,left, top drawer=0.5,", objects) == {"cabinet": 1.0, "left, top drawer": 0.5}
    with pytest.raises(InputError, match="unknown object 'cabinet, drawer'"):
        parse_state_string("cabinet, drawer=1", objects)
