"""load_run(...).render: shapes, probabilities, state handling, and the render CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from stages.model import load_run
from stages.model.render_cli import main as render_main
from stages.model.run import dataset_of_run
from stages.scene import InputError


def test_render_contract(trained_run, tiny_dataset):
    run = load_run(trained_run)
    assert run.objects == tiny_dataset.objects
    frame = tiny_dataset.frames[1]
    out = run.render(tiny_dataset.camera, frame.c2w, frame.state, frame_index=1)
    assert out["rgb"].shape == (12, 16, 3) and out["depth"].shape == (12, 16)
    assert out["accumulation"].shape == (12, 16) and out["probs"].shape == (12, 16, 4)
    assert np.allclose(out["probs"].sum(-1), 1.0, atol=1e-5)
    for v in out.values():
        assert np.isfinite(v).all()
    assert np.all((out["rgb"] >= 0) & (out["rgb"] <= 1))
    # a sequence, a partial dict and None (the frame's own state) all resolve to one value per object
    seq = run.render(tiny_dataset.camera, frame.c2w, [frame.state[o] for o in run.objects])
    assert np.allclose(seq["rgb"], out["rgb"], atol=1e-6)
    assert np.allclose(run.state_vector(None, 1), [frame.state[o] for o in run.objects])
    assert run.state_vector({"object1": 0.25}, 1)[1] == 0.25
    with pytest.raises(InputError, match="unknown objects"):
        run.render(tiny_dataset.camera, frame.c2w, {"nope": 1.0})
    with pytest.raises(InputError, match="3 objects"):
        run.render(tiny_dataset.camera, frame.c2w, [0.5])
    # a NaN state would render as empty space (render_weights takes NaN thickness as 0): refused, by either form
    with pytest.raises(InputError, match=r"states of \['object1'\] are not finite"):
        run.render(tiny_dataset.camera, frame.c2w, {"object1": float("nan")})
    with pytest.raises(InputError, match=r"states of \['object0'\] are not finite"):
        run.state_vector([float("inf"), 0.0, 0.0])


def test_render_cli_writes_images(trained_run, tiny_dataset, tmp_path, capsys):
    out = tmp_path / "render"
    rc = render_main(["--run", str(trained_run), "--pose", f"{tiny_dataset.root}/transforms.json:00001",
                      "--state", "object0=1", "--out", str(out)])
    assert rc == 0
    names = {p.name for p in out.iterdir()}
    assert {"rgb.png", "depth.png", "depth.npy", "probs.npy", "prob_object0.png", "prob_background.png"} <= names
    assert json.loads(capsys.readouterr().out)["states"]["object0"] == 1.0
    matrix = " ".join(str(x) for x in np.asarray(tiny_dataset.frames[0].c2w).ravel())
    assert render_main(["--run", str(trained_run), "--pose-matrix", matrix, "--out", str(tmp_path / "m")]) == 0
    assert render_main(["--run", str(tmp_path / "none"), "--pose-matrix", matrix, "--out", str(tmp_path / "x")]) == 2
    capsys.readouterr()
    for bad, message in ((["--state", "object0=nan"], "nan is not in [0, 1]"),
                         (["--state", "object0=5"], "5 is not in"),
                         (["--pose-matrix", "nan 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"], "NaN or infinite"),
                         (["--pose-matrix", "0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1"], "not orthonormal")):
        pose = [] if "--pose-matrix" in bad else ["--pose-matrix", matrix]
        assert render_main(["--run", str(trained_run), *pose, *bad, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err
        assert message in err
        assert "--pose-matrix" not in bad or "fix: give a finite rigid camera-to-world matrix" in err
    assert not (tmp_path / "bad").exists()
    bad = ["--run", str(trained_run), "--pose", f"{tiny_dataset.root}/transforms.json:frame_00001", "--out", str(out)]
    assert render_main(bad) == 2
    err = capsys.readouterr().err
    assert "no frame with id 'frame_00001' (an image name? its id is '00001')" in err
    assert "fix: pick one of the dataset's frame ids: 00000, 00001" in err


def test_a_model_of_an_older_format_is_refused_with_the_fix(trained_run, tmp_path):
    import shutil

    import torch

    old = tmp_path / "old"
    shutil.copytree(trained_run, old)
    payload = torch.load(old / "model.pt", weights_only=True)
    payload["format"] = 1
    torch.save(payload, old / "model.pt")
    with pytest.raises(InputError, match=r"older version.*retrain"):
        load_run(old)


def test_a_truncated_model_is_refused_with_the_fix(trained_run, tmp_path):
    import shutil

    cut = tmp_path / "cut"
    shutil.copytree(trained_run, cut)
    (cut / "model.pt").write_bytes((trained_run / "model.pt").read_bytes()[:1000])
    with pytest.raises(InputError, match=r"model\.pt: cannot be read, truncated or corrupt.*fix: copy the run"):
        load_run(cut)


def test_weights_holding_nan_are_refused_with_the_fix(trained_run, tmp_path):
    import shutil

    import torch

    bad = tmp_path / "nan"
    shutil.copytree(trained_run, bad)
    payload = torch.load(bad / "model.pt", weights_only=True)
    name = next(k for k in payload["state_dict"] if k.endswith("weight"))  # a parameter (buffers may hold NaN)
    payload["state_dict"][name].view(-1)[:3] = torch.tensor([float("nan"), float("inf"), 0.5])
    torch.save(payload, bad / "model.pt")
    with pytest.raises(InputError, match=rf"model\.pt: 2 weights are NaN or infinite, in {name} \(2\).*fix: copy"):
        load_run(bad)


def test_render_into_the_run_folder_is_refused_and_the_run_kept(trained_run, tiny_dataset, tmp_path, capsys):
    import shutil

    run = tmp_path / "run_copy"
    shutil.copytree(trained_run, run)
    before = sorted(p.name for p in run.iterdir())
    rc = render_main(["--run", str(run), "--pose", f"{tiny_dataset.root}/transforms.json:00001", "--out", str(run)])
    assert rc == 2 and "is the input" in capsys.readouterr().err
    assert sorted(p.name for p in run.iterdir()) == before


def test_the_runs_dataset_is_found_from_the_cwd_or_the_run_folders_ancestors(tmp_path, monkeypatch):
    """config.yaml keeps --data as training got it (relative to where it ran): a moved results tree still opens."""
    root = tmp_path / "moved" / "repo"
    dataset, run = root / "results" / "s" / "dataset", root / "results" / "s" / "runs" / "livescene"
    dataset.mkdir(parents=True)
    run.mkdir(parents=True)
    (run / "config.yaml").write_text("data: results/s/dataset\n")
    monkeypatch.chdir(tmp_path)  # not where training ran: found through the run folder's ancestors
    assert dataset_of_run(run).resolve() == dataset.resolve()
    monkeypatch.chdir(root)  # where training ran: the path as written
    assert dataset_of_run(run) == Path("results/s/dataset")
    assert dataset_of_run(run, "elsewhere") == Path("elsewhere")  # --data wins
    (run / "config.yaml").write_text("data: results/other/dataset\n")
    with pytest.raises(InputError, match="names the dataset results/other/dataset, which is not there"):
        dataset_of_run(run)


SHARES = [0.1, 0.6, 0.2, 0.1]  # three objects and the background


def _fake_model(run, monkeypatch, seen: list) -> None:
    """Replace the run's model by one whose outputs are known: depth = the ray's near (its box entry, normalised
    units), with the logits the rendered probabilities (focal_mask_on: probabilities) of shares SHARES and a ray
    weight of 0.5, rgb and accumulation 0.5."""
    import torch

    def forward(rays, step=0, outputs=(), **kwargs):
        seen.append(rays)
        n = len(rays)
        assert rays.states.shape[1] + 1 == len(SHARES)
        out = {"rgb": torch.full((n, 3), 0.5), "depth": rays.nears.clone(), "accumulation": torch.full((n,), 0.5),
               "logits": torch.zeros(n, len(SHARES))}
        out = {k: v for k, v in out.items() if k in outputs}
        if "logits" in outputs:
            out["probs"] = 0.5 * torch.tensor(SHARES).expand(n, len(SHARES))
        return out

    monkeypatch.setattr(run.model, "forward", forward)


def test_render_rays_returns_depth_in_dataset_units(trained_run, monkeypatch):
    # a scene box [-2, 2]^3: the normalised scene is the dataset's scaled by 0.5. A camera at world (0, 0, -6)
    # looking along +z enters the box at world z = -2, 4 dataset units away (2 normalised units)
    from stages.model.scene_normalization import SceneNormalization

    run = load_run(trained_run)
    run.norm = SceneNormalization(np.diag([0.5, 0.5, 0.5, 1.0]), "scene_box")
    assert run.norm.scale == pytest.approx(0.5)
    _fake_model(run, monkeypatch, [])
    out = run.render_rays(np.array([[0.0, 0.0, -6.0]]), np.array([[0.0, 0.0, 1.0]]), np.zeros(len(run.objects)),
                          outputs=("depth",))
    assert out["depth"] == pytest.approx([4.0], rel=1e-6)


def test_rendered_probabilities_are_divided_by_the_rays_weight(trained_run, monkeypatch):
    # rendered probabilities (focal_mask_on: probabilities) sum to the ray's weight, 0.5 here: the image shows the
    # shares of the weight, SHARES, which sum to 1
    run = load_run(trained_run)
    _fake_model(run, monkeypatch, [])
    out = run.render_rays(np.zeros((3, 3)), np.eye(3), np.zeros(len(run.objects)), outputs=("probs",))
    np.testing.assert_allclose(out["probs"], np.tile(SHARES, (3, 1)), rtol=1e-6)


def test_render_rays_gives_every_ray_the_requested_time(trained_run, monkeypatch):
    import torch

    run = load_run(trained_run)
    seen: list = []
    _fake_model(run, monkeypatch, seen)
    run.render_rays(np.zeros((5, 3)), np.tile([1.0, 0.0, 0.0], (5, 1)), np.zeros(len(run.objects)), time_value=0.6,
                    outputs=("rgb",))
    times = torch.cat([r.times for r in seen])
    assert times.shape == (5,) and torch.all(times == torch.tensor(0.6))
