"""Open a trained run and render any pose with any object states: the API evaluation, report and language use.

``load_run(run_dir).render(camera, c2w, states, frame_index)`` takes the pose
in the DATASET's world coordinates (OpenGL camera axes) and returns numpy
arrays: ``rgb`` [H, W, 3], ``depth`` [H, W] (distance along the ray, dataset
units), ``accumulation`` [H, W], ``probs`` [H, W, alpha + 1] (softmax of the
rendered final-level logits, or the rendered probabilities where the mask loss
trains those, background last) and ``language`` [H, W, D] when
the run was trained with language targets.

``open_run`` and ``dataset_of_run`` are how the commands that take ``--run``
(language, control, evaluate, view) open a run and find its dataset.
"""

from __future__ import annotations

import json
import pickle
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F

from stages.scene import Camera, InputError, generate_rays, read_yaml_mapping

from .allocator import keep_freed_memory
from .appearance_choice import EXPOSURE_FILE
from .camera_opt import ALIGN_LR, ALIGN_RAYS, ALIGN_STEPS, align_rays, corrected_c2w
from .chunk_threads import map_chunks
from .config import RunConfig, config_from_dict
from .methods import SceneInfo, build_model
from .rays import RayBundle
from .scene_normalization import SceneNormalization, aabb_near_far
from .trainer import MODEL_FORMAT, resolve_device

States = Mapping[str, float] | Sequence[float] | np.ndarray | None
IMAGE_OUTPUTS = ("rgb", "depth", "accumulation", "probs", "language")
"""What ``render`` can return (language only for runs trained with language targets)."""
MODEL_OUTPUT = {"probs": "logits"}
"""The model output each image is made from, where the names differ."""


class LoadedRun:
    """A trained model in eval mode with its scene normalisation and per-frame states."""

    def __init__(self, run_dir: Path, payload: dict[str, Any], device: str = "cpu") -> None:
        self.run_dir = run_dir
        self.device = resolve_device(device)  # "auto", or a clear error for CUDA on a machine without it
        keep_freed_memory()
        self.config = config_from_dict(payload["config"], str(run_dir / "model.pt"))
        self.method = str(payload["method"])
        self.info = SceneInfo(**payload["info"])
        self.model = build_model(self.method, self.config.model, self.info)
        self.model.load_state_dict(payload["state_dict"])
        self.model.to(self.device).eval()
        self.norm = SceneNormalization.from_dict(payload["normalization"])
        frame_states = payload["frame_states"]  # [frames][objects]; a room without objects has empty rows
        self.frame_states = np.asarray(frame_states, dtype=np.float64).reshape(len(frame_states), self.info.n_objects)
        self.frame_ids = list(payload.get("frame_ids", []))
        self.step = int(payload["step"])
        self.language_encoder = payload.get("language_encoder")
        self.camera_opt: dict[str, Any] | None = payload.get("camera_opt")
        """The training cameras' corrections (``train.camera_opt``): mode, frame ids, ``[frames, 6]``; None when off."""

    @property
    def refined_cameras(self) -> bool:
        """Whether training refined its cameras: the world then moved off the dataset's poses, and a held-out view is
        scored at its pose aligned to the run (``align_pose``; docs/model.md, "Camera refinement")."""
        return self.camera_opt is not None

    ALIGNMENT: ClassVar[dict[str, float]] = {"steps": ALIGN_STEPS, "rays_per_step": ALIGN_RAYS, "lr": ALIGN_LR}
    """The alignment's fixed settings, as metrics.json records them."""

    def align_pose(self, camera: Camera, c2w: np.ndarray, image: np.ndarray, states: States = None,
                   frame_index: int | None = None, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """The pose of ``camera`` near ``c2w`` (dataset world) at which this run best renders ``image`` [H, W, 3]
        with ``states``: a correction (as training's, ``[t, w]`` in the normalised scene) optimised with the model
        frozen, ``ALIGN_STEPS`` Adam steps on ``ALIGN_RAYS`` pixels each, drawn by a generator seeded with ``seed``
        (the same pose every time on one machine). Returns the aligned camera-to-world and the correction."""
        state = self.state_vector(states, frame_index)
        origins, dirs = generate_rays(camera, np.asarray(c2w, dtype=np.float64))
        o = torch.tensor(self.norm.points(origins.reshape(-1, 3)), dtype=torch.float32, device=self.device)
        d = torch.tensor(dirs.reshape(-1, 3), dtype=torch.float32, device=self.device)
        d = d / d.norm(dim=-1, keepdim=True)
        target = torch.tensor(np.asarray(image, dtype=np.float32).reshape(-1, 3), device=self.device)
        st = torch.tensor(state, dtype=torch.float32, device=self.device)
        t = self.frame_time(frame_index) if frame_index is not None else 0.0

        def render(rays: RayBundle) -> torch.Tensor:
            n = len(rays)
            rays.states = st.expand(n, self.info.n_objects)
            rays.times = torch.full((n,), float(t), device=self.device)
            return self.model(rays, step=self.step, outputs=("rgb",))["rgb"]

        frozen = [p for p in self.model.parameters() if p.requires_grad]
        for p in frozen:  # gradients reach the correction only
            p.requires_grad_(False)
        try:
            with torch.inference_mode(False), torch.enable_grad():
                adjustment = align_rays(render, o, d, target, self.config.model.sampling.near_plane, seed)
        finally:
            for p in frozen:
                p.requires_grad_(True)
        return corrected_c2w(c2w, adjustment, self.norm), adjustment

    @property
    def objects(self) -> list[str]:
        return list(self.info.objects)

    @property
    def n_frames(self) -> int:
        return self.info.n_frames

    @property
    def state_mode(self) -> str:
        return self.config.model.state.mode

    @property
    def reads_states(self) -> bool:
        """False for a method whose images are the same at any state vector: K-Planes' fourth axis is the frame's
        time (docs/baselines.md)."""
        return self.method != "k-planes"

    STATES_UNREAD = ("a k-planes run reads no object state (its fourth axis is the frame's time), so the states "
                     "given change nothing")

    def warn_if_states_unread(self, states: Collection[str] | Mapping[str, float] | None) -> None:
        """Say on stderr when object states are asked of a method that reads none."""
        if not self.reads_states and states:
            import warnings

            warnings.warn(f"{self.run_dir}: {self.STATES_UNREAD}; fix: render a run of livescene, mk-planes or "
                          "conerf to set object states", stacklevel=2)

    def check_dataset(self, ds: Any) -> None:
        """Refuse a ``--data`` whose objects are not the run's (a state, mask or name would reach the wrong object),
        and warn when its cameras are not those the run was trained on (another world frame, such as a capture's
        ``truth/`` in metres where training had COLMAP's units: every render is then of empty space)."""
        if list(ds.objects) != self.objects:
            raise InputError(Path(ds.root) / "mapping.yaml", f"objects {list(ds.objects)} differ from the run's "
                             f"{self.objects}", "pass the dataset the run was trained on with --data (or leave "
                             "--data out: the run names its own)")
        trained = recorded_dataset(self.run_dir)
        if trained is None or trained.resolve() == Path(ds.root).resolve():
            return
        ours, theirs = Path(ds.root) / "transforms.json", trained / "transforms.json"
        if ours.is_file() and theirs.is_file() and _cameras(ours) != _cameras(theirs):
            import warnings

            warnings.warn(f"{ds.root}: its cameras differ from those of the dataset this run was trained on "
                          f"({trained}): renders at its poses, and anything made from them, are of another world "
                          "frame than the run's; fix: pass the run's own dataset with --data (or leave --data out)",
                          stacklevel=2)

    @property
    def exposure_gains(self) -> dict[str, list[float]] | None:
        """Every frame's measured log gains per channel when the run was trained on them (``exposure.json``),
        else None: the images were taken as they are."""
        path = self.run_dir / EXPOSURE_FILE
        return json.loads(path.read_text())["log_gains"] if path.is_file() else None

    def frame_index_of(self, frame: Any, ds_frames: Sequence[Any]) -> int | None:
        """The run's own index of a dataset frame (its learned state, time and colour correction), by frame id: a
        dataset given in another order, or a copy of it, names the same frames. None when the run does not know
        the frame; a run saved before frame ids were recorded takes the frame's position in ``ds_frames``."""
        if not self.frame_ids:
            return list(ds_frames).index(frame)
        try:
            return self.frame_ids.index(frame.frame_id)
        except ValueError:
            return None

    def frame_time(self, frame_index: int) -> float:
        n = self.info.n_frames
        if not 0 <= frame_index < n:
            raise InputError(self.run_dir, f"frame index {frame_index} outside the trained dataset's 0..{n - 1}",
                             "pass the index of a frame of the dataset the run was trained on")
        return self.info.frame_time(frame_index)

    @torch.no_grad()
    def learned_states(self, frame_indices: Sequence[int] | None = None) -> np.ndarray:
        """States the model uses per frame: the state network's output (learned mode) or the dataset's."""
        idx = list(range(self.n_frames)) if frame_indices is None else list(frame_indices)
        state_field = getattr(self.model, "state_field", None)
        if state_field is None:
            return np.nan_to_num(self.frame_states[idx])
        t = torch.tensor([self.frame_time(i) for i in idx], dtype=torch.float32, device=self.device)
        return state_field(t).cpu().numpy().astype(np.float64)

    def state_vector(self, states: States, frame_index: int | None = None) -> np.ndarray:
        """Resolve ``states`` to one value per object; objects not named keep the frame's (or 0)."""
        alpha = self.info.n_objects
        base = self.learned_states([frame_index])[0] if frame_index is not None else np.zeros(alpha)
        if states is None:
            return base
        if isinstance(states, Mapping):
            unknown = sorted(set(states) - set(self.objects))
            if unknown:
                raise InputError(self.run_dir, f"unknown objects {unknown} in the state",
                                 f"use {self.objects}" if self.objects else "give no state: this run's scene has "
                                 "no objects")
            out = base.copy()
            for j, name in enumerate(self.objects):
                if name in states:
                    out[j] = float(states[name])
            return self._finite(out)
        arr = np.asarray(states, dtype=np.float64).reshape(-1)
        if arr.shape[0] != alpha:
            raise InputError(self.run_dir, f"{arr.shape[0]} state values for {alpha} objects {self.objects}",
                             "give one value per object, in this order")
        return self._finite(arr)

    def _finite(self, state: np.ndarray) -> np.ndarray:
        """A NaN state would reach the field as NaN features and render as empty space without a word."""
        bad = [name for name, v in zip(self.objects, state, strict=True) if not np.isfinite(v)]
        if bad:
            raise InputError(self.run_dir, f"object states of {bad} are not finite numbers",
                             "give each object a finite state (0 closed, 1 open)")
        return state

    @torch.inference_mode()
    def render_rays(self, origins: np.ndarray, directions: np.ndarray, state: np.ndarray,
                    time_value: float = 0.0, outputs: Collection[str] = IMAGE_OUTPUTS) -> dict[str, np.ndarray]:
        """Render world-space rays [N, 3] with one state vector; returns flat arrays of the named ``outputs``."""
        unknown = sorted(set(outputs) - set(IMAGE_OUTPUTS))
        if unknown:
            raise ValueError(f"unknown render outputs {unknown}; choose from {IMAGE_OUTPUTS}")
        o = torch.tensor(self.norm.points(origins.reshape(-1, 3)), dtype=torch.float32, device=self.device)
        d = torch.tensor(directions.reshape(-1, 3), dtype=torch.float32, device=self.device)
        d = d / d.norm(dim=-1, keepdim=True)
        nears, fars = aabb_near_far(o, d, self.config.model.sampling.near_plane)
        n = o.shape[0]
        st = torch.tensor(state, dtype=torch.float32, device=self.device).expand(n, self.info.n_objects)
        times = torch.full((n,), float(time_value), device=self.device)
        rays = RayBundle(o, d, nears, fars, st, times)
        model_outputs = [MODEL_OUTPUT.get(k, k) for k in outputs]
        # on a CPU, whole chunks go to worker threads (one core each): faster than splitting every op
        workers = torch.get_num_threads() if self.device.type == "cpu" else 1
        outs = map_chunks(lambda a, b: self.model(rays.slice(a, b), step=self.step, outputs=model_outputs), n,
                          self.config.train.render_chunk, workers)
        parts: dict[str, list[torch.Tensor]] = {}
        for out in outs:
            if "rgb" in out:
                parts.setdefault("rgb", []).append(out["rgb"].clamp(0, 1))
            if "depth" in out:
                parts.setdefault("depth", []).append(out["depth"] / self.norm.scale)
            if "accumulation" in out:
                parts.setdefault("accumulation", []).append(out["accumulation"])
            if "probs" in out:  # rendered probabilities (losses.focal_mask_on), by the ray's weight
                parts.setdefault("probs", []).append(out["probs"] / out["probs"].sum(-1, keepdim=True).clamp(min=1e-6))
            elif "logits" in out:
                parts.setdefault("probs", []).append(torch.softmax(out["logits"], dim=-1))
            if "language" in out:
                parts.setdefault("language", []).append(F.normalize(out["language"], dim=-1))
        return {k: torch.cat(v).float().cpu().numpy() for k, v in parts.items()}

    def render(self, camera: Camera, c2w: np.ndarray, states: States = None, frame_index: int | None = None,
               outputs: Collection[str] = IMAGE_OUTPUTS) -> dict[str, np.ndarray]:
        """Render a full image of ``camera`` at pose ``c2w`` (dataset world, OpenGL) with ``states``.

        ``outputs`` picks what to render (default all); ``("rgb",)`` is the fast path of plain images.
        """
        state = self.state_vector(states, frame_index)
        origins, dirs = generate_rays(camera, np.asarray(c2w, dtype=np.float64))
        t = self.frame_time(frame_index) if frame_index is not None else 0.0
        flat = self.render_rays(origins, dirs, state, t, outputs)
        h, w = camera.height, camera.width
        return {k: v.reshape(h, w, *v.shape[1:]) for k, v in flat.items()}

    def relevancy(self, camera: Camera, c2w: np.ndarray, states: States, query_embedding: np.ndarray,
                  frame_index: int | None = None) -> np.ndarray:
        """Cosine similarity [H, W] of the rendered language embedding with a query embedding."""
        out = self.render(camera, c2w, states, frame_index, outputs=("language",))
        if "language" not in out:
            raise InputError(self.run_dir, "this run renders no language embedding",
                             "train with --language-targets targets.npz")
        q = np.asarray(query_embedding, dtype=np.float32)
        return out["language"] @ (q / max(float(np.linalg.norm(q)), 1e-12))


def load_run(run_dir: str | Path, device: str = "cpu") -> LoadedRun:
    """Open a run folder written by ``livescene train`` (needs model.pt)."""
    resolve_device(device)  # before the weights are read
    run_dir = Path(run_dir)
    path = run_dir / "model.pt"
    if not path.is_file():
        raise InputError(path, "no trained model in this run folder",
                         "train one with `livescene train --data DS --out RUN` (or resume it to the end)")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, EOFError, OSError, pickle.UnpicklingError) as exc:
        resume = " or resume its training (`livescene train --resume --out RUN`, from checkpoints/)" if any(
            (run_dir / "checkpoints").glob("step_*.pt")) else ""
        raise InputError(path, f"cannot be read, truncated or corrupt ({str(exc).splitlines()[0]})",
                         f"copy the run folder again{resume}") from exc
    if not isinstance(payload, dict) or payload.get("format") != MODEL_FORMAT:
        raise InputError(path, f"model format {payload.get('format')} was written by an older version of the model "
                         f"stage (this one reads format {MODEL_FORMAT})",
                         "retrain the run (`livescene train ... --out NEW`), or load it with the version that wrote it")
    run = LoadedRun(run_dir, payload, device)
    _check_finite_weights(path, dict(run.model.named_parameters()))  # buffers may hold NaN (an absent key state)
    return run


def _check_finite_weights(path: Path, parameters: Mapping[str, torch.Tensor]) -> None:
    """Refuse weights holding NaN or inf: training never saves them (it stops first), and at render time a NaN
    density would only show as empty space (``render_weights`` maps it to zero thickness)."""
    bad = {name: int((~torch.isfinite(t)).sum()) for name, t in parameters.items() if not bool(torch.isfinite(t).all())}
    if bad:
        named = ", ".join(f"{name} ({n})" for name, n in sorted(bad.items())[:4]) + (" ..." if len(bad) > 4 else "")
        raise InputError(path, f"{sum(bad.values())} weights are NaN or infinite, in {named}; `livescene train` "
                         "never writes such a file, so it was damaged or written by something else",
                         "copy the run folder again, or retrain it (`livescene train ... --out NEW`)")


def _run_folder(run_dir: str | Path) -> Path:
    """``run_dir`` as a Path, or an error saying the folder itself is missing (not only its model.pt)."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(run_dir, "run folder not found", "train one with `livescene train --data DS --out RUN`")
    return run_dir


def open_run(run_dir: str | Path, device: str = "cpu") -> LoadedRun:
    """``load_run`` for a run folder named on the command line: a folder that is not there is named as such."""
    return load_run(_run_folder(run_dir), device=device)


def run_config(run_dir: str | Path) -> RunConfig | None:
    """The RunConfig of the run's config.yaml (written first by ``livescene train``); None when there is none."""
    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        return None
    return config_from_dict(read_yaml_mapping(path, "the run's settings, as `livescene train` writes them",
                                              error=InputError), str(path))


def run_dataset_root(run_dir: str | Path) -> Path | None:
    """The dataset the run was trained on, ``RunConfig.data`` as written (None when the run does not say)."""
    config = run_config(run_dir)
    return Path(config.data) if config is not None and config.data else None


def _cameras(transforms: Path) -> dict[str, list]:
    """file path -> camera-to-world of a transforms.json (unreadable: empty, so that nothing is claimed)."""
    try:
        frames = json.loads(transforms.read_text()).get("frames", [])
        return {str(f.get("file_path")): f.get("transform_matrix") for f in frames if isinstance(f, dict)}
    except (OSError, ValueError, AttributeError):
        return {}


def recorded_dataset(run_dir: str | Path) -> Path | None:
    """The dataset the run was trained on, where it is found (see ``dataset_of_run``); None when the run does not
    say or it is not there."""
    found = run_dataset_root(run_dir)
    return None if found is None else _located(found, Path(run_dir))


def _located(found: Path, run_dir: Path) -> Path | None:
    """``RunConfig.data`` as written, looked for from the current folder, then from each ancestor of the run folder."""
    candidates = [found] if found.is_absolute() else [found, *(parent / found for parent in run_dir.resolve().parents)]
    return next((c for c in candidates if c.is_dir()), None)


def dataset_of_run(run_dir: str | Path, data: str | Path | None = None) -> Path:
    """The dataset to open with a run: ``data`` (--data) when given, else the run's own.

    ``RunConfig.data`` is the path as training was given it: relative to the folder training ran in (the
    workflow trains from the repository root: ``results/demo/dataset``). It is looked for from the current
    folder, then from each ancestor of the run folder, so a results folder moved as a whole still opens; a
    dataset found nowhere is an error naming the run's config.yaml and the fix.
    """
    if data:
        return Path(data)
    run_dir = _run_folder(run_dir)
    path = run_dir / "config.yaml"
    found = run_dataset_root(run_dir)
    if found is None:
        raise InputError(path, "does not say which dataset the run was trained on", "pass --data DS")
    located = _located(found, run_dir)
    if located is not None:
        return located
    raise InputError(path, f"names the dataset {found}, which is not there from {Path.cwd()} (nor relative to the "
                     "run folder's parents)", "pass --data DS (the dataset the run was trained on), or start from "
                     "the folder the run was trained in")
