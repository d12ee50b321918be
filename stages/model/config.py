"""Every hyperparameter of the model stage, as nested dataclasses built from a preset YAML.

A preset (``config/model/<name>.yaml``) gives any subset of the fields below;
``--set section.field=value`` overrides one field from the command line. Every
value must have its field's type, nothing is converted (docs/model.md, Presets). The
defaults are the reference settings of docs/method.md; where the paper and the
authors' code disagree, the field's docstring says which one the default follows.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml

from stages.scene import InputError, read_yaml_mapping
from stages.scene.typed_yaml import from_mapping

PRESET_DIR = Path(__file__).resolve().parent / "presets"
"""The presets, shipped with the package: in a checkout a link to config/model (docs/model.md, Presets)."""


@dataclass
class RadianceFieldConfig:
    """The main 4D K-Planes field over (x, y, z, k)."""

    base_resolution: int = 128
    """Spatial plane resolution at scale x1 (cells per axis over the [-1, 1] box)."""
    k_resolution: int = 32
    """Resolution of the k (interaction variable) axis of the xk, yk, zk planes."""
    scales: list[int] = dataclasses.field(default_factory=lambda: [1, 2, 4])
    """Spatial multipliers of the multi-scale planes (features concatenated over scales)."""
    channels: int = 32
    """Feature channels per plane and scale."""
    init_range: list[float] = dataclasses.field(default_factory=lambda: [0.1, 0.5])
    """Uniform init of the spatial planes (k planes start at 1, the product's identity)."""
    geo_feat_dim: int = 15
    """Geometry features passed from the density MLP to the colour MLP."""
    hidden: int = 64
    """Width of the density MLP's single hidden layer."""
    color_hidden: int = 64
    """Width of the colour MLP's hidden layers."""
    color_layers: int = 2
    """Hidden layers of the colour MLP (16 SH + 15 features -> 64 -> 64 -> 3)."""
    sh_degree: int = 4
    """Spherical-harmonics degree of the view-direction encoding (4 -> 16 components)."""
    density_bias: float = -1.0
    """density = exp(raw + density_bias); the reference uses exp(raw - 1)."""
    density_exp_clamp: float = 15.0
    """Clamp of the exponent (truncated exp) so densities stay finite in float32 and bf16."""


@dataclass
class ProposalConfig:
    """The proposal density fields (one per proposal level)."""

    resolutions: list[list[int]] = dataclasses.field(default_factory=lambda: [[64, 32], [128, 32]])
    """Per level: [spatial resolution, k resolution] (reference [64,64,64,32] and [128,128,128,32])."""
    channels: int = 8
    """Feature channels of each proposal K-Planes grid."""
    hidden: int = 64
    """Width of the one hidden layer of the proposal density MLP."""
    init_range: list[float] = dataclasses.field(default_factory=lambda: [0.1, 0.15])
    """Uniform init of proposal spatial planes (reference code's 0.1..0.15)."""


@dataclass
class ProbabilityConfig:
    """The interaction probability field (tri-plane + MLP -> alpha + 1 logits), shared by all levels."""

    resolution: int = 128
    """Tri-plane resolution (reference code: 128 on the last proposal level's language grid)."""
    channels: int = 8
    """Tri-plane channels (planes multiplied, then sigmoid)."""
    hidden: int = 64
    """Width of the decoder's single hidden layer."""
    init_range: list[float] = dataclasses.field(default_factory=lambda: [0.1, 0.15])
    """Uniform init of the tri-planes (reference code's 0.1..0.15)."""
    rejection_threshold: float = 0.0
    """Samples whose best object probability is below this get k = static_value (reference ships 0 = off)."""
    static_value: float = 0.0
    """The 4th coordinate of rejected samples (reference code: 0)."""
    static_row: bool = False
    """Give rejected samples a row of the k-planes of their own: objects' states then take the k axis from the
    main field's second vertex on (``kappa -> 1/(K-1) + (1 - 1/(K-1)) kappa``, K = ``field.k_resolution``), so
    the static value 0 (the first vertex) is read by the static room alone, not also by every closed object
    (reference: off, one shared row; docs/rooms.md "The static room's own row")."""
    state_input: Literal["all", "none"] = "all"
    """What the decoder reads besides the features: ``all`` = the whole state vector (reference code), ``none`` =
    nothing, so an object's region is the space it sweeps over all its states and no state change moves any
    sample to another object (docs/method.md section 2)."""


@dataclass
class SamplingConfig:
    """Proposal sampling with the k-projection at every level (docs/method.md section 4)."""

    num_proposal_samples: list[int] = dataclasses.field(default_factory=lambda: [256, 128])
    """Samples per ray at each proposal level (reference 256, 128)."""
    num_samples: int = 48
    """Samples per ray of the final level (reference code 48; the paper says 64)."""
    single_jitter: bool = False
    """Use one jitter per ray instead of one per sample."""
    anneal_slope: float = 10.0
    """Slope of the proposal-weight annealing exponent (Mip-NeRF 360 eq. 18)."""
    anneal_max_steps: int = 1000
    """Steps over which the annealing exponent rises from 0 to 1."""
    update_every: int = 5
    """After the warm-up the proposal nets get gradients every this many steps."""
    update_warmup: int = 5000
    """Steps over which the update interval ramps from 1 to update_every."""
    near_plane: float = 0.05
    """Nearest sample distance, in normalised scene units."""
    background: list[float] = dataclasses.field(default_factory=lambda: [1.0, 1.0, 1.0])
    """Colour behind the last sample (reference: white), with ``background_mode: fixed``."""
    background_mode: Literal["fixed", "last_sample"] = "fixed"
    """``fixed``: ``background`` (the reference). ``last_sample``: the colour of each ray's last sample (nerfacto's
    default for real captures), so a ray always ends on an opaque colour of the model's own. A model starts half
    transparent, so against white its first renders are far brighter than a dark room; the first steps then push
    the colour head into saturation at black, and the room is fitted as grey opacity over the white background
    (docs/model.md, "Background colour")."""
    histogram_padding: float = 0.01
    """Added to the weights before PDF sampling so no interval has zero probability."""


@dataclass
class StateConfig:
    """Given or learned object states (docs/method.md section 6)."""

    mode: Literal["auto", "given", "learned"] = "auto"
    """'given' (dense states from the dataset), 'learned' (key frames supervise a state network) or 'auto': given
    when every frame carries every object's state, else learned when the dataset has key frames (a published
    dataset); a run records the mode it resolved to."""
    grid_resolution: int = 256
    """Cells of the 1D grid over normalised frame index (257 vertices, as the reference)."""
    grid_channels: int = 4
    """Channels of the 1D state grid (= input width of the state MLP)."""
    hidden: int = 32
    """Hidden width of the state MLP (docs/method.md: 4 -> 32 -> alpha; the reference code's field default is 64)."""
    positional_encoding: bool = True
    """Add the small sinusoidal encoding of the frame index to the grid features (reference: on)."""
    grid_init: list[float] = dataclasses.field(default_factory=lambda: [0.0, 1.0])
    """Uniform init of the 1D grid (reference 0..1)."""
    key_frame_every: int = 0
    """0: supervise with key_frame_value.yaml; N > 0: use the dataset's own states of every N-th frame instead."""


@dataclass
class LanguageConfig:
    """The interaction-aware language table (docs/method.md section 7); active with --language-targets."""

    buckets: int = 0
    """State buckets per object in the table; 0 = as many as the targets file has levels."""
    interpolate_by: Literal["kappa", "frame"] = "kappa"
    """'kappa' (paper: interpolate by the object's state) or 'frame' (reference code: by frame index)."""
    huber_delta: float = 1.25
    """Delta of the Huber loss on rendered embeddings."""


@dataclass
class LossWeights:
    """Loss weights (docs/method.md section 5, the reference values)."""

    rgb: float = 1.0
    """Photometric MSE."""
    interlevel: float = 1.0
    """Proposal interlevel loss."""
    distortion: float = 0.001
    """Mip-NeRF 360 distortion loss on the final weights."""
    plane_tv: float = 0.1
    """Total variation of the main field's planes."""
    plane_tv_proposal: float = 1e-4
    """Total variation of the proposal fields' planes."""
    plane_tv_probability: float = 1e-4
    """Total variation of the probability field's tri-planes."""
    l1_k_planes: float = 1e-3
    """L1 of the main field's k planes to 1."""
    l1_k_planes_proposal: float = 1e-4
    """L1 of the proposal fields' k planes to 1."""
    k_smoothness: float = 0.1
    """Second-difference smoothness along k, main field."""
    k_smoothness_proposal: float = 1e-3
    """Second-difference smoothness along k, proposal fields."""
    focal_mask: float = 1e-3
    """Focal cross-entropy of rendered logits against mask labels, at the levels ``mask_levels`` names."""
    focal_mask_on: Literal["logits", "probabilities", "samples", "both"] = "logits"
    """What the focal mask loss judges along a ray: ``logits`` the rendered logits (the reference; one
    low-weight sample with an extreme logit can outvote the surface), ``probabilities`` the rendered
    per-sample probabilities, ``samples`` every sample's own focal CE weighted by its rendering weight,
    ``both`` the logits and the probabilities forms summed (docs/method.md section 5)."""
    mask_levels: Literal["all", "final"] = "all"
    """Which sampling levels the mask losses (focal, repulsion) supervise: ``all`` (the reference) or ``final``
    only. With ``final`` the probability field runs without gradient at the proposal levels, where its argmax only
    places the k coordinate (docs/method.md section 5)."""
    repulsion: float = 1e-3
    """Repulsion of rendered logits of ray pairs with different labels."""
    repulsion_margin: float = 10.0
    """K of ELU(K - dist) + 1."""
    language: float = 0.1
    """Huber loss of the rendered language embedding."""
    state_mse: float = 1e-3
    """MSE of learned states against key frames (learned-state mode only)."""
    appearance: float = 1e-2
    """L2 of the per-frame colour corrections (``appearance.mode: affine`` only)."""


@dataclass
class ConerfConfig:
    """The CoNeRF-style baseline (``--method conerf``; other methods ignore this section)."""

    attribute_frequencies: int = 4
    """Sinusoidal frequencies per gated attribute fed to the field MLP (0 = the raw gated value only)."""
    hidden: int = 64
    """Width of the density MLP's hidden layers (spatial features + encoded attributes -> density)."""
    hidden_layers: int = 2
    """Hidden layers of the density MLP (the attributes enter only here, so it needs depth)."""
    latent_dim: int = 8
    """Per-frame latent code width; learned-state mode regresses the attributes from it (key frames only)."""


@dataclass
class AppearanceConfig:
    """Per-frame colour of the training images (docs/model.md, "Exposure")."""

    mode: Literal["none", "affine", "measured", "auto"] = "none"
    """``affine``: every training frame gets a learned per-channel log gain and bias applied to the rendered
    colour in the photometric loss (a phone's auto exposure and white balance), zero at the start and
    L2-penalised; renders and evaluation use none (the nominal colour). ``measured``: nothing is learned; each
    training image is divided by its gains as measured from its overlapping neighbours (``stages.scene.exposure``).
    ``none``: the reference. ``auto``: ``measured`` when the dataset's frames vary in exposure by at least
    ``auto_spread``, else ``none``; the run records the choice and the measured spread
    (``stages.model.appearance_choice``)."""
    auto_spread: float = 0.01
    """``auto``: the least spread of the frames' log gains (std over frames; ``stages.scene.exposure``) that turns
    the correction on. Constant exposure reads 0.0005-0.0008 on the synthetic captures; docs/model.md has the
    measurements behind the value."""


@dataclass
class ModelConfig:
    """What the method is made of."""

    field: RadianceFieldConfig = dataclasses.field(default_factory=RadianceFieldConfig)
    """Main radiance field."""
    proposal: ProposalConfig = dataclasses.field(default_factory=ProposalConfig)
    """Proposal density fields."""
    probability: ProbabilityConfig = dataclasses.field(default_factory=ProbabilityConfig)
    """Interaction probability field."""
    sampling: SamplingConfig = dataclasses.field(default_factory=SamplingConfig)
    """Ray sampling."""
    state: StateConfig = dataclasses.field(default_factory=StateConfig)
    """State source."""
    language: LanguageConfig = dataclasses.field(default_factory=LanguageConfig)
    """Language table."""
    losses: LossWeights = dataclasses.field(default_factory=LossWeights)
    """Loss weights."""
    conerf: ConerfConfig = dataclasses.field(default_factory=ConerfConfig)
    """CoNeRF-style baseline settings (used by ``--method conerf`` only)."""
    appearance: AppearanceConfig = dataclasses.field(default_factory=AppearanceConfig)
    """Per-frame colour correction of the training images."""


@dataclass
class TrainConfig:
    """How training runs."""

    max_steps: int = 80000
    """Optimisation steps (paper: 80k OmniSim, 100k InterReal)."""
    max_seconds: float = 0.0
    """Wall-clock budget in seconds (0 = none); training stops and saves when it is spent."""
    batch_rays: int = 4096
    """Rays per step (reference 4096)."""
    lr: float = 0.02
    """Peak Adam learning rate of every parameter group (LiveScene reference code 2e-2; K-Planes uses 1e-2)."""
    adam_eps: float = 1e-12
    """Adam epsilon (LiveScene reference code 1e-12; nerfstudio K-Planes 1e-15)."""
    warmup_steps: int = 512
    """Linear learning-rate warm-up steps (K-Planes: 512)."""
    lr_final_ratio: float = 0.0
    """Learning rate at the last step relative to the peak (cosine decay)."""
    mixed_precision: Literal["auto", "bf16", "fp16", "off"] = "auto"
    """'auto' (bf16 autocast on CUDA where supported, else fp16; off on CPU), or 'bf16' / 'fp16' (any device), 'off'."""
    eval_every: int = 500
    """Held-out PSNR every this many steps (0 = never)."""
    eval_rays: int = 4096
    """Fixed held-out rays used for the periodic PSNR."""
    checkpoint_every: int = 5000
    """Checkpoint every this many steps (and at the end, on SIGTERM and on the time budget)."""
    keep_checkpoints: int = 2
    """How many step checkpoints to keep."""
    log_every: int = 10
    """Steps between reads of the queued steps' loss terms and finite checks (one host sync each; also at eval and
    checkpoint steps). Steps in between never wait for the device; a skipped step is named at the next read."""
    max_nonfinite: int = 20
    """Stop after this many consecutive steps with a non-finite loss or gradient."""
    render_chunk: int = 4096
    """Rays per forward pass when rendering whole images."""
    threads: int = 0
    """torch CPU threads (0 = leave torch's default)."""
    compile: bool = False
    """torch.compile the fields' forward passes (fullgraph, dynamic shapes). Off by default: on an H100 it trained
    no faster than eager, and on the CPU the inductor build takes longer than a cpu-demo run saves (docs/model.md)."""
    compile_mode: Literal["default", "reduce-overhead"] = "default"
    """With ``compile``: torch.compile's mode. ``reduce-overhead`` replays each field's kernels as CUDA graphs
    (static shapes: one graph per distinct batch shape), which saves the launch cost of a step whose device
    work is shorter than its dispatch; on the CPU it only compiles for static shapes (no graphs there)."""
    cuda_graphs: bool = True
    """On CUDA: capture the whole training step (forward, losses, backward, finite checks, Adam) as CUDA graphs
    and replay them, one launch per step instead of ~2,500 ops' kernels (step_graphs.py; on an H200 1.8x the
    eager rays/s). A run that compiles its fields or scales an fp16 loss trains eagerly, and says so. Ignored on
    the CPU."""
    camera_opt: Literal["off", "SO3xR3"] = "off"
    """Refine the training cameras while training: ``SO3xR3`` learns a rotation and a translation per training frame,
    applied to its rays, with an Adam of its own (nerfacto's camera optimiser; docs/model.md, "Camera refinement").
    Off by default: a run without it has none of its keys in its config and trains as before. A refined run's
    held-out views are aligned to the refined world before they are scored (the evaluation's ``view_alignment``)."""
    camera_opt_lr: float = 1e-3
    """Peak learning rate of the corrections (nerfacto: 1e-3), decayed exponentially to ``camera_opt_lr_final``."""
    camera_opt_lr_final: float = 1e-4
    """The corrections' learning rate at the last step (nerfacto: 1e-4)."""
    camera_opt_translation_penalty: float = 1e-2
    """Weight of the mean length of the translation corrections (normalised scene units) in the loss (nerfacto 1e-2):
    it keeps the corrections, whose common part no image constrains, small."""
    camera_opt_rotation_penalty: float = 1e-3
    """Weight of the mean rotation angle of the corrections (radians) in the loss (nerfacto 1e-3)."""


CAMERA_OPT_KEYS = ("camera_opt", "camera_opt_lr", "camera_opt_lr_final", "camera_opt_translation_penalty",
                   "camera_opt_rotation_penalty")
"""The ``train`` keys of camera refinement: a run with ``camera_opt: off`` records none of them (its config.yaml,
checkpoints and model.pt are byte for byte those of a run before the option existed)."""


@dataclass
class TrustConfig:
    """When a trained run's numbers are results: below these the report flags the run instead of ranking it."""

    min_steps: int = 30000
    """Fewer optimisation steps than this: undertrained for the preset (a number from too little training)."""
    min_psnr: float = 20.0
    """Held-out PSNR (dB) below this: the renders are not trustworthy."""
    min_grounding_miou: float = 0.5
    """Grounding mIoU below this: the probability field has not found the objects."""
    min_object_accumulation: float = 0.5
    """Held-out mean accumulation over object pixels below this: most of an object's colour comes from what the
    ray meets behind it (the background; under ``last_sample`` the colour at the ray's end), so the run paints its
    objects, and their states, on the room behind them instead of modelling them where they are."""


@dataclass
class RunConfig:
    """A whole run: the method, its model and the training schedule."""

    method: str = "livescene"
    """Registered method name (livescene, mk-planes, mk-planes-star, conerf, k-planes)."""
    preset: str = "gpu-paper"
    """Preset the config started from."""
    seed: int = 0
    """Seed of every random generator (parameters, ray sampling, jitter)."""
    data: str = ""
    """Scene dataset the run trains on."""
    language_targets: str = ""
    """Language targets .npz (empty = no language table)."""
    exposure: str = ""
    """The dataset's exposure estimate (``livescene scene exposure --out``) for ``model.appearance.mode`` auto or
    measured; empty = the trainer measures the frames itself."""
    model: ModelConfig = dataclasses.field(default_factory=ModelConfig)
    """Model hyperparameters."""
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    """Training schedule."""
    trust: TrustConfig = dataclasses.field(default_factory=TrustConfig)
    """Floors under which the report calls a run undertrained or untrustworthy."""

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        if self.train.camera_opt == "off":  # absent means off (config_from_dict fills the defaults back in)
            for key in CAMERA_OPT_KEYS:
                del out["train"][key]
        return out


def preset_path(preset: str) -> Path:
    """A preset name (config/model/<name>.yaml) or a path to a YAML file."""
    p = Path(preset)
    if p.suffix in (".yaml", ".yml") and p.is_file():
        return p
    candidate = PRESET_DIR / f"{preset}.yaml"
    if candidate.is_file():
        return candidate
    names = sorted(x.stem for x in PRESET_DIR.glob("*.yaml")) if PRESET_DIR.is_dir() else []
    raise InputError(candidate, f"preset {preset!r} not found", f"use one of {names} or a path to a YAML file")


def parse_override(text: str) -> tuple[list[str], Any]:
    """``model.field.channels=16`` -> (['model', 'field', 'channels'], 16); the value is parsed as YAML."""
    if "=" not in text:
        raise InputError("--set", f"{text!r} is not key=value", "write e.g. --set train.batch_rays=2048")
    key, value = text.split("=", 1)
    return key.strip().split("."), yaml.safe_load(value)


METHOD_DIR = PRESET_DIR / "methods"


def method_overlay(method: str, preset: str) -> dict[str, Any]:
    """The sections of ``config/model/methods/<method>.yaml`` that differ from base preset ``preset``.

    Each file maps a preset scale (``cpu-demo``, ``gpu-paper``) to the sections that differ, e.g.
    ``{gpu-paper: {model: {conerf: {hidden: 128}}}}`` (docs/baselines.md); a method or scale without an
    entry trains the base preset as is.
    """
    path = METHOD_DIR / f"{method}.yaml"
    if not path.is_file():
        return {}
    data = read_yaml_mapping(path, "{<preset scale>: {model: {...}, train: {...}}}", error=InputError)
    overlay = data.get(Path(preset).stem) or {}
    if not isinstance(overlay, dict):
        raise InputError(path, f"entry {Path(preset).stem!r} is not a mapping", "write model:/train: sections under it")
    return overlay


def _merge(base: dict[str, Any], overlay: dict[str, Any]) -> None:
    for key, value in overlay.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            _merge(base[key], value)
        else:
            base[key] = value


def load_config(preset: str = "gpu-paper", overrides: list[str] | None = None, **top: Any) -> RunConfig:
    """A RunConfig from a preset, the method's overlay on it, ``--set`` overrides, then top-level fields.

    This is the one way a method's config is built: the workflow's ``livescene train --method m``,
    ``livescene compare`` and the Python API all get preset + ``config/model/methods/<m>.yaml``.
    Each source is checked on its own against the field types first, so an error names the file (the
    preset, the overlay) or the ``--set`` item that holds the bad value. Top-level fields given as
    paths (``data=Path(...)``) are taken as their text.
    """
    path = preset_path(preset)
    data = read_yaml_mapping(path, "sections model:, train: and trust: (see config/model/cpu-demo.yaml)",
                             error=InputError)
    data.setdefault("preset", path.stem)
    from_mapping(RunConfig, data, path=path)
    parsed = []
    for text in overrides or []:
        keys, value = parse_override(text)
        _check_override(text, keys, value)
        parsed.append((text, keys, value))
    top = {k: os.fspath(v) if isinstance(v, os.PathLike) else v for k, v in top.items() if v is not None}
    from_mapping(RunConfig, top, path="load_config")
    method = top.get("method") or next((v for _, k, v in reversed(parsed) if k == ["method"]), data.get("method"))
    # no method named: the config trains the default method, so it gets that method's overlay too
    method = method or RunConfig.method
    if method:  # the overlay sits between the preset and the explicit overrides, which win
        # a preset file of the user's names the scale it varies in its own `preset:` key (a copy of cpu-demo.yaml
        # with `preset: cpu-demo` keeps cpu-demo's method overlays); else its name is the scale
        scale = str(data["preset"])
        overlay = method_overlay(str(method), scale)
        if not overlay and (METHOD_DIR / f"{method}.yaml").is_file() and not (PRESET_DIR / f"{scale}.yaml").is_file():
            warnings.warn(f"{path}: {METHOD_DIR / f'{method}.yaml'} has no entry {scale!r}, so {method} trains "
                          "without its overlay of settings; fix: write `preset: cpu-demo` (or gpu-paper) in the preset "
                          "file to take that scale's overlay", stacklevel=2)
        from_mapping(RunConfig, overlay, path=METHOD_DIR / f"{method}.yaml", root=scale)
        _merge(data, overlay)
    for text, keys, value in parsed:
        node = data
        for k in keys[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise InputError("--set", f"{text!r}: {k} is not a section", "name a field inside a section")
        node[keys[-1]] = value
    data.update(top)
    config = from_mapping(RunConfig, data, path=path)
    _check_ranges(config, path)
    return config


TRAIN_RANGES: dict[str, tuple[float, str]] = {
    "batch_rays": (1, "rays per step, e.g. 4096"), "eval_rays": (1, "held-out rays, e.g. 4096"),
    "render_chunk": (1, "rays per render pass, e.g. 4096"), "log_every": (0, "steps, e.g. 10"),
    "checkpoint_every": (0, "steps (0 = only at the end)"), "keep_checkpoints": (0, "checkpoints, e.g. 2"),
    "max_steps": (1, "steps"), "max_seconds": (0, "seconds (0 = no budget)"), "eval_every": (0, "steps (0 = never)"),
    "warmup_steps": (0, "steps"), "lr_final_ratio": (0, "a ratio, e.g. 0.0"), "threads": (0, "threads (0 = torch's)"),
    "max_nonfinite": (0, "steps, e.g. 20"), "camera_opt_translation_penalty": (0, "a weight, e.g. 0.01"),
    "camera_opt_rotation_penalty": (0, "a weight, e.g. 0.001"),
}
"""Least value of each numeric ``train`` field and what it counts: types are checked per source, ranges here."""


def _check_ranges(config: RunConfig, preset: Path) -> None:
    """Refuse a ``train`` value out of its range (a negative batch, a zero chunk, an lr that is not finite)."""
    for name, (least, what) in TRAIN_RANGES.items():
        value = getattr(config.train, name)
        if not math.isfinite(value) or value < least:
            raise InputError(f"train.{name}", f"{value} is out of range (in {preset} or a --set item)",
                             f"give {'a positive' if least else 'a non-negative'} number of {what}")
    for name in ("lr", "adam_eps", "camera_opt_lr", "camera_opt_lr_final"):
        value = getattr(config.train, name)
        if not (math.isfinite(value) and 0 < value <= 10):
            raise InputError(f"train.{name}", f"{value} is not a finite value in (0, 10] (in {preset} or a --set "
                             "item)", "give e.g. train.lr=0.02, train.adam_eps=1e-12, train.camera_opt_lr=0.001")
    for key, problem, fix in _model_problems(config.model):
        raise InputError(f"model.{key}", f"{problem} (in {preset}, its method overlay or a --set item)", fix)


def _model_problems(m: ModelConfig) -> list[tuple[str, str, str]]:
    """(key, problem, fix) of model values no field can be built from or whose meaning is undefined."""
    out: list[tuple[str, str, str]] = []

    def positive(key: str, value: int | float, what: str) -> None:
        if not value >= 1:
            out.append((key, f"{value} is not at least 1", f"give a positive number of {what}"))

    for key, value, what in [("field.base_resolution", m.field.base_resolution, "grid vertices"),
                             ("field.k_resolution", m.field.k_resolution, "grid vertices"),
                             ("field.channels", m.field.channels, "channels"),
                             ("proposal.channels", m.proposal.channels, "channels"),
                             ("probability.resolution", m.probability.resolution, "grid vertices"),
                             ("probability.channels", m.probability.channels, "channels"),
                             ("sampling.num_samples", m.sampling.num_samples, "samples per ray")]:
        positive(key, value, what)
    if not m.field.scales or any(v < 1 for v in m.field.scales):
        out.append(("field.scales", f"{m.field.scales} is not a list of positive multipliers", "give e.g. [1, 2]"))
    if any(len(r) != 2 or min(r) < 1 for r in m.proposal.resolutions):
        out.append(("proposal.resolutions", f"{m.proposal.resolutions} is not a list of [spatial, k] sizes >= 1",
                    "give e.g. [[32, 16]]"))
    if len(m.sampling.num_proposal_samples) != len(m.proposal.resolutions) or \
            any(v < 1 for v in m.sampling.num_proposal_samples):
        out.append(("sampling.num_proposal_samples", f"{m.sampling.num_proposal_samples} does not give one positive "
                    f"count per proposal field ({len(m.proposal.resolutions)})", "give one count per field"))
    for key, pair in [("field.init_range", m.field.init_range), ("proposal.init_range", m.proposal.init_range),
                      ("probability.init_range", m.probability.init_range)]:
        if len(pair) != 2 or not pair[0] < pair[1]:
            out.append((key, f"{pair} is not [low, high] with low below high", "give e.g. [0.1, 0.5]"))
    if len(m.sampling.background) != 3 or not all(0.0 <= v <= 1.0 for v in m.sampling.background):
        out.append(("sampling.background", f"{m.sampling.background} is not an RGB colour in [0, 1]",
                    "give three values, e.g. [1.0, 1.0, 1.0]"))
    if not 0.0 <= m.probability.rejection_threshold < 1.0:
        out.append(("probability.rejection_threshold", f"{m.probability.rejection_threshold} is not in [0, 1)",
                    "give a probability below 1 (at 1 every sample is rejected: no object is ever moved)"))
    for f in dataclasses.fields(m.losses):
        value = getattr(m.losses, f.name)
        if isinstance(value, float) and not (math.isfinite(value) and value >= 0):
            out.append((f"losses.{f.name}", f"{value} is not a finite weight >= 0", "give a weight >= 0"))
    return out


def _check_override(text: str, keys: list[str], value: Any) -> None:
    """Refuse an unknown key or a wrongly typed value of one ``--set`` item, naming the item."""
    nested: Any = value
    for k in reversed(keys):
        nested = {k: nested}
    try:
        from_mapping(RunConfig, nested, path="--set")
    except InputError as exc:
        raise InputError("--set", f"{text!r}: {exc.problem}", exc.fix) from None


def config_from_dict(data: dict[str, Any], where: str = "config.yaml") -> RunConfig:
    """Rebuild a RunConfig saved by ``RunConfig.to_dict`` (run folders, checkpoints)."""
    return from_mapping(RunConfig, data, path=where)
