"""``livescene poses``: COLMAP poses for extracted frames; ``livescene poses compare``: pose error vs truth."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stages.scene import InputError, write_json
from stages.scene.cli_errors import cli_errors

from .config import PosesConfig


def _estimate_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene poses",
        description="Estimate camera poses with COLMAP (pycolmap): SIFT with interactive objects masked out, "
                    "sequential or exhaustive matching, incremental mapping; writes sparse/0, transforms.json "
                    "(nerfstudio, OpenGL axes), points3D.ply, scene.json and poses.json. "
                    "`livescene poses compare --help` compares poses with reference poses; "
                    "`livescene poses import --help` imports a COLMAP model made elsewhere.")
    d = PosesConfig(frames_dir=Path(), out_dir=Path())
    p.add_argument("--frames", type=Path, required=True, help="output folder of `livescene frames` (holds images/)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--masks", type=Path, help="object masks per frame (PNG id maps, 0 = static, or .npy); "
                                              "masked pixels get no features")
    p.add_argument("--matcher", choices=["sequential", "exhaustive", "auto"], default=d.matcher,
                   help=f"pairing (auto: exhaustive up to {d.exhaustive_max_images} frames, else sequential)")
    p.add_argument("--overlap", type=int, default=d.sequential_overlap, help="sequential matching overlap")
    p.add_argument("--vocab-tree", type=Path, help="COLMAP vocabulary tree: enables loop detection")
    p.add_argument("--threads", type=int, default=d.threads, help="CPU threads (-1 = all)")
    p.add_argument("--seed", type=int, default=d.seed, help="random seed")
    p.add_argument("--parallel", "--parallel-extraction", dest="parallel_extraction", action="store_true",
                   help="run COLMAP on all --threads (faster, but runs are no longer bit-identical)")
    p.add_argument("--min-registered", type=float, default=d.min_registered,
                   help="quality gate: minimum fraction of frames that must get a pose")
    p.add_argument("--max-still-share", type=float, default=d.max_still_share,
                   help="pose gate: refuse a model with more than this share of its cameras on one spot "
                        "(a tripod clip; see docs/poses.md, Quality gate)")
    p.add_argument("--camera-model", default=d.camera_model,
                   choices=["SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV"],
                   help="COLMAP camera model shared by all frames (default %(default)s, chosen by measurement: "
                        "docs/poses.md, Camera model)")
    p.add_argument("--focal", type=float,
                   help="known focal length in pixels of the frames as written: COLMAP starts from it and keeps it "
                        "(principal point at the centre; docs/poses.md, Known focal length)")
    p.add_argument("--focal-35mm", type=float,
                   help="known 35 mm-equivalent focal length in mm (a phone's spec sheet), converted by the image "
                        "diagonal (43.27 mm for full frame)")
    p.add_argument("--refine-focal", action="store_true",
                   help="let bundle adjustment refine the given focal length (default: kept fixed)")
    p.add_argument("--max-image-size", type=int, default=d.max_image_size,
                   help="longest side for feature extraction (-1 = full)")
    p.add_argument("--max-features", type=int, default=d.max_num_features, help="SIFT features per frame")
    p.add_argument("--mask-dilate", type=int, help="mask dilation in pixels (default 1%% of the diagonal)")
    p.add_argument("--no-orient", action="store_true",
                   help="keep the world frame of the model as it is (default: z up, x and y along the walls, origin "
                        "at the scene box centre; docs/poses.md, World frame)")
    p.add_argument("--keep-database", action="store_true", help="keep COLMAP's database.db")
    p.add_argument("--verbose", action="store_true", help="show COLMAP's own log")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _compare_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene poses compare",
        description="Align estimated poses to reference poses with a similarity and report camera-centre error "
                    "relative to the scene extent, rotation error and focal error. Frames are paired by name "
                    "(0001.jpg = frame_00001.png = 00001; image stems; COLMAP image names) or, with --match order, "
                    "by position.")
    p.add_argument("--pred", type=Path, required=True,
                   help="estimated poses: transforms.json or a COLMAP model folder (POSES/transforms.json)")
    p.add_argument("--truth", type=Path, required=True,
                   help="reference poses: transforms.json or a COLMAP model folder (CAPTURE/truth/...)")
    p.add_argument("--match", choices=["id", "order"], default="id",
                   help="id = pair frames by the number in their names, their stems or their image paths, whichever "
                        "pairs most (default); order = pair the k-th frame of each file (same frames, same order; "
                        "for a reference without file names)")
    p.add_argument("--out", type=Path, help="write the report here (JSON)")
    p.add_argument("--extent", type=float,
                   help="scene extent in reference units (default: longest side of the scene_box in the "
                        "reference's scene.json, else of the reference camera centres)")
    p.add_argument("--align", choices=["poses", "centres"], default="poses",
                   help="similarity fit: poses = centres and orientations together (default; stable for short "
                        "arcs), centres = Umeyama on camera centres only")
    return p


def _compare(argv: list[str]) -> int:
    from .comparison import compare_poses, summary_lines

    args = _compare_parser().parse_args(argv)
    report = compare_poses(args.pred, args.truth, extent=args.extent, align=args.align, match=args.match)
    if args.out is not None:
        write_json(args.out, report)
    print("\n".join(summary_lines(report)))
    return 0


def _estimate(argv: list[str]) -> int:
    from .pipeline import estimate_poses

    a = _estimate_parser().parse_args(argv)
    if not 0.0 <= a.min_registered <= 1.0:
        raise InputError(Path("--min-registered"), f"{a.min_registered} is not a fraction", "give a value in [0, 1]")
    if not 0.0 < a.max_still_share <= 1.0:
        raise InputError(Path("--max-still-share"), f"{a.max_still_share} is not a fraction",
                         "give a value in (0, 1]")
    cfg = PosesConfig(frames_dir=a.frames, out_dir=a.out, masks_dir=a.masks, matcher=a.matcher,
                      sequential_overlap=a.overlap, vocab_tree=a.vocab_tree, threads=a.threads, seed=a.seed,
                      deterministic=not a.parallel_extraction,
                      min_registered=a.min_registered, max_still_share=a.max_still_share,
                      camera_model=a.camera_model, focal_px=a.focal, focal_35mm=a.focal_35mm,
                      refine_focal=a.refine_focal, max_image_size=a.max_image_size,
                      max_num_features=a.max_features, mask_dilate_px=a.mask_dilate, keep_database=a.keep_database,
                      orient=not a.no_orient,
                      progress=not a.no_progress, verbose=a.verbose)
    s = estimate_poses(cfg)
    for warning in s["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    t = s["timings"]
    print(f"registered {s['n_registered']}/{s['n_frames']} frames ({s['registered_fraction']:.1%}), "
          f"{s['n_points3D']} points, reprojection error {s['mean_reprojection_error']:.3f} px, "
          f"{s['matcher']} matching, {t['total']:.1f} s -> {a.out}")
    return 0


def _import_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="livescene poses import",
        description="Import a COLMAP model made elsewhere (COLMAP GUI, colmap mapper, ns-process-data) instead of "
                    "running structure from motion: writes the same POSES folder as `livescene poses` (sparse/0, "
                    "transforms.json, points3D.ply, scene.json, poses.json). See docs/poses.md.")
    p.add_argument("--model", type=Path, required=True,
                   help="COLMAP model folder (cameras, images, points3D as .bin or .txt), or a folder holding "
                        "sparse/0 (COLMAP project) or colmap/sparse/0 (ns-process-data output)")
    p.add_argument("--out", type=Path, required=True, help="POSES folder to write (replaced atomically)")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--frames", type=Path,
                       help="FRAMES folder of `livescene frames`: COLMAP images are matched to frames by frame "
                            "number (0001.jpg -> frame_00001.png); intrinsics are rescaled to the frames' size")
    which.add_argument("--images", type=Path, help="the folder the model was made from (COLMAP's image path)")
    p.add_argument("--min-registered", type=float, default=0.8,
                   help="smallest fraction of the frames that must have a posed image in the model")
    p.add_argument("--no-orient", action="store_true",
                   help="keep the world frame of the model as it is (default: z up, x and y along the walls, origin "
                        "at the scene box centre; docs/poses.md, World frame)")
    return p


def _import(argv: list[str]) -> int:
    from .colmap_import import ImportConfig, import_model

    a = _import_parser().parse_args(argv)
    if not 0.0 <= a.min_registered <= 1.0:
        raise InputError(Path("--min-registered"), f"{a.min_registered} is not a fraction", "give a value in [0, 1]")
    s = import_model(ImportConfig(model_dir=a.model, out_dir=a.out, images_dir=a.images, frames_dir=a.frames,
                                  min_registered=a.min_registered, orient=not a.no_orient))
    for warning in s["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"imported {s['imported_from']['model']} ({s['imported_from']['format']}): {s['n_registered']}/"
          f"{s['n_frames']} {s['imported_from']['images']} posed ({s['registered_fraction']:.1%}), "
          f"{s['n_points3D']} points, reprojection error {s['mean_reprojection_error']:.3f} px, "
          f"{s['timings']['total']:.1f} s -> {a.out}")
    return 0


@cli_errors()
def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == "import":
        return _import(argv[1:])
    if argv and argv[0] == "compare":
        return _compare(argv[1:])
    return _estimate(argv)
