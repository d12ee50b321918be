"""Ray-cast rendering of a spec at any camera pose and any object states (open3d RaycastingScene, CPU).

Shading is Lambertian: ``albedo x (ambient + sum_l intensity_l x max(0, n.l) x visible_l)``,
with optional shadow rays to each light. Geometry lives in metres internally;
poses and depth at the interface are in the spec's output units.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import open3d as o3d

from stages.scene import Camera, InputError, generate_rays, read_yaml_mapping
from stages.scene.camera import pixel_directions
from stages.scene.transforms import camera_from_dict

from .geometry import FACE_AXES, FACE_UV_AXES, SceneModel, build_scene
from .lens import lens_camera
from .spec import CaptureSpec, CaptureSpecError, spec_from_dict
from .textures import atlas_key, cached_atlas, sample_atlas, save_atlas

ATLAS_FILE = "texture_atlas.npz"
"""The capture's texture atlas, in ``truth/``: a cache, regenerated from the spec where missing or stale."""
SHADOW_EPS = 1e-3  # metres; lifts shadow-ray origins off the surface to avoid self-hits


class SceneRenderer:
    """Renders one spec; rebuilds the ray-casting scene only when the states change."""

    def __init__(self, spec: CaptureSpec, atlas_file: Path | None = None) -> None:
        """``atlas_file``: a texture atlas cached by the capture stage (used when it matches the spec)."""
        self.spec = spec
        self.model: SceneModel = build_scene(spec)
        r = spec.render
        # what the atlas is a function of, for the cache lookup here and the capture's write_atlas
        self._texture_inputs = (self.model.materials, spec.seed, r.texture_size, r.contrast)
        self.atlas = cached_atlas(atlas_file, *self._texture_inputs)
        rng = np.random.default_rng([spec.seed, 7])
        # a random texture offset per part and face, so no two faces show the same patch
        self.face_offsets = rng.uniform(0, r.texture_size, size=(len(self.model.parts), 6, 2))
        self.camera = lens_camera(spec.video)
        self.scale = float(spec.units.per_metre)
        self._cached_states: np.ndarray | None = None
        self._scene: o3d.t.geometry.RaycastingScene | None = None
        self._poses: np.ndarray | None = None
        self._pixel_dirs: list[tuple[Camera, np.ndarray]] = []  # render_rows' cameras (and supersampled) and rays

    def write_atlas(self, path: Path) -> None:
        """Save the texture atlas with its key, for a later renderer of the same spec to load (``atlas_file``)."""
        save_atlas(path, self.atlas, atlas_key(*self._texture_inputs))

    @property
    def objects(self) -> list[str]:
        return self.spec.object_names

    def state_vector(self, states: Mapping[str, float] | Sequence[float] | np.ndarray | None) -> np.ndarray:
        """Object states in spec order; a mapping may leave objects out (they stay closed)."""
        n = len(self.spec.objects)
        if states is None:
            return np.zeros(n)
        if isinstance(states, Mapping):
            unknown = sorted(set(states) - set(self.objects))
            if unknown:
                raise KeyError(f"unknown objects {unknown}; known: {self.objects}")
            return np.array([float(states.get(name, 0.0)) for name in self.objects])
        vec = np.asarray(states, dtype=np.float64).reshape(-1)
        if len(vec) != n:
            raise ValueError(f"expected {n} states (one per object {self.objects}), got {len(vec)}")
        return vec

    def _prepare(self, states: np.ndarray) -> None:
        if self._cached_states is not None and np.array_equal(states, self._cached_states):
            return
        poses = self.model.part_poses(states)
        verts, tris = self.model.mesh(poses)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(verts), o3d.core.Tensor(tris))
        self._scene, self._poses, self._cached_states = scene, poses, states.copy()

    def _cast(self, origins: np.ndarray, dirs: np.ndarray) -> dict[str, np.ndarray]:
        rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
        ans = self._scene.cast_rays(o3d.core.Tensor(rays))  # type: ignore[union-attr]
        return {k: v.numpy() for k, v in ans.items()}

    def _ids(self, prim: np.ndarray, hit: np.ndarray) -> np.ndarray:
        part = np.where(hit, prim // 12, 0)
        ids = self.model.part_object[part].astype(np.int32)
        if self.spec.mask_scope == "moving":
            ids = np.where(self.model.part_moving[part], ids, 0)
        return np.where(hit, ids, 0)

    def _shade(self, origins: np.ndarray, dirs: np.ndarray, shadows: bool) -> tuple[np.ndarray, dict]:
        """Colour of each ray; also the primary hit and per-light shadow casters (object ids)."""
        ans = self._cast(origins, dirs)
        t = ans["t_hit"].astype(np.float64)
        hit = np.isfinite(t)
        prim = np.where(hit, ans["primitive_ids"].astype(np.int64), 0)
        part = prim // 12
        face = (prim % 12) // 2
        t_safe = np.where(hit, t, 0.0)
        points = origins + dirs * t_safe[:, None]
        poses = self._poses  # type: ignore[assignment]
        rot, centre = poses[part, :3, :3], poses[part, :3, 3]
        local = np.einsum("nji,nj->ni", rot, points - centre)  # R^T (p - c)
        uv_axes = FACE_UV_AXES[face]
        coords = np.take_along_axis(local, uv_axes, axis=1)
        tpm = self.spec.render.texels_per_metre
        texel = coords * tpm + self.face_offsets[part, face]
        material = self.model.face_materials[part, face]
        albedo = sample_atlas(self.atlas, material, texel[:, 0], texel[:, 1])
        normal = np.einsum("nij,nj->ni", rot, _axis_vectors(face))
        facing = np.sum(normal * dirs, axis=1) > 0
        normal[facing] *= -1  # light the side the camera sees
        light_sum = np.full(len(t), self.spec.render.ambient)
        casters = []
        for light in self.spec.render.lights:
            to_light = np.asarray(light.position, dtype=np.float64) - points
            dist = np.linalg.norm(to_light, axis=1)
            ldir = to_light / np.maximum(dist, 1e-9)[:, None]
            ndl = np.clip(np.sum(normal * ldir, axis=1), 0.0, None)
            visible = np.ones(len(t))
            caster = np.zeros(len(t), dtype=np.int32)
            if shadows and light.shadows:
                lit = hit & (ndl > 0)
                idx = np.nonzero(lit)[0]
                if len(idx):
                    sh = self._cast(points[idx] + normal[idx] * SHADOW_EPS, ldir[idx])
                    blocked = sh["t_hit"] < dist[idx] - 2 * SHADOW_EPS
                    visible[idx[blocked]] = 0.0
                    sprim = np.where(blocked, sh["primitive_ids"].astype(np.int64), 0)
                    caster[idx[blocked]] = self._ids(sprim, blocked)[blocked]
                    # a caster id 0 (room, furniture) stays 0; mark "shadowed by background" as -1
                    bg = idx[blocked][caster[idx[blocked]] == 0]
                    caster[bg] = -1
            light_sum = light_sum + light.intensity * ndl * visible
            casters.append(caster)
        rgb = np.where(hit[:, None], albedo * light_sum[:, None], 0.0)
        return np.clip(rgb, 0.0, 1.0), {"t": t, "hit": hit, "prim": prim, "casters": casters}

    def render(self, c2w: np.ndarray, states: Mapping[str, float] | Sequence[float] | np.ndarray | None = None,
               camera: Camera | None = None, *, supersample: int | None = None,
               shadows: bool | None = None) -> dict[str, np.ndarray]:
        """Render a pose (4x4 camera-to-world, OpenGL axes, output units) at the given states.

        Returns ``rgb`` float32 HxWx3 in [0, 1], ``depth`` float32 HxW (distance along the
        camera's viewing axis, output units; 0 where nothing is hit), ``ids`` int32 HxW (0
        background, k = mapping id) and ``shadow_ids`` int32 [lights, H, W] (object id whose
        body shadows the pixel from each light; -1 room or furniture, 0 lit), all at pixel centres.
        """
        camera = camera or self.camera
        ss = int(supersample or self.spec.render.supersample)
        shadows = self.spec.render.shadows if shadows is None else shadows
        state_vec = self.state_vector(states)
        self._prepare(state_vec)
        c2w_m = np.array(c2w, dtype=np.float64, copy=True)
        c2w_m[:3, 3] /= self.scale
        h, w = camera.height, camera.width
        o, d = generate_rays(camera, c2w_m)
        o, d = o.reshape(-1, 3), d.reshape(-1, 3)
        rgb, info = self._shade(o, d, shadows)
        if ss > 1:
            big = camera.scaled(ss)
            so, sd = generate_rays(big, c2w_m)
            srgb, _ = self._shade(so.reshape(-1, 3), sd.reshape(-1, 3), shadows)
            rgb = srgb.reshape(h, ss, w, ss, 3).mean(axis=(1, 3)).reshape(-1, 3)
        forward = -c2w_m[:3, 2]
        depth = np.where(info["hit"], info["t"] * (d @ forward), 0.0) * self.scale
        ids = self._ids(info["prim"], info["hit"])
        return {
            "rgb": rgb.reshape(h, w, 3).astype(np.float32),
            "depth": depth.reshape(h, w).astype(np.float32),
            "ids": ids.reshape(h, w),
            "shadow_ids": np.stack(info["casters"]).reshape(-1, h, w),
        }

    def render_rows(self, c2w_rows: np.ndarray, row_states: np.ndarray, camera: Camera | None = None, *,
                    supersample: int | None = None, shadows: bool | None = None) -> dict[str, np.ndarray]:
        """Render with a pose and object states per image row, as a rolling shutter exposes them: ``c2w_rows``
        ``[H, 4, 4]`` (output units), ``row_states`` ``[H, n_objects]`` in spec order; outputs as ``render``'s.

        Each row's rays leave that row's camera, and its depth is along that camera's viewing axis. A ray-casting
        scene is built per run of rows with equal states (rows of one state cost one scene). Sub-pixel rows of
        ``supersample`` share their pixel row's pose and states.
        """
        camera = camera or self.camera
        ss = int(supersample or self.spec.render.supersample)
        shadows = self.spec.render.shadows if shadows is None else shadows
        h, w = camera.height, camera.width
        c2w_m = np.array(c2w_rows, dtype=np.float64, copy=True).reshape(h, 4, 4)
        c2w_m[:, :3, 3] /= self.scale
        row_states = np.asarray(row_states, dtype=np.float64).reshape(h, -1)

        def rays(cam: Camera, k: int) -> tuple[np.ndarray, np.ndarray]:
            """``[cam.height, cam.width, 3]`` origins and unit directions; image row r // k is the pose's row."""
            cached = [dirs for c, dirs in self._pixel_dirs if c == cam]  # undistorting costs 60 ms at 320x240
            if not cached:
                v, u = np.meshgrid(np.arange(cam.height), np.arange(cam.width), indexing="ij")
                cached = [pixel_directions(cam, u, v)]
                self._pixel_dirs = [*self._pixel_dirs[-1:], (cam, cached[0])]
            rows = c2w_m[np.arange(cam.height) // k]
            d = np.einsum("hwj,hij->hwi", cached[0], rows[:, :3, :3])
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            return np.broadcast_to(rows[:, None, :3, 3], d.shape).copy(), d

        # runs of consecutive rows whose states are equal: one scene each
        change = np.flatnonzero(np.any(row_states[1:] != row_states[:-1], axis=1)) + 1
        runs = list(zip(np.r_[0, change], np.r_[change, h], strict=True))

        def shade_runs(o: np.ndarray, d: np.ndarray, k: int) -> tuple[np.ndarray, dict]:
            rgb = np.zeros((*o.shape[:2], 3))
            info: dict = {"t": np.zeros(o.shape[:2]), "hit": np.zeros(o.shape[:2], dtype=bool),
                          "prim": np.zeros(o.shape[:2], dtype=np.int64),
                          "casters": np.zeros((len(self.spec.render.lights), *o.shape[:2]), dtype=np.int32)}
            for a, b in runs:
                self._prepare(row_states[a])
                band = slice(a * k, b * k)
                c, i = self._shade(o[band].reshape(-1, 3), d[band].reshape(-1, 3), shadows)
                rgb[band] = c.reshape(-1, o.shape[1], 3)
                for key in ("t", "hit", "prim"):
                    info[key][band] = i[key].reshape(-1, o.shape[1])
                info["casters"][:, band] = np.stack(i["casters"]).reshape(-1, (b - a) * k, o.shape[1])
            return rgb, info

        o, d = rays(camera, 1)
        rgb, info = shade_runs(o, d, 1)
        if ss > 1:
            so, sd = rays(camera.scaled(ss), ss)
            srgb, _ = shade_runs(so, sd, ss)
            rgb = srgb.reshape(h, ss, w, ss, 3).mean(axis=(1, 3))
        forward = -c2w_m[:, :3, 2]  # per row
        depth = np.where(info["hit"], info["t"] * np.einsum("hwi,hi->hw", d, forward), 0.0) * self.scale
        ids = self._ids(info["prim"].reshape(-1), info["hit"].reshape(-1)).reshape(h, w)
        return {"rgb": rgb.astype(np.float32), "depth": depth.astype(np.float32), "ids": ids,
                "shadow_ids": info["casters"]}


def _axis_vectors(face: np.ndarray) -> np.ndarray:
    """Outward unit normal of each face in its box's own axes."""
    out = np.zeros((len(face), 3))
    out[np.arange(len(face)), FACE_AXES[face]] = np.where(face % 2 == 1, 1.0, -1.0)
    return out


class TruthRenderer(SceneRenderer):
    """The renderer of a generated capture, rebuilt from ``truth/spec.yaml``; cameras from the truth poses."""

    def __init__(self, spec: CaptureSpec, capture_dir: Path | None = None, camera: Camera | None = None) -> None:
        super().__init__(spec, capture_dir / "truth" / ATLAS_FILE if capture_dir is not None else None)
        self.capture_dir = capture_dir
        if camera is not None:
            self.camera = camera

    @classmethod
    def from_capture(cls, capture_dir: str | Path) -> TruthRenderer:
        capture_dir = Path(capture_dir)
        spec_path = capture_dir / "truth" / "spec.yaml"
        if not spec_path.is_file():
            raise InputError(spec_path, "truth spec not found", "point to a folder written by `livescene capture`")
        spec = spec_from_dict(read_yaml_mapping(spec_path, "the capture spec", error=CaptureSpecError), spec_path)
        tpath = capture_dir / "truth" / "transforms.json"
        camera = None
        if tpath.is_file():
            camera = camera_from_dict(json.loads(tpath.read_text()), tpath, "top level")
        return cls(spec, capture_dir, camera)

    def truth_frames(self) -> list[dict]:
        """The frames of truth/transforms.json (pose, state, source index per video frame)."""
        if self.capture_dir is None:
            return []
        return json.loads((self.capture_dir / "truth" / "transforms.json").read_text())["frames"]
