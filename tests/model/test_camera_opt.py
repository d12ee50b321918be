"""Camera refinement (train.camera_opt): the correction's arithmetic, the trainer's corrections (saved, resumed,
skipped with a non-finite step) and the alignment of a view to a frozen model (docs/model.md, "Camera refinement")."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import torch
import yaml

from stages.model import Trainer, load_config, load_run
from stages.model.camera_opt import (
    CameraCorrections,
    align_rays,
    correct_rays,
    corrected_c2w,
    correction_size,
    exponential_factor,
    so3_exp,
)
from stages.model.rays import RayBundle
from stages.model.scene_normalization import SceneNormalization
from stages.scene import InputError

ON = "train.camera_opt=SO3xR3"


def test_so3_exp_is_rodrigues_with_a_finite_gradient_at_zero():
    quarter = so3_exp(torch.tensor([[0.0, 0.0, math.pi / 2]], dtype=torch.float64))[0]
    # a quarter turn about z takes x to y and y to -x
    torch.testing.assert_close(
        quarter @ torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64), torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    )
    torch.testing.assert_close(
        quarter @ torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64),
        torch.tensor([-1.0, 0.0, 0.0], dtype=torch.float64),
    )
    w = torch.zeros(1, 3, requires_grad=True)
    rot = so3_exp(w)
    torch.testing.assert_close(rot[0], torch.eye(3))
    # d/dw_z of R[1, 0] at 0 is 1 (the skew matrix), and nothing is NaN
    (grad,) = torch.autograd.grad(rot[0, 1, 0], w)
    torch.testing.assert_close(grad, torch.tensor([[0.0, 0.0, 1.0]]))


def test_a_correction_moves_the_ray_and_its_near_and_far():
    rays = RayBundle(torch.zeros(1, 3), torch.tensor([[1.0, 0.0, 0.0]]), torch.zeros(1), torch.ones(1))
    moved = correct_rays(rays, torch.tensor([[0.0, 0.1, 0.0, 0.0, 0.0, math.pi / 2]]), near_plane=0.05)
    torch.testing.assert_close(moved.origins, torch.tensor([[0.0, 0.1, 0.0]]))
    torch.testing.assert_close(moved.directions, torch.tensor([[0.0, 1.0, 0.0]]))
    # from y = 0.1 along +y the box [-1, 1]^3 ends 0.9 further; it starts behind the origin, so near is the plane
    torch.testing.assert_close(moved.fars, torch.tensor([0.9]))
    torch.testing.assert_close(moved.nears, torch.tensor([0.05]))


def test_a_world_pose_takes_the_correction_of_the_normalised_scene():
    # x_unit = 0.5 x_world + 1: a step of 0.1 in the unit box is 0.2 in the world
    transform = np.diag([0.5, 0.5, 0.5, 1.0])
    transform[:3, 3] = 1.0
    c2w = np.eye(4)
    c2w[:3, 3] = [1.0, 2.0, 3.0]
    out = corrected_c2w(c2w, np.array([0.1, 0.0, 0.0, 0.0, 0.0, math.pi / 2]), SceneNormalization(transform, "t"))
    np.testing.assert_allclose(out[:3, 3], [1.2, 2.0, 3.0])
    np.testing.assert_allclose(out[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)


def test_camera_opt_is_off_by_default_and_absent_from_the_config(tiny_dataset, tmp_path, tiny_config):
    trainer = Trainer(tiny_config(tiny_dataset.root, steps=2), tmp_path / "run", device="cpu", progress=False)
    assert trainer.cameras is None and trainer.camera_optimizer is None
    assert [n for n, _ in trainer._checked_params] == [n for n, _ in trainer.model.named_parameters()]
    trainer.train()
    assert "camera_opt" not in yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())["train"]
    assert "camera_opt" not in torch.load(tmp_path / "run" / "model.pt", weights_only=True)
    assert "camera_opt" not in json.loads((tmp_path / "run" / "run.json").read_text())
    assert not load_run(tmp_path / "run").refined_cameras


def test_an_unknown_mode_is_refused():
    with pytest.raises(InputError, match="camera_opt"):
        load_config("cpu-demo", ["train.camera_opt=SE3"])


def test_refined_cameras_are_saved_per_training_frame(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "run"
    summary = Trainer(tiny_config(tiny_dataset.root, ON, steps=4), out, device="cpu", progress=False).train()
    payload = torch.load(out / "model.pt", weights_only=True)["camera_opt"]
    train_ids = [f.frame_id for f in tiny_dataset.frames_in("train")]
    assert payload["mode"] == "SO3xR3" and payload["frame_ids"] == train_ids
    assert payload["adjustment"].shape == (len(train_ids), 6) and bool(payload["adjustment"].abs().sum() > 0)
    assert summary["camera_opt"]["frames"] == len(train_ids)
    assert yaml.safe_load((out / "config.yaml").read_text())["train"]["camera_opt"] == "SO3xR3"
    run = load_run(out)
    assert run.refined_cameras and run.camera_opt["frame_ids"] == train_ids


def test_a_resumed_refined_run_is_bit_identical(tiny_dataset, tmp_path, tiny_config):
    config = tiny_config(tiny_dataset.root, ON, "train.checkpoint_every=2", steps=4)
    straight = tmp_path / "straight"
    Trainer(config, straight, device="cpu", progress=False).train()
    interrupted = tmp_path / "interrupted"
    trainer = Trainer(config, interrupted, device="cpu", progress=False)
    original = trainer.train_step

    def step_then_stop():
        result = original()
        if trainer.step == 1:
            trainer.request_stop("sigterm")
        return result

    trainer.train_step = step_then_stop
    assert trainer.train() == {"status": "sigterm", "step": 2}
    Trainer(config, interrupted, device="cpu", progress=False, resume=True).train()
    a, b = (torch.load(d / "model.pt", weights_only=True) for d in (straight, interrupted))
    torch.testing.assert_close(a["camera_opt"]["adjustment"], b["camera_opt"]["adjustment"], rtol=0, atol=0)
    for k in a["state_dict"]:
        torch.testing.assert_close(a["state_dict"][k], b["state_dict"][k], rtol=0, atol=0, equal_nan=True, msg=k)
    # a checkpoint of an unrefined run is another run: it does not resume into a refined one
    plain = tmp_path / "plain"
    Trainer(
        tiny_config(tiny_dataset.root, "train.checkpoint_every=2", steps=2), plain, device="cpu", progress=False
    ).train()
    with pytest.raises(InputError, match=r"train\.camera_opt"):
        Trainer(
            tiny_config(tiny_dataset.root, ON, "train.checkpoint_every=2", steps=4),
            plain,
            device="cpu",
            progress=False,
            resume=True,
        ).train()


def test_a_non_finite_correction_skips_the_step_on_the_device(tiny_dataset, tmp_path, tiny_config, capsys):
    trainer = Trainer(tiny_config(tiny_dataset.root, ON, steps=4), tmp_path / "run", device="cpu", progress=False)
    real = trainer.cameras.penalty
    trainer.cameras.penalty = lambda *a: real(*a) * float("nan")
    trainer.train_step()
    assert trainer.flush_steps() == [None]
    assert "non-finite loss term(s) ['camera_opt']" in capsys.readouterr().err
    assert bool((trainer.cameras.adjustment == 0).all())


def test_the_loss_log_keeps_its_columns_with_refinement(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "run"
    Trainer(tiny_config(tiny_dataset.root, ON, steps=2), out, device="cpu", progress=False).train()
    with (out / "train_log.csv").open() as fh:
        header = next(csv.reader(fh))
    assert "camera_opt" not in header and header[:4] == ["wall_s", "step", "lr", "loss"]


def test_alignment_recovers_a_known_correction():
    """A frozen 'model' whose colour is a smooth function of the point one unit along the ray: the view rendered
    with a known correction is matched by aligning the uncorrected rays (100 steps, fixed pixels)."""
    g = torch.Generator().manual_seed(0)
    n = 400
    origins = torch.rand(n, 3, generator=g) * 0.2 - 0.1
    directions = torch.nn.functional.normalize(torch.rand(n, 3, generator=g) - 0.5 + torch.tensor([0, 0, -1.0]), dim=-1)

    def render(rays: RayBundle) -> torch.Tensor:
        p = rays.origins + rays.directions
        return 0.5 + 0.5 * torch.sin(3.0 * p)

    truth = torch.tensor([[0.02, -0.01, 0.015, 0.01, -0.02, 0.005]])
    target = render(
        correct_rays(RayBundle(origins, directions, origins[:, 0], origins[:, 0]), truth.expand(n, 6), 0.05)
    ).detach()
    found = align_rays(render, origins, directions, target, 0.05, seed=0, steps=100, rays_per_step=256)
    np.testing.assert_allclose(found, truth[0].numpy(), atol=2e-3)
    again = align_rays(render, origins, directions, target, 0.05, seed=0, steps=100, rays_per_step=256)
    np.testing.assert_array_equal(found, again)


def test_a_loaded_refined_run_aligns_a_view_with_its_weights_frozen(tiny_dataset, tmp_path, tiny_config):
    out = tmp_path / "run"
    Trainer(tiny_config(tiny_dataset.root, ON, steps=2), out, device="cpu", progress=False).train()
    run = load_run(out)
    before = {k: v.clone() for k, v in run.model.state_dict().items()}
    frame = tiny_dataset.frames_in("test")[0]
    index = tiny_dataset.frames.index(frame)
    found = [
        run.align_pose(
            tiny_dataset.camera_of(frame),
            frame.c2w,
            tiny_dataset.load_image(frame),
            frame.state,
            frame_index=index,
            seed=index,
        )
        for _ in range(2)
    ]
    np.testing.assert_array_equal(found[0][0], found[1][0])  # the same pose every time
    c2w, adjustment = found[0]
    assert adjustment.shape == (6,) and np.isfinite(adjustment).all()
    np.testing.assert_allclose(c2w, corrected_c2w(frame.c2w, adjustment, run.norm))
    for k, v in run.model.state_dict().items():
        torch.testing.assert_close(v, before[k], rtol=0, atol=0, equal_nan=True, msg=k)
    assert all(p.requires_grad for p in run.model.parameters())


def test_alignment_leaves_a_view_that_fits_at_its_pose():
    """A view whose given pose already fits is not moved: every step's correction is scored and the best kept (new
    pixels at every step made the alignment a random walk that moved true demo poses by 0.65 degrees)."""
    g = torch.Generator().manual_seed(1)
    origins = torch.zeros(300, 3)
    directions = torch.nn.functional.normalize(
        torch.rand(300, 3, generator=g) - 0.5 + torch.tensor([0, 0, -1.0]), dim=-1
    )

    def render(rays: RayBundle) -> torch.Tensor:
        return 0.5 + 0.5 * torch.sin(3.0 * (rays.origins + rays.directions))

    target = render(RayBundle(origins, directions, origins[:, 0], origins[:, 0]))
    found = align_rays(render, origins, directions, target, 0.05, seed=0)
    np.testing.assert_array_equal(found, np.zeros(6))


@pytest.mark.parametrize("mode", ["SO3xR3", "off"])
def test_the_train_cli_takes_camera_opt(tiny_dataset, tmp_path, tiny_overrides, mode):
    from stages.model.train_cli import main as train_main

    sets = [a for o in tiny_overrides for a in ("--set", o)]
    args = ["--data", str(tiny_dataset.root), "--out", str(tmp_path / "run"), "--max-steps", "2", "--device", "cpu"]
    assert train_main([*args, *sets, "--camera-opt", mode, "--no-progress"]) == 0
    train = yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())["train"]
    assert train.get("camera_opt", "off") == mode


def _rodrigues(w: np.ndarray) -> np.ndarray:
    """R = cos t I + sin t [k]x + (1 - cos t) k k^T, t = |w|, k = w / t (float64, by hand)."""
    t = float(np.linalg.norm(w))
    k = w / t
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return math.cos(t) * np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * np.outer(k, k)


@pytest.mark.parametrize("theta2", [5e-7, 5e-3])  # either side of the Taylor series' 1e-6
def test_so3_exp_is_exact_in_float64_near_zero(theta2: float):
    w = np.array([1.0, -2.0, 0.5]) * math.sqrt(theta2 / 5.25)
    got = so3_exp(torch.tensor(w[None], dtype=torch.float64))[0].numpy()
    np.testing.assert_allclose(got, _rodrigues(w), rtol=0, atol=1e-15)


def test_penalty_decay_and_sizes_by_hand():
    corrections = CameraCorrections(torch.tensor([0, 1]), 2)
    with torch.no_grad():
        corrections.adjustment.copy_(torch.tensor([[3.0, 4.0, 0, 0, 0, 0], [0, 0, 0, 0, 0.5, 0]]))
    # mean translation length (5 + 0) / 2, mean angle (0 + 0.5) / 2, each length with 1e-12 under its root
    assert float(corrections.penalty(1.0, 10.0).detach()) == pytest.approx(2.5 + 10 * 0.25, abs=1e-4)
    assert exponential_factor(50, 100, 0.1) == pytest.approx(0.1**0.5)
    assert exponential_factor(50, 100, 0.1, time_fraction=0.8) == pytest.approx(0.1**0.8)  # the budget leads
    assert exponential_factor(200, 100, 0.1) == pytest.approx(0.1)
    norm = SceneNormalization(np.diag([0.5, 0.5, 0.5, 1.0]), "t")  # x_unit = 0.5 x_world
    size = correction_size(np.array([0.3, 0.4, 0.0, 0.0, 0.0, math.pi / 2]), norm)
    assert size == pytest.approx({"rotation_deg": 90.0, "translation": 1.0})


def test_a_turned_camera_takes_the_world_rotation_first():
    """The correction turns the camera in world axes: R' = exp(w) R, the rays' ``exp(w) d``, not R exp(w)."""
    c2w = np.eye(4)
    c2w[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # 90 degrees about x
    out = corrected_c2w(c2w, np.array([0, 0, 0, 0, 0, math.pi / 2]), SceneNormalization(np.eye(4), "t"))
    # [[0, -1, 0], [1, 0, 0], [0, 0, 1]] @ R, by hand
    np.testing.assert_allclose(out[:3, :3], [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-12)


def test_alignment_keeps_the_best_pose_and_fits_its_pixels():
    """A first Adam step of lr 1 overshoots a 0.001 offset by far: the zero correction, scored best, is returned;
    the objective is rays_per_step pixels of the view, the same at every step."""
    origins = torch.zeros(50, 3)
    directions = torch.nn.functional.normalize(torch.rand(50, 3, generator=torch.Generator().manual_seed(2)), dim=-1)
    seen = []

    def render(rays: RayBundle) -> torch.Tensor:
        seen.append(len(rays.origins))
        return rays.origins  # the colour is where the ray starts: at zero correction the target's 0.001 off

    found = align_rays(render, origins, directions, origins + 0.001, 0.05, seed=0, steps=3, rays_per_step=20, lr=1.0)
    np.testing.assert_array_equal(found, np.zeros(6))
    assert seen == [20] * 4  # the pose before each of 3 steps and the last one's, 20 pixels each
