"""Settings of the pose stage, one field per knob the CLI exposes."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from .trajectory_check import TrajectorySettings

Matcher = Literal["sequential", "exhaustive", "auto"]


@dataclass
class PosesConfig:
    """How to run COLMAP on a folder of frames and what to accept as a usable result."""

    frames_dir: Path
    """FRAMES folder of `livescene frames` (images/ + frames.csv), or a plain folder of images."""
    out_dir: Path
    """POSES folder to write (sparse/0, transforms.json, points3D.ply, scene.json, poses.json)."""
    masks_dir: Path | None = None
    """Object masks (PNG id maps, 0 = static scene, or .npy label/one-hot maps); their pixels get no features."""
    matcher: Matcher = "auto"
    """Pairing: sequential (videos), exhaustive (small unordered sets), auto = exhaustive up to
    ``exhaustive_max_images`` frames, sequential above."""
    exhaustive_max_images: int = 40
    """Largest frame count for which ``auto`` picks exhaustive matching (cost grows with n^2)."""
    sequential_overlap: int = 10
    """Sequential matching pairs each frame with this many successors (plus quadratic jumps)."""
    vocab_tree: Path | None = None
    """A COLMAP vocabulary-tree file; when given, sequential matching adds loop-closure pairs."""
    threads: int = -1
    """CPU threads for extraction, matching and mapping (-1 = all cores)."""
    seed: int = 0
    """Random seed for RANSAC and the mapper (results repeat for a fixed seed and thread count)."""
    deterministic: bool = True
    """Run COLMAP (extraction, matching, mapping) on one thread so that a fixed seed gives identical poses run
    after run; False uses ``threads``, faster, and results vary in the last digits."""
    min_registered: float = 0.8
    """Quality gate: smallest accepted fraction of frames with a pose."""
    camera_model: str = "RADIAL"
    """COLMAP camera model shared by all frames (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV).
    RADIAL (one focal length, k1, k2) by measurement: on a real 50-image phone capture its focal error was
    0.05% against SIMPLE_RADIAL's 0.71%, and OPENCV's free fy and tangential terms drifted on the synthetic
    demo (fy 1.8% off, rotation error doubled); docs/poses.md "Camera model"."""
    focal_px: float | None = None
    """A known focal length in pixels of the frames as written (``--focal``); None = estimated by COLMAP."""
    focal_35mm: float | None = None
    """A known 35 mm-equivalent focal length in millimetres (``--focal-35mm``), converted by the image diagonal."""
    refine_focal: bool = False
    """Let bundle adjustment refine a given focal length (default: kept as given; known_focal.py)."""
    max_image_size: int = 1600
    """Frames are downscaled to this longest side for feature extraction (-1 = full size)."""
    max_num_features: int = 8192
    """SIFT features kept per frame."""
    mask_dilate_px: int | None = None
    """Grow object masks by this many pixels before excluding them (None = 1% of the image diagonal)."""
    static_motion_fraction: float = 0.004
    """A camera whose background moves less than this fraction of the image diagonal between every pair of
    sampled frames (pre-check, before COLMAP) or whose matched features do so in every matched pair (after
    matching) is reported as not moving."""
    min_baseline_ratio: float = 0.01
    """Pose gate: the camera centres must span at least this fraction of the median point depth."""
    still_radius_fraction: float = 0.005
    """Pose gate: cameras within this fraction of the median point depth of one camera stand on one spot."""
    max_still_share: float = 0.5
    """Pose gate: refuse a model with more than this share of its cameras on one spot (a tripod clip)."""
    jump_factor: float = 10.0
    """Pose gate: a step between cameras neighbouring in time longer than this many typical steps (per source
    frame) is a jump; short runs that jump away and back are dropped, a path broken by jumps is cut to its
    largest piece when that holds a majority, else refused."""
    jump_floor_fraction: float = 0.05
    """Pose gate: steps shorter than this fraction of the median point depth are never jumps."""
    max_spread_ratio: float = 20.0
    """Pose gate: warn when a camera lies farther than this many median point depths from the middle of the path."""
    orient: bool = True
    """Turn the world so that z is up and x, y follow the walls, origin at the scene box centre (world_frame.py);
    False keeps the frame COLMAP's first image pair gave."""
    keep_database: bool = False
    """Keep COLMAP's database.db in the output (large; useful for debugging)."""
    progress: bool = True
    """Show tqdm progress over the COLMAP steps."""
    verbose: bool = False
    """Let COLMAP print its own (very chatty) log."""

    def trajectory_settings(self) -> TrajectorySettings:
        return TrajectorySettings(min_baseline_ratio=self.min_baseline_ratio, still_radius=self.still_radius_fraction,
                                  max_still_share=self.max_still_share, jump_factor=self.jump_factor,
                                  jump_floor=self.jump_floor_fraction, max_spread_ratio=self.max_spread_ratio)
