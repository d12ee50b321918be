"""The capture writer: determinism, frame count, truth poses and masks against the truth renderer."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from stages.capture import TruthRenderer, generate_capture
from stages.scene import project_points
from stages.scene.transforms import camera_from_dict


def _files(root: Path, sub: str) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((root / sub).iterdir())}


def test_same_seed_gives_identical_frames_and_another_seed_does_not(tmp_path, small_spec):
    outs = []
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        spec = small_spec(n_frames=3, width=48, height=36)
        spec.seed = seed
        outs.append(generate_capture(spec, tmp_path / name, progress=False))
    a, b, c = outs
    for sub in ("truth/images", "masks", "truth/depth"):
        assert _files(a, sub) == _files(b, sub), sub
    assert (a / "truth" / "transforms.json").read_text() == (b / "truth" / "transforms.json").read_text()
    assert _files(a, "truth/images") != _files(c, "truth/images")


def test_video_has_the_spec_frame_count(tiny_capture):
    meta = json.loads((tiny_capture / "capture.json").read_text())
    cap = cv2.VideoCapture(str(tiny_capture / "video.mp4"))
    assert cap.isOpened()
    declared = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    decoded = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        assert frame.shape == (meta["height"], meta["width"], 3)
        decoded += 1
    cap.release()
    assert decoded == declared == meta["n_frames"] == 8
    assert len(list((tiny_capture / "masks").glob("frame_*.png"))) == 8


def test_masks_agree_with_truth_renderer_ids(tiny_capture):
    renderer = TruthRenderer.from_capture(tiny_capture)
    frames = renderer.truth_frames()
    for fr in frames[::3]:
        out = renderer.render(np.asarray(fr["transform_matrix"]), fr["state"])
        mask = cv2.imread(str(tiny_capture / "masks" / Path(fr["file_path"]).name), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(out["ids"], mask)
        assert set(np.unique(mask)) <= {0, 1, 2}
    assert {1, 2} <= set(np.unique(mask))


@pytest.mark.parametrize("per_metre", [1.0, 1000.0])
def test_truth_pose_reprojects_a_known_corner(tmp_path, small_spec, per_metre):
    """The top-left front corner of the closed cabinet door lands where the rendered depth puts it."""
    spec = small_spec(n_frames=2, width=96, height=72)
    spec.units.per_metre = per_metre
    cap = generate_capture(spec, tmp_path / "cap", progress=False)
    truth = json.loads((cap / "truth" / "transforms.json").read_text())
    camera = camera_from_dict(truth, cap / "truth" / "transforms.json", "top level")
    frame = truth["frames"][0]
    assert frame["state"]["cabinet"] == 0.0
    cab = spec.objects[0]  # door hinged left, front facing -y, no yaw
    w, d, h = cab.size
    corner = np.array([cab.position[0] - w / 2, cab.position[1] - d / 2 - cab.thickness, cab.position[2] + h])
    corner *= per_metre
    c2w = np.asarray(frame["transform_matrix"])
    uv, z = project_points(camera, c2w, corner[None])
    u, v = uv[0]
    assert 2 < u < camera.width - 2 and 2 < v < camera.height - 2 and z[0] > 0
    depth = np.load(cap / "truth" / "depth" / "frame_00000.npy")
    ids = cv2.imread(str(cap / "masks" / "frame_00000.png"), cv2.IMREAD_UNCHANGED)
    # back-project the cabinet pixels near the projection with the truth depth and pose
    vv, uu = np.mgrid[0:camera.height, 0:camera.width]
    near = (np.hypot(uu + 0.5 - u, vv + 0.5 - v) < 4) & (ids == 1)
    assert near.sum() >= 3
    zz = depth[near]
    cam_pts = np.stack([(uu[near] + 0.5 - camera.cx) / camera.fx * zz,
                        -(vv[near] + 0.5 - camera.cy) / camera.fy * zz, -zz], axis=1)
    world = cam_pts @ c2w[:3, :3].T + c2w[:3, 3]
    best = int(np.argmin(np.linalg.norm(world - corner, axis=1)))
    pixel_dist = np.hypot(uu[near][best] + 0.5 - u, vv[near][best] + 0.5 - v)
    assert pixel_dist < 1.0, (u, v, uu[near][best], vv[near][best])
    footprint = z[0] / camera.fx  # one pixel at the corner's depth
    assert np.linalg.norm(world[best] - corner) < 1.5 * footprint


def test_exposure_jitter_scales_each_frame_and_leaves_the_truth_nominal(tmp_path, small_spec):
    plain = small_spec(n_frames=4, width=48, height=36)
    base = generate_capture(plain, tmp_path / "plain", progress=False)
    jittery = small_spec(n_frames=4, width=48, height=36)
    jittery.video.exposure_jitter, jittery.video.white_balance_jitter = 0.2, 0.05
    out = generate_capture(jittery, tmp_path / "jitter", progress=False)
    gains = np.array(json.loads((out / "capture.json").read_text())["frame_gains"])
    assert gains.shape == (4, 3) and np.ptp(gains.mean(1)) > 0.05  # the frames differ in exposure
    assert json.loads((base / "capture.json").read_text())["frame_gains"] is None
    for k in range(4):
        name = f"frame_{k:05d}.png"
        nominal = cv2.imread(str(base / "truth" / "images" / name))[..., ::-1].astype(float)
        seen = cv2.imread(str(out / "truth" / "images" / name))[..., ::-1].astype(float)
        unclipped = nominal * gains[k] < 254
        # the frame is the nominal one x its gain (both rounded to 8 bits: half a level each, the first scaled)
        assert np.abs(seen - nominal * gains[k])[unclipped].max() <= 0.5 * (1.0 + gains[k].max()) + 1e-9
    assert _files(base, "masks") == _files(out, "masks") and _files(base, "truth/depth") == _files(out, "truth/depth")
    # the truth renderer, which evaluation reads, renders at the nominal exposure: without jitter, the frames
    # are its renders rounded to 8 bits, byte for byte (no gain of one, which would round some pixels otherwise)
    truth = json.loads((out / "truth" / "transforms.json").read_text())["frames"][0]
    rendered = TruthRenderer.from_capture(out).render(np.array(truth["transform_matrix"]), truth["state"])["rgb"]
    nominal = cv2.imread(str(base / "truth" / "images" / "frame_00000.png"))[..., ::-1]
    assert np.array_equal(np.round(np.clip(rendered, 0.0, 1.0) * 255.0).astype(np.uint8), nominal)
