"""LiveScene (docs/method.md): proposal sampling with the k-projection at every level, one shared 4D field.

Per level: sample positions -> interaction probability field (logits for the
mask losses) -> argmax object ``u`` -> 4D coordinate (x, y, z, kappa_u) ->
proposal density (or, at the final level, the main radiance field). Baselines
subclass this model and override ``field_dims`` / ``coordinates`` to feed the
same sampler, trainer and losses a different field.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from .. import losses as L
from ..config import ModelConfig
from ..encodings import PlaneGrids
from ..fields import DensityField, LanguageTable, ProbabilityField, RadianceField, StateField
from ..language_targets import LanguageTargets
from ..ray_dataset import RayBatch
from ..ray_samplers import ProposalSchedule, RaySamples, pdf_samples, uniform_samples
from ..rays import RayBundle
from ..renderers import render_accumulation, render_depth, render_features, render_rgb, render_weights

RENDER_OUTPUTS = ("rgb", "depth", "accumulation", "logits", "language")
"""What ``forward`` can render; training renders all of them (language only with a table)."""
RENDER_WEIGHT_FLOOR = 1e-4
"""Outside training, samples whose render weight is at most this get no colour evaluation (black): with the
final level's samples per ray S, a pixel moves by at most S x 1e-4 (12 samples: 0.3/255)."""


@dataclass
class SceneInfo:
    """What a method needs to know about the scene to build itself."""

    objects: list[str]
    """Object names in state-vector order."""
    n_frames: int
    """Frames of the dataset (the learned-state grid spans their normalised index)."""
    key_times: list[float] = field(default_factory=list)
    """Normalised frame index of each key frame (learned-state supervision)."""
    key_states: list[list[float]] = field(default_factory=list)
    """Key-frame states [K, alpha]; NaN where an object is not annotated."""
    language_dim: int = 0
    """Language embedding width (0 = no language table)."""
    language_levels: int = 0
    """State levels of the language targets."""
    train_frames: list[int] = field(default_factory=list)
    """Indices of the training frames (empty = all): the per-frame colour corrections have zero mean over them."""
    frame_times: list[float] | None = None
    """Each frame's time in [0, 1] by its number (``stages.scene.key_frame_states.frame_times``); None when the
    frames are numbered evenly in file order (t = i / (n - 1)), as every run before this field had them."""

    def to_dict(self) -> dict:
        """The fields as saved in model.pt; ``frame_times`` only where set, so runs of evenly numbered frames keep
        the bytes they had before the field existed."""
        out = asdict(self)
        if out["frame_times"] is None:
            del out["frame_times"]
        return out

    def frame_time(self, index: int) -> float:
        if self.frame_times is not None:
            return self.frame_times[index]
        return index / (self.n_frames - 1) if self.n_frames > 1 else 0.0

    @property
    def n_objects(self) -> int:
        return len(self.objects)


def _render_probs(weights: torch.Tensor, logits: torch.Tensor) -> torch.Tensor:
    """Weights (detached) times every sample's softmax, summed along the ray [R, alpha + 1]."""
    return render_features(weights.detach(), torch.softmax(logits.float(), -1))


def _corrected(rgb: torch.Tensor, corrections: torch.Tensor) -> torch.Tensor:
    """Colour [R, 3] through per-ray (log gain, bias) [R, 6] of each channel."""
    return rgb * torch.exp(corrections[:, :3].clamp(-3.0, 3.0)) + corrections[:, 3:]


class LiveSceneModel(nn.Module):
    """The LiveScene method; ``forward`` renders rays, ``loss_dict`` weighs every term of section 5."""

    def __init__(self, config: ModelConfig, info: SceneInfo) -> None:
        super().__init__()
        self.config, self.info = config, info
        alpha = info.n_objects
        n_dims, pairs = self.field_dims()
        self.n_dims = n_dims
        self.field = RadianceField(config.field, n_dims, pairs)
        fc = config.field
        self.proposal_fields = nn.ModuleList([
            DensityField([r, r, r] + [kr] * (n_dims - 3), config.proposal.channels, config.proposal.hidden,
                         config.proposal.init_range, pairs, fc.density_bias, fc.density_exp_clamp)
            for r, kr in config.proposal.resolutions])
        if len(config.sampling.num_proposal_samples) != len(self.proposal_fields):
            raise ValueError(f"{len(config.sampling.num_proposal_samples)} proposal sample counts for "
                             f"{len(self.proposal_fields)} proposal fields; give one count per field")
        self.probability_field = ProbabilityField(config.probability, alpha, fc.k_resolution)
        self.state_field = StateField(config.state, alpha) if config.state.mode == "learned" else None
        self.language_table: LanguageTable | None = None
        if info.language_dim > 0:
            buckets = config.language.buckets or max(info.language_levels, 2)
            self.language_table = LanguageTable(alpha, buckets, info.language_dim)
        self.schedule = ProposalSchedule(config.sampling)
        # per-frame (log gain, bias) of each colour channel; absent unless asked for, so the reference is unchanged
        self.appearance = nn.Parameter(torch.zeros(info.n_frames, 6)) if config.appearance.mode == "affine" else None
        if self.appearance is not None:
            train = torch.zeros(info.n_frames, dtype=torch.bool)
            train[info.train_frames or slice(None)] = True
            self.register_buffer("appearance_train", train)
        self.register_buffer("background", torch.tensor(config.sampling.background, dtype=torch.float32))
        self.last_sample_behind = config.sampling.background_mode == "last_sample"
        """What a ray does not cover shows its last sample's colour instead of ``background``."""
        key_states = torch.tensor(info.key_states, dtype=torch.float32).reshape(len(info.key_times), alpha)
        self.register_buffer("key_times", torch.tensor(info.key_times, dtype=torch.float32))
        self.register_buffer("key_states", key_states)

    # -- hooks a baseline overrides ---------------------------------------------------------------------------
    field_reads_probabilities: bool = True
    """Whether ``coordinates`` reads the probability field's logits at every sampling level (LiveScene's
    k-projection, CoNeRF's mask gating). A baseline whose field ignores them sets False: the probability field
    then runs at the final level only, which is all the evaluation's probabilities and grounding need
    (docs/baselines.md, "The probability field of the baselines")."""

    def field_dims(self) -> tuple[int, list[tuple[int, int]] | None]:
        """Coordinate width of the radiance/proposal fields and their plane pairs (None = all pairs)."""
        return 4, None

    def coordinates(self, positions: torch.Tensor, states: torch.Tensor, logits: torch.Tensor | None,
                    times: torch.Tensor) -> torch.Tensor:
        """Field coordinates [N, D] of samples: (x, y, z, 2 kappa_u - 1).

        ``logits`` is None only at a proposal level of a method with ``field_reads_probabilities`` False.
        """
        assert logits is not None, "the k-projection needs the probability field's logits"
        k, _ = self.probability_field.project(logits, states)
        return torch.cat([positions, (2.0 * k - 1.0).unsqueeze(-1).to(positions.dtype)], dim=-1)

    # -- states ---------------------------------------------------------------------------------------------
    def ray_states(self, rays: RayBundle) -> torch.Tensor:
        """[R, alpha]: given states, or the learned state at each ray's frame time."""
        if self.state_field is not None and (rays.states is None or self.training):
            assert rays.times is not None, "learned-state mode needs the frame time of every ray"
            return self.state_field(rays.times)
        if rays.states is None:
            return torch.zeros(len(rays), self.info.n_objects, device=rays.origins.device)
        return rays.states.float()

    # -- rendering ------------------------------------------------------------------------------------------
    def _level(self, rays: RayBundle, samples: RaySamples, states: torch.Tensor, level: int, final: bool,
               grad_density: bool, want_rgb: bool = True) -> dict[str, torch.Tensor]:
        """One sampling level: proposal field ``level`` (or, with ``final``, the radiance field) at ``samples``."""
        n_rays, n_samp = samples.bins.shape[0], samples.n_samples
        mids = samples.mids
        pos = (rays.origins[:, None, :] + rays.directions[:, None, :] * mids[..., None]).reshape(-1, 3)
        pos = pos.clamp(-1.0, 1.0)
        st = states[:, None, :].expand(n_rays, n_samp, states.shape[-1]).reshape(n_rays * n_samp, states.shape[-1])
        times = rays.times if rays.times is not None else torch.zeros(n_rays, device=pos.device)
        t = times[:, None].expand(n_rays, n_samp).reshape(-1)
        # one set of plane grids per level: the spatial xy/xz/yz grid serves the probability tri-plane and every
        # scale of the density field, the k grid every scale
        grids: PlaneGrids = {}
        out: dict[str, torch.Tensor] = {}
        logits = None
        if final or self.field_reads_probabilities:
            supervised = final or self.config.losses.mask_levels == "all"
            # the tri-plane is sampled at box-normalised positions (the reference code forgets to normalise)
            with torch.set_grad_enabled(supervised and torch.is_grad_enabled()):
                logits = self.probability_field(pos, states, grids)
            if supervised:  # the mask losses read these; otherwise the argmax below is their only use
                out["logits"] = logits.view(n_rays, n_samp, -1)
        coords = self.coordinates(pos, st, logits, t)
        if final:
            sigma, geo = self.field.density(coords, grids)
            weights = render_weights(sigma.view(n_rays, n_samp), samples.deltas)
            if want_rgb:
                # the samples of a ray share its direction: encoded once per ray, each sample takes its ray's row
                sh = self.field.direction_encoding(rays.directions)
                if self.training:
                    per_sample = sh[:, None, :].expand(n_rays, n_samp, sh.shape[-1])
                    rgb = self.field.color(geo, per_sample.reshape(n_rays * n_samp, -1))
                else:  # rendering: no colour for samples the image cannot see (error <= samples x floor per pixel)
                    visible = weights > RENDER_WEIGHT_FLOOR
                    if self.last_sample_behind:
                        visible[:, -1] = True  # its colour shows behind the ray
                    keep = visible.reshape(-1).nonzero()[:, 0]
                    rgb = torch.zeros(n_rays * n_samp, 3, device=geo.device)
                    rgb[keep] = self.field.color(geo[keep], sh[keep // n_samp])
                out["rgb"] = rgb.view(n_rays, n_samp, 3)
        else:
            with torch.set_grad_enabled(grad_density and torch.is_grad_enabled()):
                sigma = self.proposal_fields[level](coords, grids)
            weights = render_weights(sigma.view(n_rays, n_samp), samples.deltas)
        out["density"], out["weights"] = sigma.view(n_rays, n_samp), weights
        return out

    def render_language(self, weights: torch.Tensor, logits: torch.Tensor, states: torch.Tensor,
                        times: torch.Tensor | None) -> torch.Tensor:
        """Rendered language embedding [R, D] of the final level (``LanguageTable.render``).

        Every sample takes the entry of its region (argmax over all alpha + 1
        logits, so background samples take the background entry) at the state of
        that region's object, or at the frame time; the weights are detached, as
        the language loss trains the table only.
        """
        assert self.language_table is not None
        alpha = self.info.n_objects
        region = logits.detach().argmax(dim=-1)  # [R, S]
        region_weights = torch.zeros(weights.shape[0], alpha + 1, device=weights.device, dtype=torch.float32)
        region_weights = region_weights.scatter_add(1, region, weights.detach().float())
        if self.config.language.interpolate_by == "frame" or alpha == 0:
            t = times if times is not None else torch.zeros(weights.shape[0], device=weights.device)
            values = t[:, None].float().expand(-1, alpha + 1)
        else:
            values = torch.cat([states.float(), torch.zeros_like(states[:, :1]).float()], dim=1)
        return self.language_table.render(region_weights, values)

    def forward(self, rays: RayBundle, step: int = 0, generator: torch.Generator | None = None,
                outputs: Collection[str] = RENDER_OUTPUTS, anneal: float | torch.Tensor | None = None) -> dict:
        """Render rays. In training mode the result holds what ``loss_dict`` needs; in eval, images only.

        ``outputs`` (eval) names what to render of ``RENDER_OUTPUTS``: a plain
        image needs only ``("rgb",)``, which skips the language table and the
        rendered logits (the probability field still runs: it places k).
        ``anneal`` replaces the schedule's proposal exponent at ``step``: a
        device tensor lets one captured CUDA graph serve every step (step_graphs.py).
        """
        cfg = self.config.sampling
        training = self.training
        if training:
            outputs = RENDER_OUTPUTS
        states = self.ray_states(rays)
        grad_prop = training and self.schedule.updates_proposals(step)
        anneal = self.schedule.anneal(step) if anneal is None else anneal
        annealed = isinstance(anneal, torch.Tensor) or anneal != 1.0
        samples = uniform_samples(rays.nears, rays.fars, cfg.num_proposal_samples[0], training, cfg.single_jitter,
                                  generator) if self.proposal_fields else uniform_samples(
            rays.nears, rays.fars, cfg.num_samples, training, cfg.single_jitter, generator)
        # no state on self: threads may render chunks through one model at the same time
        levels: list[tuple[RaySamples, dict]] = []
        for i in range(len(self.proposal_fields)):
            lvl = self._level(rays, samples, states, i, final=False, grad_density=grad_prop)
            levels.append((samples, lvl))
            n_next = cfg.num_proposal_samples[i + 1] if i + 1 < len(self.proposal_fields) else cfg.num_samples
            w = lvl["weights"].detach()
            samples = pdf_samples(samples, w.clamp(min=0) ** anneal if annealed else w, n_next, training,
                                  cfg.single_jitter, cfg.histogram_padding, generator)
        final = self._level(rays, samples, states, len(levels), final=True, grad_density=True,
                            want_rgb="rgb" in outputs)
        w = final["weights"]
        out: dict = {"states": states}
        if "rgb" in outputs:
            behind = final["rgb"][:, -1, :] if self.last_sample_behind else self.background
            out["rgb"] = render_rgb(w, final["rgb"], behind)
        if "depth" in outputs:
            out["depth"] = render_depth(w, samples.mids, rays.nears, rays.fars)
        if "accumulation" in outputs:
            out["accumulation"] = render_accumulation(w)
        if "logits" in outputs:
            out["logits"] = render_features(w.detach(), final["logits"])
            if self.config.losses.focal_mask_on in ("probabilities", "samples"):
                # what the mask loss trains is what the relevancy maps show
                out["probs"] = _render_probs(w, final["logits"])
        if "language" in outputs and self.language_table is not None:
            out["language"] = self.render_language(w, final["logits"], states, rays.times)
        if training:
            out["proposal"] = [(s, lv["weights"]) for s, lv in levels]
            out["final"] = (samples, w)
            # the mask losses supervise every level whose logits were kept (model.losses.mask_levels)
            out["level_logits"] = [render_features(lv["weights"].detach(), lv["logits"])
                                   for _, lv in levels if "logits" in lv]
            out["level_logits"].append(out["logits"])
            if self.config.losses.focal_mask_on == "samples":
                out["level_samples"] = [(lv["weights"], lv["logits"]) for _, lv in [*levels, (samples, final)]
                                        if "logits" in lv]
            elif self.config.losses.focal_mask_on in ("probabilities", "both"):
                out["level_probs"] = [_render_probs(lv["weights"], lv["logits"]) for _, lv in levels if "logits" in lv]
                out["level_probs"].append(out["probs"] if "probs" in out else _render_probs(w, final["logits"]))
        return out

    # -- losses ---------------------------------------------------------------------------------------------
    def _focal_mask(self, out: dict, labels: torch.Tensor) -> torch.Tensor:
        """The focal mask loss summed over every level whose logits exist, in the form ``focal_mask_on`` names."""
        form = self.config.losses.focal_mask_on
        if form == "samples":
            return sum(L.focal_mask_loss_samples(w, lg, labels) for w, lg in out["level_samples"])
        terms = []
        if form in ("logits", "both"):
            terms.append(sum(L.focal_mask_loss(lg, labels) for lg in out["level_logits"]))
        if form in ("probabilities", "both"):
            terms.append(sum(L.focal_mask_loss_probs(p, labels) for p in out["level_probs"]))
        return sum(terms[1:], terms[0])  # no add of a leading 0: one form costs no extra op

    def loss_dict(self, out: dict, batch: RayBatch, step: int,
                  language: LanguageTargets | None = None) -> dict[str, torch.Tensor]:
        """Every weighted loss term (terms with weight 0 are left out)."""
        w = self.config.losses
        rays = batch.rays
        terms: dict[str, torch.Tensor] = {}

        def add(name: str, weight: float, fn) -> None:
            if weight != 0:
                terms[name] = weight * fn()

        if self.appearance is None:
            add("rgb", w.rgb, lambda: L.rgb_loss(out["rgb"], batch.rgb))
        else:
            corrections = self.frame_corrections()[batch.frames]
            add("rgb", w.rgb, lambda: L.rgb_loss(_corrected(out["rgb"], corrections), batch.rgb))
            add("appearance", w.appearance, lambda: corrections.square().mean())
        if out["proposal"]:
            add("interlevel", w.interlevel, lambda: L.interlevel_loss(out["proposal"], out["final"]))
        add("distortion", w.distortion, lambda: L.distortion_loss(out["final"][0], out["final"][1], rays.nears,
                                                                   rays.fars))
        add("plane_tv", w.plane_tv, lambda: L.plane_tv(self.field.encoding))
        add("plane_tv_proposal", w.plane_tv_proposal,
            lambda: sum(L.plane_tv(p.encoding) for p in self.proposal_fields))
        add("plane_tv_probability", w.plane_tv_probability, lambda: L.plane_tv(self.probability_field.encoding))
        add("l1_k_planes", w.l1_k_planes, lambda: L.k_planes_l1(self.field.encoding))
        add("l1_k_planes_proposal", w.l1_k_planes_proposal,
            lambda: sum(L.k_planes_l1(p.encoding) for p in self.proposal_fields))
        add("k_smoothness", w.k_smoothness, lambda: L.k_smoothness(self.field.encoding))
        add("k_smoothness_proposal", w.k_smoothness_proposal,
            lambda: sum(L.k_smoothness(p.encoding) for p in self.proposal_fields))
        if self.info.n_objects > 0:
            add("focal_mask", w.focal_mask,
                lambda: self._focal_mask(out, batch.labels))
            add("repulsion", w.repulsion,
                lambda: sum(L.repulsion_loss(lg, batch.labels, w.repulsion_margin) for lg in out["level_logits"]))
        if "language" in out and language is not None:
            add("language", w.language, lambda: L.language_loss(
                out["language"], language.targets(batch.labels, out["states"]), batch.labels >= 0,
                self.config.language.huber_delta))
        if self.state_field is not None and self.key_times.numel() > 0:
            add("state_mse", w.state_mse, lambda: L.state_loss(self.state_field(self.key_times), self.key_states))
        return terms

    def frame_corrections(self) -> torch.Tensor:
        """Per-frame (log gain, bias) [n_frames, 6], zero-mean over the training frames.

        Without the centring, a colour shift shared by every frame could sit in the corrections or in the field
        alike, and the renders (which use none) would carry whatever part the field took."""
        assert self.appearance is not None
        train = self.appearance_train.unsqueeze(-1).to(self.appearance.dtype)
        return self.appearance - (self.appearance * train).sum(0) / train.sum()

    def frame_colour(self, rgb: torch.Tensor, frames: torch.Tensor) -> torch.Tensor:
        """Rendered colour [R, 3] as the frames' cameras saw it: per-frame gain and bias (``appearance``)."""
        return rgb if self.appearance is None else _corrected(rgb, self.frame_corrections()[frames])

    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        """Parameters by role (all share one learning rate schedule; the split is for reporting)."""
        groups = {
            "field": list(self.field.parameters()),
            "proposal_fields": list(self.proposal_fields.parameters()),
            "probability_field": list(self.probability_field.parameters()),
        }
        if self.state_field is not None:
            groups["state_field"] = list(self.state_field.parameters())
        if self.language_table is not None:
            groups["language_table"] = list(self.language_table.parameters())
        if self.appearance is not None:
            groups["appearance"] = [self.appearance]
        return groups
