"""Evaluate a trained run: held-out views, unseen state combinations, grounding -> metrics.json.

metrics.json holds only what depends on the run and the data, so two evaluations of one trained
model write the same bytes; every wall-clock number (render seconds, fps) goes to timings.json.

The run is anything with the model stage's render API: ``.objects`` and
``.render(camera, c2w, states, frame_index=None)`` returning numpy ``rgb``
``[H, W, 3]``, ``probs`` ``[H, W, alpha + 1]`` (background last) and, when
trained with language targets, ``language`` ``[H, W, D]``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from stages.frames.selection import downscale_factor
from stages.scene import Camera, Frame, InputError, SceneDataset, SceneError, atomic_dir, write_json
from stages.scene.dataset import fit_file_name
from stages.scene.machine import machine_info

from .locality import locality
from .metrics import SSIM_FORM, Lpips, iou, psnr, ssim, summarize
from .truth_source import TruthSource
from .unseen_states import OBSERVED_WITHIN, observed_levels, unseen_combinations

EVALUATE_VERSION = 7
"""2: timings moved to timings.json; non-novel combinations recorded, not rendered; grounding frames.
3: held-out PSNR also over object pixels and over static pixels (``psnr_objects``, ``psnr_static``).
4: the unseen-combination and locality tests say how many poses they used and asked for, and whether the render
budget cut them (a room of many objects: ``max_unseen_renders``, ``max_locality_pairs``; a test split with
fewer frames than asked also gives fewer poses, not cut).
5: held-out mean accumulation over object pixels and over static pixels (``accumulation_objects``,
``accumulation_static``): the report's trust check on objects painted behind themselves.
6: unseen combinations take each object only at levels the training showed it at (``observed_within``);
``training_range`` and ``levels_not_observed`` say what was left out.
7: a grounding query that is an object's name or synonym takes that object's probability alone (weight 1); the
softmax over the objects' phrases weighs only other queries (``Grounder.object_weights``)."""


@dataclass
class EvaluateConfig:
    """What to evaluate and how much of it."""

    max_views: int | None = None
    """Held-out (split == test) views to evaluate, evenly spaced; None = all."""
    unseen_views: int = 3
    """Held-out poses at which unseen state combinations are rendered (needs truth)."""
    max_unseen_renders: int | None = 48
    """Most unseen-combination renders: with 3 per object (one per level), a room of many objects gets fewer poses
    (at least one) so that poses x unseen combinations stays within it; None = no cap. 48 leaves rooms of up to 5
    objects at 3 poses; a 10-object room's baseline (MK-Planes, 78 planes per scale, ~18 s a view on 2 cores) would
    otherwise spend over an hour on this test and the locality test (docs/workflow.md, "Evaluation budget")."""
    levels: tuple[float, ...] = (0.0, 0.5, 1.0)
    """Levels each object is set to in the unseen-combination test."""
    novelty_min: float = 0.25
    """Least L-infinity distance to every training state vector for a combination to count as unseen."""
    observed_within: float | None = OBSERVED_WITHIN
    """An object takes a level in the unseen-combination test only where a training frame holds it within this
    distance of the level (an object never opened fully is not asked to render open); None = every level."""
    moved_threshold: float = 0.05
    """An object 'moved' when its test value differs from the view's own state by more than this."""
    grounding_threshold: float = 0.5
    """Relevancy above which a pixel belongs to the queried object."""
    save_renders: bool = True
    """Write PNGs (held-out renders, unseen model|truth pairs, grounding maps) for the report."""
    progress: bool = True
    """Progress bars on stderr (off for logs: ``--no-progress``)."""
    locality_views: int = 8
    """Held-out poses of the locality test (each object at 0 and 1, truth swept region; needs truth). Two views
    were the default until 24 Nov: on the kitchen they put a run under the 1/255 line that 8 views put over it."""
    max_locality_pairs: int | None = 40
    """Most (pose, object) pairs of the locality test: a room of many objects gets fewer poses (at least one);
    None = no cap. 40 leaves rooms of up to 5 objects at 8 poses."""
    max_unseen_images: int = 12
    """How many unseen-combination model|truth pairs are saved as PNG."""
    render_scale: float = 1.0
    """Render and compare at this fraction of the dataset's image size (0.5 = a quarter of the rays on a CPU);
    images are area-downscaled, masks sampled at pixel centres, the truth camera scaled alike."""


def render_scale_for(dataset: SceneDataset, max_side: int) -> float:
    """``1 / k`` for the smallest integer k that brings every frame's longer side to at most ``max_side``.

    An integer factor, as ``livescene frames --max-side`` takes: each rendered pixel then averages whole k x k
    blocks of the dataset image (the images_2 / images_4 convention of nerfstudio and mip-NeRF 360).
    """
    sizes = {(cam.width, cam.height) for cam in map(dataset.camera_of, dataset.frames)}  # read_scene: >= 1 frame
    return 1.0 / max(downscale_factor(w, h, max_side) for w, h in sizes)


def _evenly(items: list, n: int | None) -> list:
    if n is None or n >= len(items):
        return list(items)
    if n <= 0:
        return []
    idx = np.linspace(0, len(items) - 1, n).round().astype(int)
    return [items[i] for i in dict.fromkeys(idx.tolist())]


def _within(views: int, per_view: int, budget: int | None) -> int:
    """Poses to use when each costs ``per_view`` items and at most ``budget`` items may be spent (at least one)."""
    if budget is None or per_view <= 0 or views * per_view <= budget:
        return views
    return max(1, budget // per_view)


def _cut(views: int, asked: int, available: int) -> bool:
    """Whether the budget left fewer poses than asking alone would have (a short test split is not a cut)."""
    return min(views, available) < min(asked, available)


def grounding_figure(source: str, query: str, frame_id: str) -> str:
    """The file name of a relevancy map in ``grounding/``: the query's letters of any script kept, spaces as '-',
    path separators replaced (the report finds the map by this name)."""
    stem = fit_file_name(query.replace(" ", "-").replace("/", "-").replace("\\", "-"))
    return f"{source}_{stem}_{frame_id}.png"


def _to_png(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.clip(np.asarray(rgb, dtype=np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if img.ndim == 3:
        img = img[..., ::-1]
    cv2.imwrite(str(path), img)


def _finite_or_none(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


class Evaluator:
    """Runs the three evaluations of one run on one dataset."""

    def __init__(self, run: Any, dataset: SceneDataset, truth: TruthSource | None = None,
                 grounder: Any | None = None, config: EvaluateConfig | None = None) -> None:
        self.run = run
        self.ds = dataset
        self.truth = truth
        self.grounder = grounder
        self.config = config or EvaluateConfig()
        self.timings: dict[str, Any] = {}
        """Wall-clock numbers of the last evaluation (timings.json), kept out of the metrics."""
        self._masks: dict[str, np.ndarray] = {}
        """Object masks by frame id: loaded (or truth-rendered) once for the region split and the grounding."""
        self._aligned: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        """A refined run's aligned pose and correction by frame id, found once and used by every render there."""
        self.align_seconds = 0.0
        run_objects = list(getattr(run, "objects", dataset.objects))
        if run_objects != list(dataset.objects):
            raise InputError(dataset.root / "mapping.yaml", f"the run's objects {run_objects} differ from the "
                             f"dataset's {dataset.objects}", "evaluate a run on the dataset it was trained on")

    # -- rendering ------------------------------------------------------------------------------------------
    def _camera(self, frame: Frame) -> Camera:
        """The dataset camera of a frame at the evaluation's render scale."""
        cam = self.ds.camera_of(frame)
        return cam if self.config.render_scale == 1.0 else cam.scaled(self.config.render_scale)

    def _render(self, frame: Frame, states: dict[str, float] | None,
                rgb_only: bool = False) -> dict[str, np.ndarray]:
        """The run's render of ``frame``'s view; ``rgb_only`` takes the model's fast path (no probs, no language)."""
        extra = {"outputs": ("rgb",)} if rgb_only else {}
        return self.run.render(self._camera(frame), self._pose(frame), states, frame_index=self._run_index(frame),
                               **extra)

    @property
    def refined(self) -> bool:
        """Whether the run refined its training cameras (its world moved off the dataset's poses)."""
        return bool(getattr(self.run, "refined_cameras", False))

    def _pose(self, frame: Frame) -> np.ndarray:
        """The pose every render of ``frame``'s view uses: the dataset's, or for a run that refined its cameras that
        pose aligned to the run against the view's own image (docs/model.md, "Camera refinement"), once per view."""
        c2w = np.asarray(frame.c2w, float)
        if not self.refined:
            return c2w
        if frame.frame_id not in self._aligned:
            t0 = time.perf_counter()
            image = self._image(frame)
            nominal = self._nominal(frame, image)  # the run renders the nominal exposure
            image = image if nominal is None else nominal
            learned = getattr(self.run, "state_mode", "given") == "learned"
            self._aligned[frame.frame_id] = self.run.align_pose(
                self._camera(frame), c2w, image, None if learned else frame.state, frame_index=self._run_index(frame),
                seed=self.ds.frames.index(frame))
            self.align_seconds += time.perf_counter() - t0
        return self._aligned[frame.frame_id][0]

    def _nominal(self, frame: Frame, image: np.ndarray) -> np.ndarray | None:
        """``image`` of ``frame`` at the nominal exposure a run trained on measured gains renders (docs/model.md,
        "Exposure"); None when the run has no gain for the frame."""
        gains = getattr(self.run, "exposure_gains", None) or {}
        if frame.frame_id not in gains:
            return None
        return np.clip(image * np.exp(-np.asarray(gains[frame.frame_id])), 0.0, 1.0)

    def view_alignment(self) -> dict[str, Any]:
        """metrics.json's record of the protocol: the alignment's settings and each aligned view's correction."""
        from stages.model.camera_opt import correction_size

        views = [{"frame": fid, **correction_size(adj, self.run.norm)} for fid, (_, adj) in self._aligned.items()]
        return {"protocol": "each held-out view's pose aligned to the refined run (test-time optimisation of its "
                            "correction, model frozen, against the view's image) before every render there",
                **getattr(self.run, "ALIGNMENT", {}), "training_cameras": self.run.camera_opt["mode"],
                "views": views, "rotation_deg": summarize([v["rotation_deg"] for v in views]),
                "translation": summarize([v["translation"] for v in views]), "translation_unit": "dataset units"}

    def _run_index(self, frame: Frame) -> int | None:
        """The run's index of ``frame``, by id (a dataset given in another order names the same frames)."""
        index_of = getattr(self.run, "frame_index_of", None)
        index = index_of(frame, self.ds.frames) if index_of else self.ds.frames.index(frame)
        if index is None and getattr(self.run, "state_mode", "given") == "learned":
            raise InputError(self.ds.root / "transforms.json", f"frame {frame.frame_id} is not a frame the run was "
                             "trained on, so it has no learned state",
                             "evaluate with the dataset the run was trained on")
        return index

    def _image(self, frame: Frame) -> np.ndarray:
        """The dataset image at the render scale (area averaging, as a camera with larger pixels would see)."""
        img = self.ds.load_image(frame)
        cam = self._camera(frame)
        if img.shape[:2] == (cam.height, cam.width):
            return img
        return cv2.resize(img, (cam.width, cam.height), interpolation=cv2.INTER_AREA)

    def _mask(self, frame: Frame) -> np.ndarray:
        """The dataset's one-hot mask ``[H, W, alpha + 1]`` at the render scale (sampled at pixel centres)."""
        mask = self.ds.load_mask(frame)
        cam = self._camera(frame)
        if mask.shape[:2] == (cam.height, cam.width):
            return mask
        rows = np.minimum(((np.arange(cam.height) + 0.5) * mask.shape[0] / cam.height).astype(int), mask.shape[0] - 1)
        cols = np.minimum(((np.arange(cam.width) + 0.5) * mask.shape[1] / cam.width).astype(int), mask.shape[1] - 1)
        return mask[rows][:, cols]

    # -- 1. held-out views ----------------------------------------------------------------------------------
    def held_out(self, out_dir: Path | None) -> tuple[dict[str, Any], list[tuple[Frame, dict[str, np.ndarray]]]]:
        frames = _evenly(self.ds.frames_in("test"), self.config.max_views)
        if not frames:
            raise InputError(self.ds.root / "transforms.json", "no held-out frames (split == test)",
                             "assemble the dataset with a train/test split")
        lpips = Lpips()
        records, kept = [], []
        render_seconds = 0.0
        # a learned-state run renders a held-out frame at the state it learned for that frame index
        # (docs/method.md section 6)
        learned = getattr(self.run, "state_mode", "given") == "learned"
        regions = self._mask_source() if self.ds.objects else ""
        gains = getattr(self.run, "exposure_gains", None) or {}
        for frame in tqdm(frames, desc="held-out views", unit="view", disable=not self.config.progress):
            gt = self._image(frame)
            self._pose(frame)  # a refined run's alignment, timed apart from the render
            t0 = time.perf_counter()
            out = self._render(frame, None if learned else frame.state)
            render_seconds += time.perf_counter() - t0
            rgb = np.asarray(out["rgb"], dtype=np.float64)
            rec = {"frame": frame.frame_id, "file_path": frame.file_path, "psnr": _finite_or_none(psnr(rgb, gt)),
                   "ssim": ssim(rgb, gt), "lpips": lpips(rgb, gt) if lpips.available else None,
                   "state": frame.state}
            if regions:
                rec.update(self._region_scores(frame, rgb, gt, out.get("accumulation")))
            # a run trained on measured exposure gains renders the nominal exposure: score it against each held-out
            # image at that exposure too (its gains come from the same measurement; docs/model.md, "Exposure")
            if (nominal := self._nominal(frame, gt)) is not None:
                rec["psnr_nominal"] = _finite_or_none(psnr(rgb, nominal))
            records.append(rec)
            kept.append((frame, self._for_grounding(out)))
            if out_dir is not None and self.config.save_renders:
                _to_png(out_dir / "renders" / f"{frame.frame_id}.png", rgb)
        cam = self._camera(frames[0])
        summary = {
            "views": records,
            "psnr": summarize([r["psnr"] for r in records]),
            "ssim": summarize([r["ssim"] for r in records]),
            "ssim_form": SSIM_FORM,
            "lpips": summarize([r["lpips"] for r in records]) if lpips.available else None,
            "lpips_status": lpips.status,
            "psnr_objects": summarize([r.get("psnr_objects") for r in records]),
            "psnr_static": summarize([r.get("psnr_static") for r in records]),
            "accumulation_objects": summarize([r.get("accumulation_objects") for r in records]),
            "accumulation_static": summarize([r.get("accumulation_static") for r in records]),
            "region_source": regions or "none: the dataset has no masks and no truth capture was given",
            **({"psnr_nominal": summarize([r.get("psnr_nominal") for r in records]),
                "psnr_nominal_source": "each held-out image divided by its measured exposure gains (the run's "
                                       "exposure.json)"} if gains else {}),
            "image_size": [cam.width, cam.height],
            "state_source": "run's learned state at the frame index" if learned
            else "dataset per-frame state" if all(f.state for f in frames)
            else "dataset per-frame state; the run's own state at the frame index where the dataset has none",
        }
        self.timings["held_out"] = {"render_seconds": render_seconds, "views": len(frames),
                                    "fps": len(frames) / render_seconds if render_seconds > 0 else None}
        return summary, kept

    def _region_scores(self, frame: Frame, rgb: np.ndarray, gt: np.ndarray,
                       acc: np.ndarray | None) -> dict[str, float | None]:
        """PSNR and mean accumulation over the pixels of any object and over the rest (static), by the frame's
        object masks.

        The PSNR splits the held-out error between what the state drives and what it should not touch. The
        accumulation is the share of a pixel's colour that the samples give; the rest is the background's (under
        ``last_sample`` the colour at the ray's end, behind everything): objects under half opaque are painted
        on what lies behind them rather than modelled where they are (the report's trust check). A frame whose
        mask file is missing gets None for all.
        """
        none = {"psnr_objects": None, "psnr_static": None, "accumulation_objects": None, "accumulation_static": None}
        try:
            objects = self._object_masks(frame)[..., :-1].any(axis=-1)
        except SceneError:
            return none
        out = {"psnr_objects": _finite_or_none(psnr(rgb, gt, objects)) if objects.any() else None,
               "psnr_static": _finite_or_none(psnr(rgb, gt, ~objects)) if not objects.all() else None}
        if acc is not None:
            acc = np.asarray(acc, dtype=np.float64)
            out["accumulation_objects"] = _finite_or_none(float(acc[objects].mean())) if objects.any() else None
            out["accumulation_static"] = _finite_or_none(float(acc[~objects].mean())) if not objects.all() else None
        return out

    # -- 2. unseen state combinations -----------------------------------------------------------------------
    def _other_scale(self) -> str | None:
        """Why the truth's states and the run's are not on one scale, or None: key values the trainer rescaled
        (a published-form dataset's units, docs/data-contract.md "Key frames and the time axis") are not the
        truth renderer's [0, 1]."""
        if not self.ds.states_at_key_frames_only:
            return None
        from stages.scene.key_frame_states import key_frame_states

        rescaled = key_frame_states(self.ds).rescaled
        if not rescaled:
            return None
        shown = ", ".join(f"{o} {r['lo']:g}..{r['hi']:g}" for o, r in rescaled.items())
        return (f"skipped: the dataset's key values were mapped to [0, 1] ({shown}), so the truth capture's states "
                "and the run's are not on one scale")

    def unseen(self, out_dir: Path | None) -> dict[str, Any]:
        if self.truth is None:
            return {"status": "skipped: no truth capture given (--truth)"}
        if (why := self._other_scale()) is not None:
            return {"status": why}
        cfg = self.config
        objects = self.ds.objects
        train_states = self.ds.state_matrix(self.ds.frames_in("train"))
        combos = unseen_combinations(len(objects), train_states, cfg.levels, cfg.novelty_min,
                                     observed_within=cfg.observed_within)
        observed = dict(zip(objects, observed_levels(train_states, cfg.levels, cfg.observed_within), strict=True))
        n_views = _within(cfg.unseen_views, sum(c.unseen for c in combos), cfg.max_unseen_renders)
        views = _evenly(self.ds.frames_in("test"), n_views)
        records, seen = [], []
        unknown_state: list[str] = []
        saved = model_renders = 0
        render_seconds = 0.0
        pose_sources = set()
        for frame in tqdm(views, desc="unseen combinations", unit="view", disable=not self.config.progress):
            cam = self._camera(frame)
            tcam = self.truth.camera_for(cam.width, cam.height)
            t_c2w, how = self.truth.pose_for(frame)
            pose_sources.add(how)
            own_state = self.truth.state_for(frame) or {}
            if not own_state:  # every object then counts as moved, and the view has no seen reference
                unknown_state.append(frame.frame_id)
            own_ids = None
            if own_state:
                # the same view at its own (seen) state: the reference the unseen scores are read against
                own = self.truth.renderer.render(t_c2w, own_state, camera=tcam)
                own_ids = own["ids"]
                t0 = time.perf_counter()
                seen_rgb = np.asarray(self._render(frame, own_state, rgb_only=True)["rgb"], dtype=np.float64)
                render_seconds += time.perf_counter() - t0
                model_renders += 1
                obj_region = np.isin(own_ids, list(self.truth.object_ids.values()))
                seen.append({"frame": frame.frame_id,
                             "psnr": _finite_or_none(psnr(seen_rgb, np.asarray(own["rgb"], np.float64))),
                             "psnr_objects": _finite_or_none(psnr(seen_rgb, np.asarray(own["rgb"], np.float64),
                                                                  obj_region))})
            for ci, combo in enumerate(combos):
                states = dict(zip(objects, combo.values, strict=True))
                moved = [o for o in objects if abs(states[o] - own_state.get(o, -1.0)) > cfg.moved_threshold]
                record = {"frame": frame.frame_id, "combination": ci, "states": states,
                          "anchor": objects[combo.anchor], "level": combo.level,
                          "novelty": _finite_or_none(combo.novelty), "unseen": combo.unseen,
                          "rendered": combo.unseen, "moved_objects": moved}
                if not combo.unseen:
                    # too close to a training state to test independent control: listed, never rendered,
                    # so the evaluation's time goes to the combinations it scores
                    records.append(record | {"moved_pixels": None, "psnr": None, "psnr_moved": None, "ssim": None})
                    continue
                t0 = time.perf_counter()
                model_rgb = np.asarray(self._render(frame, states, rgb_only=True)["rgb"], dtype=np.float64)
                render_seconds += time.perf_counter() - t0
                model_renders += 1
                t = self.truth.renderer.render(t_c2w, states, camera=tcam)
                truth_rgb = np.asarray(t["rgb"], dtype=np.float64)
                moved_ids = [self.truth.object_ids[o] for o in moved if o in self.truth.object_ids]
                region = np.isin(t["ids"], moved_ids)
                if own_ids is not None:
                    region |= np.isin(own_ids, moved_ids)  # the swept region: where it was and where it is
                records.append(record | {
                    "moved_pixels": int(region.sum()),
                    "psnr": _finite_or_none(psnr(model_rgb, truth_rgb)),
                    "psnr_moved": _finite_or_none(psnr(model_rgb, truth_rgb, region)),
                    "ssim": ssim(model_rgb, truth_rgb),
                })
                if out_dir is not None and cfg.save_renders and saved < cfg.max_unseen_images:
                    _to_png(out_dir / "unseen" / f"{frame.frame_id}_c{ci:02d}.png",
                            np.concatenate([model_rgb, truth_rgb], axis=1))
                    saved += 1
        unseen = [r for r in records if r["unseen"]]
        self.timings["unseen_combinations"] = {"model_render_seconds": render_seconds, "model_renders": model_renders}
        note = {} if not unknown_state else {  # recorded only where it happens: other rooms keep their bytes
            "views_without_truth_state": unknown_state,
            "note": f"the truth's state of {len(unknown_state)} view(s) is unknown (their frames carry no "
                    "source_index): every object counts as moved there, and they have no seen reference"}
        return note | {
            "status": "computed",
            "truth": self.truth.origin,
            "truth_pose_source": sorted(pose_sources),
            "alignment_residual": self.truth.alignment_residual(self.ds.frames),
            "levels": list(cfg.levels),
            "novelty_min": cfg.novelty_min,
            "observed_within": cfg.observed_within,
            "training_range": self.ds.state_ranges(self.ds.frames_in("train")),
            "levels_not_observed": {o: [v for v in cfg.levels if v not in observed[o]] for o in objects
                                    if len(observed[o]) < len(cfg.levels)},
            "views": len(views), "views_asked": cfg.unseen_views, "max_renders": cfg.max_unseen_renders,
            "views_cut": _cut(n_views, cfg.unseen_views, len(self.ds.frames_in("test"))),
            "combinations": [asdict(c) | {"novelty": _finite_or_none(c.novelty)} for c in combos],
            "records": records,
            "psnr": summarize([r["psnr"] for r in unseen]),
            "psnr_moved": summarize([r["psnr_moved"] for r in unseen]),
            "ssim": summarize([r["ssim"] for r in unseen]),
            "n_unseen": len(unseen),
            "n_not_novel": len(records) - len(unseen),
            "seen_reference": {"views": seen, "psnr": summarize([r["psnr"] for r in seen]),
                               "psnr_objects": summarize([r["psnr_objects"] for r in seen])},
        }

    # -- 3. grounding ---------------------------------------------------------------------------------------
    def grounding(self, rendered: list[tuple[Frame, dict[str, np.ndarray]]], out_dir: Path | None) -> dict[str, Any]:
        if self.grounder is None:
            return {"status": "skipped: --no-grounding (the workflow passes it for a scene without names)"}
        truth_masks = self._grounding_masks([f for f, _ in rendered])
        if truth_masks is None:
            return {"status": "skipped: the dataset has no masks and no truth capture was given"}
        queries, ambiguous = self._grounding_queries()
        sources = ["probs"]
        language_note = "the run renders no language embedding"
        if rendered and "language" in rendered[0][1]:
            if self._same_language_space():
                sources += ["language", "language_objects"]
                language_note = "computed"
            else:  # queries must live in the embedding space the table was trained in
                language_note = (f"skipped: run trained with encoder {getattr(self.run, 'language_encoder', None)!r}, "
                                 f"queries use {self.grounder.encoder.name!r}")
        results: dict[str, Any] = {"status": "computed", "threshold": self.config.grounding_threshold,
                                   "sources": sources, "language_source": language_note, "queries": []}
        if ambiguous:  # recorded only where there are any: metrics.json of other rooms keep their bytes
            results["ambiguous_synonyms"] = sorted(ambiguous)
        entries: list[dict[str, Any]] = []
        for q in queries:
            weights = self.grounder.object_weights(q["query"])
            entries.append(dict(q) | {"object_weights": dict(zip(self.ds.objects, map(float, weights), strict=True))}
                           | {source: {"per_view": [], "frames": []} for source in sources})
        # views outside, queries inside; each view's language maps were made from its embedding when it was rendered
        for (frame, out), masks in tqdm(list(zip(rendered, truth_masks, strict=True)), desc="grounding views",
                                        unit="view", disable=not self.config.progress):
            for q, entry in zip(queries, entries, strict=True):
                truth = masks[..., q["index"]]
                if not truth.any():
                    continue  # the object is not in view: IoU is undefined there
                for source in sources:
                    if source == "probs":
                        rel = self.grounder.relevancy_from_probs(out["probs"], q["query"])
                    elif source == "language":
                        rel = out["language"][q["query"]]
                    else:  # language_objects: the query-independent decoding of this view, weighted by the query
                        rel = self.grounder.relevancy_from_probs(out["language_objects"], q["query"])
                    ious, frames = entry[source]["per_view"], entry[source]["frames"]
                    ious.append(iou(rel > self.config.grounding_threshold, truth))
                    frames.append(frame.frame_id)  # per-view IoUs pair up across methods by (query, frame)
                    if out_dir is not None and self.config.save_renders and len(ious) == 1:
                        _to_png(out_dir / "grounding" / grounding_figure(source, q["query"], frame.frame_id), rel)
        for entry in entries:
            for source in sources:
                per_view, frames = entry[source]["per_view"], entry[source]["frames"]
                entry[source] = {"iou": summarize(per_view), "per_view": per_view, "frames": frames}
            results["queries"].append(entry)
        for source in sources:
            for kind in ("name", "synonym"):
                vals = [q[source]["iou"]["mean"] for q in results["queries"] if q["kind"] == kind]
                results[f"miou_{source}_{kind}"] = summarize([v for v in vals if v is not None])["mean"]
            results[f"miou_{source}"] = summarize(
                [q[source]["iou"]["mean"] for q in results["queries"] if q[source]["iou"]["mean"] is not None])["mean"]
        return results

    def _grounding_queries(self) -> tuple[list[dict[str, Any]], set[str]]:
        """The grounding's queries (each object's name and first synonym of its own) and the synonyms objects share."""
        queries = []
        vocabulary = self.grounder.vocabulary.entries
        owners: dict[str, set[str]] = {}
        for entry in vocabulary:
            for alias in entry.aliases:
                owners.setdefault(alias.casefold(), set()).add(entry.name)
        ambiguous: set[str] = set()
        for i, entry in enumerate(vocabulary):
            aliases = entry.aliases
            queries.append({"query": aliases[0], "object": entry.name, "index": i, "kind": "name"})
            # a synonym two objects share ("cupboard" for both cupboards) names neither: its map cannot match one
            # object's mask, so the first synonym of this object alone is scored
            synonyms = [a for a in aliases[1:] if len(owners[a.casefold()]) == 1]
            ambiguous |= {a for a in aliases[1:] if len(owners[a.casefold()]) > 1}
            if synonyms:
                queries.append({"query": synonyms[0], "object": entry.name, "index": i, "kind": "synonym"})
        return queries, ambiguous

    def _same_language_space(self) -> bool:
        """Whether the grounder's queries live in the embedding space the run's language table was trained in."""
        return getattr(self.run, "language_encoder", None) in (None, self.grounder.encoder.name)

    def _for_grounding(self, out: dict[str, np.ndarray]) -> dict[str, Any]:
        """What the grounding reads of a held-out render, kept until every held-out and unseen view is rendered: the
        probabilities and, for a rendered language embedding ``[H, W, D]``, only what the grounding makes of it (its
        relevancy map per query, and its decoded probabilities). Holding the embeddings themselves cost D = 384
        floats a pixel, 0.8 GB a 960x540 view: 8 views took the evaluation of a phone video to 12.7 GiB
        (docs/workflow.md, "A phone-sized capture end to end"). The same maps, made earlier: the same bits."""
        kept: dict[str, Any] = {k: v for k, v in out.items() if k == "probs"}
        if "language" not in out:
            return kept
        kept["language"] = {}  # the run renders a language embedding (the grounding says so either way)
        if self.grounder is None or not self._same_language_space():
            return kept
        # a view's embedding is normalised (and decoded) once for all its queries
        unit = self.grounder.unit_language(out["language"])
        kept["language_objects"] = self.grounder.probs_from_unit_language(unit)
        for q in self._grounding_queries()[0]:
            if q["query"] not in kept["language"]:
                kept["language"][q["query"]] = self.grounder.relevancy_from_unit_language(unit, q["query"])
        return kept

    def _mask_source(self) -> str:
        """Where the object masks come from: "dataset masks", "truth renderer", or "" (nowhere)."""
        return "dataset masks" if self.ds.has_masks else "truth renderer" if self.truth is not None else ""

    def _object_masks(self, frame: Frame) -> np.ndarray:
        """Object masks ``[H, W, alpha + 1]`` of a frame at the render scale, from ``_mask_source`` (memoised)."""
        if frame.frame_id not in self._masks:
            if self.ds.has_masks:
                mask = self._mask(frame)
            else:
                assert self.truth is not None, "no mask source (see _mask_source)"
                cam = self._camera(frame)
                ids = self.truth.renderer.render(self.truth.pose_for(frame)[0], self.truth.state_for(frame) or {},
                                                 camera=self.truth.camera_for(cam.width, cam.height))["ids"]
                chans = [ids == self.truth.object_ids.get(o, -1) for o in self.ds.objects]
                chans.append(~np.any(chans, axis=0))
                mask = np.stack(chans, axis=-1)
            self._masks[frame.frame_id] = mask
        return self._masks[frame.frame_id]

    def _grounding_masks(self, frames: list[Frame]) -> list[np.ndarray] | None:
        """Truth object masks ``[H, W, alpha + 1]`` per frame: the dataset's masks, else the truth renderer's ids."""
        if not self._mask_source():
            return None
        return [self._object_masks(f) for f in frames]

    # -- 4. locality ----------------------------------------------------------------------------------------
    def locality(self) -> dict[str, Any]:
        if self.truth is None:
            return {"status": "skipped: no truth capture given (--truth)"}
        if (why := self._other_scale()) is not None:
            return {"status": why}
        cfg = self.config
        n_views = _within(cfg.locality_views, len(self.ds.objects), cfg.max_locality_pairs)
        frames = _evenly(self.ds.frames_in("test"), n_views)
        if not frames or not self.ds.objects:
            return {"status": "skipped: no held-out view or no object"}
        renders = 0

        def render(frame: Frame, states: dict[str, float]) -> np.ndarray:
            nonlocal renders
            renders += 1
            return self._render(frame, states, rgb_only=True)["rgb"]

        out = locality(render, self.truth, frames, self._camera, self.ds.objects, progress=self.config.progress)
        self.timings["locality"] = {"model_renders": renders}
        return out | {"views": len(frames), "views_asked": cfg.locality_views, "max_pairs": cfg.max_locality_pairs,
                      "views_cut": _cut(n_views, cfg.locality_views, len(self.ds.frames_in("test")))}

    # -- everything -----------------------------------------------------------------------------------------
    def evaluate(self, out_dir: Path | None = None) -> dict[str, Any]:
        """The metrics (deterministic for a deterministic run); wall-clock numbers land in ``self.timings``."""
        self.timings = {}
        t0 = time.perf_counter()
        held, rendered = self.held_out(out_dir)
        t1 = time.perf_counter()
        unseen = self.unseen(out_dir)
        t2 = time.perf_counter()
        grounding = self.grounding(rendered, out_dir)
        t3 = time.perf_counter()
        local = self.locality()
        t4 = time.perf_counter()
        self.timings.setdefault("locality", {})["seconds"] = t4 - t3
        self.timings["held_out"]["seconds"] = t1 - t0
        self.timings.setdefault("unseen_combinations", {})["seconds"] = t2 - t1
        self.timings["grounding"] = {"seconds": t3 - t2}
        self.timings["seconds"] = t4 - t0  # every part, locality included
        self.timings["machine"] = machine_info(str(getattr(self.run, "device", "cpu")))
        # only a refined run's metrics carry the protocol: an unrefined one's are as before the option existed
        aligned = {"view_alignment": self.view_alignment()} if self.refined else {}
        if self.refined:
            self.timings["view_alignment"] = {"seconds": self.align_seconds, "views": len(self._aligned)}
        return {
            "evaluate_version": EVALUATE_VERSION,
            "dataset": str(self.ds.root),
            "objects": self.ds.objects,
            # what the numbers depend on: the progress bars do not (metrics.json is the same with --no-progress)
            "config": {k: v for k, v in asdict(self.config).items() if k != "progress"},
            "held_out": held,
            "unseen_combinations": unseen,
            "grounding": grounding,
            "locality": local,
            **aligned,
        }


def evaluate_run(run: Any, dataset: SceneDataset, out_dir: str | Path, truth: TruthSource | None = None,
                 grounder: Any | None = None, config: EvaluateConfig | None = None,
                 extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Evaluate and write ``out_dir`` atomically: metrics.json, timings.json and PNG renders. Returns the metrics.

    metrics.json is identical between evaluations of one trained model; the wall-clock numbers
    (render seconds, fps, stage seconds) are in timings.json next to it.
    """
    out_dir = Path(out_dir)
    with atomic_dir(out_dir, "evaluate", inputs=[dataset.root], legacy=["metrics.json"]) as tmp:
        evaluator = Evaluator(run, dataset, truth, grounder, config)
        metrics = evaluator.evaluate(tmp)
        if extra:
            metrics.update(extra)
        write_json(tmp / "metrics.json", metrics)
        write_json(tmp / "timings.json", evaluator.timings)
    return metrics
