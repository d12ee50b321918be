"""Tiny scene datasets for the stability checks, built in a fraction of a second.

Two kinds: :func:`hand_built_dataset` draws images and masks with numpy (so a
check controls exactly the states, masks, object count and units), and
:func:`capture_dataset` renders a named capture preset (``stiff``, ``stress``,
``extreme``, ``demo``, ``tiny``) at a tiny size through ``stages.capture``, then
writes its truth dataset. The presets are read from a folder the caller names
(the ``ctx`` fixture: the package's presets in ``stages/stability/captures`` or
``--captures``), never from the repository's layout: the checks run on an
installed copy as well.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import yaml

from stages.scene import Camera, Frame, SceneDataset, label_map_to_onehot, look_at, write_mask, write_scene

StatesFn = Callable[[int, int], dict[str, float]]
"""(frame index, frame count) -> {object: state}."""
LabelsFn = Callable[[int, int, int], np.ndarray]
"""(frame index, height, width) -> int label map (0..alpha-1 objects, alpha or -1 background)."""


def object_names(n_objects: int) -> list[str]:
    return [f"object{i}" for i in range(n_objects)]


def band_labels(n_objects: int) -> LabelsFn:
    """Object k fills the k-th vertical band of the lower half; the upper half is background."""

    def labels(i: int, h: int, w: int) -> np.ndarray:
        out = np.full((h, w), n_objects, dtype=np.int64)
        if n_objects:
            cols = (np.arange(w) * n_objects) // w
            out[h // 2 :, :] = cols[None, :]
        return out

    return labels


def random_language_targets(path: Path, objects: list[str], *, dim: int = 32, levels: int = 3, seed: int = 0) -> Path:
    """A language targets .npz (docs/data-contract.md, "Language targets") of random unit embeddings: what the
    checks need is a language table to train, not a text encoder."""
    rng = np.random.default_rng(seed)
    emb = rng.normal(size=(len(objects), levels, dim))
    bg = rng.normal(size=dim)
    np.savez(path, objects=np.array(objects), states=np.linspace(0.0, 1.0, levels), encoder="random",
             embeddings=(emb / np.linalg.norm(emb, axis=-1, keepdims=True)).astype(np.float32),
             background=(bg / np.linalg.norm(bg)).astype(np.float32))
    return path


def ramp_states(n_objects: int) -> StatesFn:
    """Every object moves 0 -> 1 over the frames, each with its own phase."""

    def states(i: int, n: int) -> dict[str, float]:
        t = i / max(n - 1, 1)
        return {name: float((t + j / max(n_objects, 1)) % 1.0) for j, name in enumerate(object_names(n_objects))}

    return states


def hand_built_dataset(root: Path, *, n_frames: int = 8, n_objects: int = 2, width: int = 24, height: int = 18,
                       units_scale: float = 1.0, states: StatesFn | None = None, labels: LabelsFn | None = None,
                       box_half: float = 1.0, radius: float = 3.0, seed: int = 0) -> SceneDataset:
    """Cameras on a circle looking at the origin; images are a smooth shading plus one flat colour per object.

    ``units_scale`` multiplies every length (camera centres and the scene box): the
    same scene in metres (1), millimetres (1000) or kilometres (0.001).
    """
    rng = np.random.default_rng(seed)
    names = object_names(n_objects)
    states = states or ramp_states(n_objects)
    labels = labels or band_labels(n_objects)
    colours = rng.uniform(0.1, 0.9, (n_objects + 1, 3))
    camera = Camera(fx=0.9 * width, fy=0.9 * width, cx=width / 2, cy=height / 2, width=width, height=height)
    (root / "images").mkdir(parents=True, exist_ok=True)
    frames = []
    yy, xx = np.mgrid[0:height, 0:width]
    for i in range(n_frames):
        angle = 2 * np.pi * i / n_frames
        eye = np.array([radius * np.cos(angle), radius * np.sin(angle), 0.8]) * units_scale
        c2w = look_at(eye, np.zeros(3))
        fid = f"{i:05d}"
        lab = labels(i, height, width)
        st = states(i, n_frames)
        img = colours[np.clip(lab, 0, n_objects)]
        shade = 0.15 * np.sin(xx / width * np.pi + angle)[..., None] + 0.1 * (yy / height)[..., None]
        for j, name in enumerate(names):  # an object's brightness follows its state, as an opening door would
            img = np.where((lab == j)[..., None], img * (0.6 + 0.4 * st.get(name, 0.0)), img)
        rgb = np.clip(img + shade, 0, 1)
        cv2.imwrite(str(root / "images" / f"frame_{fid}.png"), (rgb[..., ::-1] * 255).round().astype(np.uint8))
        if n_objects:
            write_mask(root, fid, label_map_to_onehot(lab, n_objects))
        frames.append(Frame(file_path=f"images/frame_{fid}.png", c2w=c2w, state=st,
                            split="test" if i % 4 == 3 else "train", source_index=i))
    key_frames = {f.frame_id: dict(f.state or {}) for f in frames[::3]} if n_objects else {}
    ds = SceneDataset(root=root, camera=camera, frames=frames, objects=names, object_ids=list(range(1, n_objects + 1)),
                      key_frames=key_frames,
                      scene_box=np.array([[-box_half] * 3, [box_half] * 3]) * units_scale,
                      meta={"units": f"{units_scale:g} x metre"})
    write_scene(ds, root)
    return ds


def preset_file(presets: Path, preset: str) -> Path:
    """``presets/<preset>.yaml``; a missing one fails the check naming the folder and the way to fix it."""
    path = Path(presets) / f"{preset}.yaml"
    assert path.is_file(), (f"capture preset {path} does not exist; fix: pass --captures DIR with {preset}.yaml "
                            "(e.g. config/captures of a checkout)")
    return path


def capture_spec_data(presets: Path, preset: str, *, width: int, height: int, n_frames: int) -> dict:
    """Capture preset ``preset`` of folder ``presets``, shrunk to a tiny video (lengths and units untouched)."""
    data = yaml.safe_load(preset_file(presets, preset).read_text()) or {}
    data.setdefault("name", preset)
    data.setdefault("video", {}).update(width=width, height=height, n_frames=n_frames)
    render = data.setdefault("render", {})
    render.update(texture_size=64, supersample=1, shadows=False)
    return data


def capture_dataset(workdir: Path, presets: Path, preset: str, *, width: int = 32, height: int = 24,
                    n_frames: int = 8) -> Path:
    """Render a tiny version of a capture preset and write its truth scene dataset; returns the dataset folder."""
    # imported on use: the capture stage takes seconds to import and only the capture checks need it
    from stages.capture import capture_to_dataset, generate_capture, spec_from_dict

    data = capture_spec_data(presets, preset, width=width, height=height, n_frames=n_frames)
    spec = spec_from_dict(data, preset_file(presets, preset))
    cap = workdir / f"capture-{preset}"
    generate_capture(spec, cap, progress=False)
    out = workdir / f"dataset-{preset}"
    capture_to_dataset(cap, out, progress=False)
    return out
