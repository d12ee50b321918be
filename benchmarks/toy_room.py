"""A small analytic interactive scene (boxes, ray-cast in numpy) for developing and measuring the model.

Used by the benchmarks when the synthetic capture generator's ``demo`` capture
is not at hand. A floor, a static table, a cabinet whose door swings open
(object ``door``) and a chest whose drawer slides out (object ``drawer``).
Every surface carries a procedural texture so the model has detail to learn;
shading is Lambertian (view-independent). ``ToyRoom.render`` gives rgb, ray
distance and object ids for any pose and any states, so the benchmarks have
ground truth at unseen state combinations.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import this_checkout  # noqa: F401  (this checkout's stages, here and in subprocesses)

from stages.scene import Camera, Frame, SceneDataset, generate_rays, label_map_to_onehot, write_mask, write_scene

OBJECTS = ["door", "drawer"]
LIGHT = np.array([0.4, -0.5, 0.77]) / np.linalg.norm([0.4, -0.5, 0.77])


@dataclass
class Box:
    centre: np.ndarray
    rotation: np.ndarray  # columns = local axes in world
    half: np.ndarray
    colour: np.ndarray
    object_id: int = 0  # 0 static, k = OBJECTS[k - 1]
    texture: float = 6.0  # stripes per unit length


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    back = eye - target
    back = back / np.linalg.norm(back)
    right = np.cross(np.asarray(up, float), back)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(back, right), back, eye
    return m


class ToyRoom:
    """The scene for a given state vector (door, drawer) in [0, 1]."""

    scene_box = np.array([[-2.0, -2.0, -0.1], [2.0, 2.0, 1.9]])

    def boxes(self, states: dict[str, float]) -> list[Box]:
        door, drawer = float(states.get("door", 0.0)), float(states.get("drawer", 0.0))
        eye = np.eye(3)
        out = [
            Box(np.array([0.0, 0.0, -0.05]), eye, np.array([1.9, 1.9, 0.05]), np.array([0.55, 0.5, 0.42]), 0, 2.0),
            Box(np.array([0.2, 0.9, 0.35]), eye, np.array([0.5, 0.3, 0.35]), np.array([0.3, 0.45, 0.6]), 0, 5.0),
            # cabinet body (open towards -y) and its door hinged at x = -1.2
            Box(np.array([-0.8, -0.6, 0.6]), eye, np.array([0.4, 0.3, 0.6]), np.array([0.75, 0.7, 0.6]), 0, 4.0),
            # chest of the drawer
            Box(np.array([1.0, -0.4, 0.3]), eye, np.array([0.35, 0.35, 0.3]), np.array([0.35, 0.3, 0.25]), 0, 3.0),
        ]
        angle = -door * np.pi / 2  # swings outward around the hinge at its -x edge
        hinge = np.array([-1.2, -0.92, 0.6])
        r = rot_z(angle)
        out.append(Box(hinge + r @ np.array([0.4, 0.0, 0.0]), r, np.array([0.4, 0.02, 0.58]),
                       np.array([0.85, 0.25, 0.2]), 1, 7.0))
        slide = 0.45 * drawer
        out.append(Box(np.array([1.0, -0.78 - slide, 0.35]), eye, np.array([0.3, 0.05, 0.12]),
                       np.array([0.2, 0.7, 0.35]), 2, 8.0))
        return out

    def render(self, c2w: np.ndarray, states: dict[str, float], camera: Camera) -> dict[str, np.ndarray]:
        origins, dirs = generate_rays(camera, c2w)
        o, d = origins.reshape(-1, 3), dirs.reshape(-1, 3)
        n = o.shape[0]
        best_t = np.full(n, np.inf)
        rgb = np.ones((n, 3))
        ids = np.zeros(n, dtype=np.int32)
        for box in self.boxes(states):
            lo_ = (o - box.centre) @ box.rotation
            ld = d @ box.rotation
            ld = np.where(np.abs(ld) < 1e-12, 1e-12, ld)
            t1, t2 = (-box.half - lo_) / ld, (box.half - lo_) / ld
            tmin, tmax = np.minimum(t1, t2), np.maximum(t1, t2)
            t_enter, t_exit = tmin.max(axis=1), tmax.min(axis=1)
            hit = (t_enter <= t_exit) & (t_enter > 1e-4) & (t_enter < best_t)
            if not hit.any():
                continue
            axis = tmin[hit].argmax(axis=1)
            p_local = lo_[hit] + ld[hit] * t_enter[hit, None]
            sign = np.sign(p_local[np.arange(axis.size), axis])
            normal = box.rotation[:, axis].T * sign[:, None]
            shade = 0.45 + 0.55 * np.clip(normal @ LIGHT, 0.0, 1.0)
            u = p_local * box.texture
            wave = np.sin(u[:, 0] * 3.1 + 1.3 * np.sin(u[:, 1] * 2.3)) * np.cos(u[:, 2] * 2.7 + u[:, 1])
            pattern = 0.85 + 0.15 * wave
            rgb[hit] = np.clip(box.colour[None] * pattern[:, None] * shade[:, None], 0.0, 1.0)
            ids[hit] = box.object_id
            best_t[hit] = t_enter[hit]
        h, w = camera.height, camera.width
        return {"rgb": rgb.reshape(h, w, 3).astype(np.float32), "depth": best_t.reshape(h, w).astype(np.float32),
                "ids": ids.reshape(h, w)}


def trajectory(n_frames: int) -> tuple[list[np.ndarray], list[dict[str, float]]]:
    """Orbit of the camera and the objects' states over the video (a door cycle and a drawer cycle)."""
    poses, states = [], []
    for i in range(n_frames):
        a = 2 * np.pi * i / n_frames - np.pi / 2
        radius, height = 3.2 + 0.3 * np.sin(3 * a), 1.7 + 0.25 * np.cos(2 * a)
        poses.append(look_at(np.array([radius * np.cos(a), radius * np.sin(a), height]), np.array([0.0, 0.0, 0.45])))
        f = i / max(n_frames - 1, 1)
        states.append({"door": float(0.5 - 0.5 * np.cos(2 * np.pi * 1.5 * f)),
                       "drawer": float(0.5 - 0.5 * np.cos(2 * np.pi * 1.0 * f + 0.9))})
    return poses, states


def write_toy_dataset(root: str | Path, n_frames: int = 60, width: int = 128, height: int = 96,
                      key_every: int = 10) -> SceneDataset:
    """A scene dataset of the toy room: alternate split (even frames test), dense truth states, masks."""
    root = Path(root)
    (root / "images").mkdir(parents=True, exist_ok=True)
    camera = Camera(fx=0.9 * width, fy=0.9 * width, cx=width / 2, cy=height / 2, width=width, height=height)
    room = ToyRoom()
    frames, keys = [], {}
    poses, states = trajectory(n_frames)
    for i, (c2w, st) in enumerate(zip(poses, states, strict=True)):
        out = room.render(c2w, st, camera)
        fid = f"{i:05d}"
        path = f"images/frame_{fid}.png"
        img = np.clip(out["rgb"] * 255 + 0.5, 0, 255).astype(np.uint8)[..., ::-1]
        cv2.imwrite(str(root / path), img)
        labels = np.where(out["ids"] == 0, len(OBJECTS), out["ids"] - 1)
        write_mask(root, fid, label_map_to_onehot(labels, len(OBJECTS)))
        frames.append(Frame(file_path=path, c2w=c2w, state=st, split="test" if i % 2 == 0 else "train",
                            source_index=i))
        if i % key_every == 0:
            keys[fid] = dict(st)
    ds = SceneDataset(root=root, camera=camera, frames=frames, objects=list(OBJECTS), object_ids=[1, 2],
                      key_frames=keys, scene_box=room.scene_box, meta={"units": "m", "source": "toy_room"})
    write_scene(ds, root)
    return ds


if __name__ == "__main__":
    import sys

    write_toy_dataset(sys.argv[1] if len(sys.argv) > 1 else "results/toy_room")
