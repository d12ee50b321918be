"""Procedural surface textures: enough structure for COLMAP, smooth enough for a small radiance field.

Structure sits at mid frequencies: the finest noise scale is 1.5 texels (at
the demo's 1 cm texels and ~7 mm pixels that is 2 pixels), blobs and stripes
span a few to tens of pixels. Per-pixel noise would give SIFT nothing stable
to match and would cap a radiance field's PSNR, so there is none. Every
texture is periodic (wrap-around filtering) so tiling leaves no seams, and is
seeded by the material name so each surface looks different yet the same for
a seed.
"""

from __future__ import annotations

import json
import logging
import zipfile
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from .camera_path import seeded_rng
from .geometry import Material

TEXTURE_CODE_VERSION = "1"
"""Bump whenever ``make_texture``'s output changes: atlases cached by earlier code then no longer match."""

log = logging.getLogger(__name__)


def _noise(rng: np.random.Generator, size: int, sigmas: tuple[float, ...], weights: tuple[float, ...]) -> np.ndarray:
    """Periodic multi-scale smoothed noise, unit standard deviation."""
    out = np.zeros((size, size))
    for sigma, w in zip(sigmas, weights, strict=True):
        layer = gaussian_filter(rng.standard_normal((size, size)), sigma, mode="wrap")
        out += w * layer / (layer.std() + 1e-12)
    return out / (out.std() + 1e-12)


def _blobs(rng: np.random.Generator, size: int, count: int, radii: tuple[float, float]) -> np.ndarray:
    """Discs and ellipses of random signed intensity, drawn with wrap-around."""
    canvas = np.zeros((size, size), dtype=np.float32)
    for _ in range(count):
        cx, cy = rng.uniform(0, size, 2)
        ax = rng.uniform(*radii, size=2)
        angle = float(rng.uniform(0, 180))
        value = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0))
        for dx in (-size, 0, size):
            for dy in (-size, 0, size):
                centre = (round(cx + dx), round(cy + dy))
                axes = (max(1, round(ax[0])), max(1, round(ax[1])))
                cv2.ellipse(canvas, centre, axes, angle, 0, 360, value, -1, cv2.LINE_AA)
    canvas = gaussian_filter(canvas.astype(np.float64), 1.0, mode="wrap")
    return canvas / (canvas.std() + 1e-12)


def _pattern(rng: np.random.Generator, style: str, size: int) -> np.ndarray:
    """Scalar pattern, roughly zero mean and unit deviation."""
    coarse = _noise(rng, size, (1.5, 4.0, 12.0), (0.25, 0.4, 0.6))
    if style == "grain":  # planks: stripes along one axis warped by noise, plus board joints
        y = np.arange(size)[:, None] * np.ones((1, size))
        period = rng.uniform(10, 22)
        warp = gaussian_filter(rng.standard_normal((size, size)), 16, mode="wrap")
        warp /= warp.std() + 1e-12
        # an integer number of periods across the texture keeps it periodic
        cycles = max(1, round(size / period))
        stripes = np.sin(2 * np.pi * (y * cycles / size + 0.35 * warp))
        boards = max(1, round(size / rng.uniform(60, 110)))
        joints = -2.0 * (np.abs(((y * boards / size) % 1.0) - 0.5) > 0.47)
        return 0.7 * stripes + 0.6 * coarse + joints
    if style == "tiles":
        u = np.arange(size)
        cells = max(1, round(size / rng.uniform(40, 70)))
        line = (np.abs(((u * cells / size) % 1.0) - 0.5) > 0.46).astype(float)
        grid = np.maximum(line[:, None], line[None, :])
        return 0.8 * coarse - 2.0 * gaussian_filter(grid, 0.8, mode="wrap") + 0.5 * _blobs(rng, size, 60, (3, 9))
    if style == "speckle":
        return 0.7 * coarse + 0.7 * _blobs(rng, size, size // 2, (1.5, 5))
    # blobs
    return 0.5 * coarse + _blobs(rng, size, size // 3, (2.5, 16))


def make_texture(material: Material, seed: int, size: int, contrast: float) -> np.ndarray:
    """``[size, size, 3]`` uint8 texture: base colour modulated by the pattern, with a little hue play."""
    rng = seeded_rng(seed, f"texture/{material.name}")
    pattern = _pattern(rng, material.style, size)
    tint = np.stack([_noise(rng, size, (6.0, 20.0), (0.5, 0.5)) for _ in range(3)], axis=-1)
    shade = 1.0 + contrast * np.clip(pattern, -2.5, 2.5)[..., None] / 1.5 + 0.25 * contrast * tint
    rgb = np.clip(material.color[None, None, :] * shade, 0.0, 1.0)
    return np.round(rgb * 255).astype(np.uint8)


def texture_atlas(materials: list[Material], seed: int, size: int, contrast: float) -> np.ndarray:
    """``[n_materials, size, size, 3]`` uint8, one texture per material, in material order."""
    return np.stack([make_texture(m, seed, size, contrast) for m in materials])


def sample_atlas(atlas: np.ndarray, material: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear, wrapping lookup of texel coordinates ``(u, v)`` in texture ``material``; float32 RGB in [0, 1]."""
    size = atlas.shape[1]
    u = u - 0.5
    v = v - 0.5
    u0, v0 = np.floor(u), np.floor(v)
    fu, fv = (u - u0)[:, None].astype(np.float32), (v - v0)[:, None].astype(np.float32)
    u0 = u0.astype(np.int64) % size
    v0 = v0.astype(np.int64) % size
    u1, v1 = (u0 + 1) % size, (v0 + 1) % size
    c00 = atlas[material, v0, u0].astype(np.float32)
    c01 = atlas[material, v0, u1].astype(np.float32)
    c10 = atlas[material, v1, u0].astype(np.float32)
    c11 = atlas[material, v1, u1].astype(np.float32)
    top = c00 + (c01 - c00) * fu
    bottom = c10 + (c11 - c10) * fu
    return (top + (bottom - top) * fv) / 255.0


def atlas_key(materials: list[Material], seed: int, size: int, contrast: float) -> str:
    """Everything an atlas is a function of, as text: a cached atlas is used only where its key is equal."""
    return json.dumps({"version": TEXTURE_CODE_VERSION, "seed": int(seed), "size": int(size),
                       "contrast": float(contrast),
                       "materials": [[m.name, m.style, [float(c) for c in m.color]] for m in materials]},
                      sort_keys=True)


def save_atlas(path: Path, atlas: np.ndarray, key: str) -> None:
    """Write an atlas with its key (uncompressed ``.npz``: loads in milliseconds)."""
    with path.open("wb") as fh:
        np.savez(fh, atlas=atlas, key=np.array(key))


def cached_atlas(path: Path | None, materials: list[Material], seed: int, size: int, contrast: float) -> np.ndarray:
    """The atlas from ``path`` when it was written for these inputs, else generated (seconds for a room).

    The capture stage writes ``truth/texture_atlas.npz``, so every later truth render (evaluation,
    locality) skips the procedural noise. A missing, unreadable or stale file is only a cache miss.
    """
    key = atlas_key(materials, seed, size, contrast)
    if path is not None and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                if str(data["key"]) == key:
                    return data["atlas"]
            log.info("%s was written for other texture inputs; generating the textures", path)
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
            log.warning("%s is unreadable (%s); generating the textures", path, err)
    return texture_atlas(materials, seed, size, contrast)
