"""Structure from motion with pycolmap: SIFT extraction, matching, incremental mapping.

Every pycolmap call passes its arguments by keyword, because names and
positions moved between pycolmap 3.x and 4.x; the project pins 4.2.1.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import pycolmap

from .config import PosesConfig
from .known_focal import KnownFocal


@dataclass
class SfmResult:
    """The largest model COLMAP built, with what it took to build it."""

    reconstruction: pycolmap.Reconstruction | None
    """The model with the most registered images; None when mapping produced none."""
    n_models: int
    """How many separate models the mapper produced (more than one = the sequence broke apart)."""
    matcher: str
    """The pairing actually used (sequential or exhaustive)."""
    model_sizes: list[int] = field(default_factory=list)
    """Registered images of every model, largest first."""
    timings: dict[str, float] = field(default_factory=dict)
    """Seconds per step: extract, match, map."""


@contextlib.contextmanager
def colmap_log_level(verbose: bool) -> Iterator[None]:
    """Silence COLMAP's INFO/WARNING log unless asked for (it prints several lines per image)."""
    previous = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = previous if verbose else 2
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = previous


def resolve_matcher(cfg: PosesConfig, n_images: int) -> str:
    if cfg.matcher == "auto":
        return "exhaustive" if n_images <= cfg.exhaustive_max_images else "sequential"
    return cfg.matcher


def worker_threads(cfg: PosesConfig) -> int:
    """COLMAP's threads: one in deterministic mode. Parallel extraction numbers images in the order threads
    finish, and multi-threaded matching and bundle adjustment sum in varying order: two runs of the same
    frames then differ in the last digits, and so does everything trained on those poses."""
    return 1 if cfg.deterministic else cfg.threads


def extract_features(cfg: PosesConfig, database: Path, image_dir: Path, names: list[str],
                     mask_dir: Path | None, focal: KnownFocal | None = None) -> None:
    """SIFT on every frame into ``database``; one shared camera (the frames come from one video), starting from a
    known focal length when one is given (COLMAP's ``--ImageReader.camera_params``: the camera then has a prior
    focal length, which the mapper uses rather than estimating one)."""
    reader = pycolmap.ImageReaderOptions(camera_model=cfg.camera_model)
    if focal is not None:
        reader.camera_params = focal.camera_params(cfg.camera_model)
    if mask_dir is not None:
        reader.mask_path = str(mask_dir)
    extraction = pycolmap.FeatureExtractionOptions(num_threads=worker_threads(cfg), max_image_size=cfg.max_image_size,
                                                   use_gpu=False)
    extraction.sift.max_num_features = cfg.max_num_features
    pycolmap.extract_features(database_path=database, image_path=image_dir, image_names=names,
                              camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                              extraction_options=extraction, device=pycolmap.Device.cpu)


def match_features(cfg: PosesConfig, database: Path, matcher: str) -> None:
    """Match and geometrically verify image pairs chosen by ``matcher``."""
    matching = pycolmap.FeatureMatchingOptions(num_threads=worker_threads(cfg), use_gpu=False)
    verification = pycolmap.TwoViewGeometryOptions()
    verification.ransac.random_seed = cfg.seed
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(database_path=database, matching_options=matching,
                                  pairing_options=pycolmap.ExhaustivePairingOptions(),
                                  verification_options=verification, device=pycolmap.Device.cpu)
        return
    pairing = pycolmap.SequentialPairingOptions(overlap=cfg.sequential_overlap, quadratic_overlap=True,
                                                num_threads=worker_threads(cfg))
    if cfg.vocab_tree is not None:
        pairing.loop_detection = True
        pairing.vocab_tree_path = str(cfg.vocab_tree)
    pycolmap.match_sequential(database_path=database, matching_options=matching, pairing_options=pairing,
                              verification_options=verification, device=pycolmap.Device.cpu)


def map_incrementally(cfg: PosesConfig, database: Path, image_dir: Path, models_dir: Path,
                      n_images: int, focal: KnownFocal | None = None) -> dict[int, pycolmap.Reconstruction]:
    """Incremental mapping with a fixed seed and thread count; returns every model built. A known focal length is
    kept as given by bundle adjustment and image registration unless ``focal.refine``."""
    options = pycolmap.IncrementalPipelineOptions(num_threads=worker_threads(cfg), random_seed=cfg.seed,
                                                  multiple_models=True,
                                                  # short sequences still get a model the gate can judge
                                                  min_model_size=min(10, max(2, n_images // 2)))
    options.mapper.num_threads = worker_threads(cfg)
    options.mapper.random_seed = cfg.seed
    options.triangulation.random_seed = cfg.seed
    if focal is not None and not focal.refine:
        options.ba_refine_focal_length = False
        options.mapper.abs_pose_refine_focal_length = False
    models_dir.mkdir(parents=True, exist_ok=True)
    return pycolmap.incremental_mapping(database_path=database, image_path=image_dir, output_path=models_dir,
                                        options=options)


def largest_model(models: dict[int, pycolmap.Reconstruction]) -> pycolmap.Reconstruction | None:
    """The model with the most registered images (ties: more 3D points)."""
    if not models:
        return None
    return max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()))


def run_sfm(cfg: PosesConfig, database: Path, image_dir: Path, names: list[str], mask_dir: Path | None,
            models_dir: Path, after_matching: object = None, focal: KnownFocal | None = None) -> SfmResult:
    """Extract, match, (check motion via ``after_matching(database)``), then map.

    ``after_matching`` lets the caller reject a static camera before the
    mapper spends minutes failing to initialise.
    """
    pycolmap.set_random_seed(seed=cfg.seed)
    matcher = resolve_matcher(cfg, len(names))
    timings: dict[str, float] = {}
    steps = ["extract", "match", "map"]
    from tqdm import tqdm

    with colmap_log_level(cfg.verbose), tqdm(total=len(steps), desc="poses", unit="step",
                                             disable=not cfg.progress) as bar:
        t0 = time.perf_counter()
        bar.set_postfix_str(f"SIFT on {len(names)} frames")
        extract_features(cfg, database, image_dir, names, mask_dir, focal)
        timings["extract"] = time.perf_counter() - t0
        bar.update()
        t0 = time.perf_counter()
        bar.set_postfix_str(f"{matcher} matching")
        match_features(cfg, database, matcher)
        timings["match"] = time.perf_counter() - t0
        bar.update()
        if callable(after_matching):
            after_matching(database)
        t0 = time.perf_counter()
        bar.set_postfix_str("incremental mapping")
        models = map_incrementally(cfg, database, image_dir, models_dir, len(names), focal)
        timings["map"] = time.perf_counter() - t0
        bar.update()
    sizes = sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)
    return SfmResult(reconstruction=largest_model(models), n_models=len(models), matcher=matcher, timings=timings,
                     model_sizes=sizes)
