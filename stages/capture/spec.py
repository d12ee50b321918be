"""The scene spec of a synthetic capture: a room, furniture, articulated objects, a camera path.

A spec is YAML that maps one to one onto the dataclasses below, each value
checked against the field's type (stages/scene/typed_yaml.py). Geometry is
written in metres; ``units.per_metre`` scales every output coordinate (poses,
depth, scene box) so a capture can live in millimetres without the spec
changing. World axes: z up, floor at z = 0, the room centred on x = y = 0.

Time in state schedules is the fraction of the capture (0 = first frame,
1 = last frame), so a schedule keeps its meaning when the frame count changes.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stages.scene import InputError, read_yaml_mapping
from stages.scene.dataset import names_read_alike, object_name_problem
from stages.scene.typed_yaml import from_mapping

OBJECT_KINDS = ("door", "drawer", "lid")
HINGES = {"door": ("left", "right", "top", "bottom"), "lid": ("back",), "drawer": ("front",)}
INTERPOLATIONS = ("smooth", "linear", "step")
CAMERA_KINDS = ("orbit", "walk")
MASK_SCOPES = ("object", "moving")


class CaptureSpecError(InputError):
    """A capture spec that cannot be rendered."""


@dataclass
class Units:
    """Output units of the capture."""

    name: str = "m"
    """Unit name written to scene.json (m, mm, ...)."""
    per_metre: float = 1.0
    """Output units per metre of the spec (1000 = millimetres)."""


@dataclass
class LensDistortion:
    """OpenCV radial-tangential coefficients of the lens, in normalised image coordinates (all 0 = a pinhole)."""

    k1: float = 0.0
    """First radial coefficient (negative = barrel, as most phone lenses before correction)."""
    k2: float = 0.0
    """Second radial coefficient."""
    p1: float = 0.0
    """First tangential coefficient (a lens tilted against the sensor)."""
    p2: float = 0.0
    """Second tangential coefficient."""


@dataclass
class VideoSpec:
    """Resolution, timing and lens of the rendered video."""

    width: int = 320
    """Image width, pixels."""
    height: int = 240
    """Image height, pixels."""
    fps: float = 10.0
    """Frames per second of video.mp4; schedules and camera speed are in seconds through it."""
    n_frames: int = 80
    """Number of video frames."""
    fov_deg: float = 65.0
    """Horizontal field of view, degrees (square pixels, centred principal point)."""
    exposure_jitter: float = 0.0
    """Standard deviation of each frame's log gain, as a phone's auto exposure moves it (0 = constant exposure).
    The video and truth/images carry it; the truth renderer renders at the nominal exposure."""
    white_balance_jitter: float = 0.0
    """Standard deviation of each frame's per-channel log gain (auto white balance; 0 = none)."""
    shutter: float = 0.0
    """Exposure time as a fraction of the frame interval (0 = instantaneous, no motion blur; 0.5 = 1/20 s at
    10 fps): each frame averages ``blur_samples`` renders over the exposure, centred on the frame's time."""
    blur_samples: int = 8
    """Sub-frame renders averaged per frame when ``shutter`` > 0 (each costs a full render)."""
    rolling_shutter: float = 0.0
    """Readout time of the whole sensor as a fraction of the frame interval (0 = global shutter): row r is exposed
    at the frame's time + (r / (height - 1) - 0.5) x rolling_shutter / fps, the top row first."""
    noise_read: float = 0.0
    """Sensor noise independent of the signal: its standard deviation in linear intensity (1 = white)."""
    noise_shot: float = 0.0
    """Signal-dependent (photon) noise: variance shot x intensity, added to noise_read's variance."""
    distortion: LensDistortion = field(default_factory=LensDistortion)
    """The lens's radial and tangential distortion (OpenCV model); written into truth/transforms.json."""


@dataclass
class LightSpec:
    """A point light."""

    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 2.4])
    """Light position, metres."""
    intensity: float = 0.7
    """Diffuse intensity (albedo x intensity x cos at full exposure)."""
    shadows: bool = True
    """Cast shadow rays towards this light."""


@dataclass
class RenderSpec:
    """Shading and texture settings."""

    ambient: float = 0.35
    """Ambient light level (fraction of albedo seen in full shadow)."""
    lights: list[LightSpec] = field(default_factory=lambda: [LightSpec()])
    """Point lights (at least one)."""
    shadows: bool = True
    """Master switch for shadow rays (per-light ``shadows`` also applies)."""
    supersample: int = 1
    """Rays per pixel side (2 = 4 rays per pixel, box-filtered) for anti-aliasing."""
    texels_per_metre: float = 100.0
    """Texture resolution on surfaces; 100 = 1 cm texels."""
    texture_size: int = 512
    """Side of each procedural texture in texels (period = size / texels_per_metre metres)."""
    contrast: float = 0.3
    """Relative amplitude of the texture pattern around each surface's base colour."""


@dataclass
class FurnitureSpec:
    """A static box (table, shelf, sofa block); part of the background."""

    name: str
    """Name (only for textures and debugging; furniture is background in the masks)."""
    position: list[float]
    """Centre of the footprint at the bottom face [x, y, z_bottom], metres."""
    size: list[float]
    """[width (x), depth (y), height (z)], metres, before yaw."""
    yaw_deg: float = 0.0
    """Rotation about the vertical axis, degrees."""
    color: list[float] | None = None
    """Base colour RGB in [0, 1]; None = drawn from the seed."""


@dataclass
class ScheduleSpec:
    """State (0 closed .. 1 open) of one object over the capture."""

    keys: list[list[float]] = field(default_factory=lambda: [[0.0, 0.0], [1.0, 0.0]])
    """[[time fraction in 0..1, state], ...], time increasing; held constant outside."""
    interpolation: str = "smooth"
    """smooth (eased, zero speed at keys), linear, or step (jump at each key)."""


@dataclass
class ObjectSpec:
    """An articulated object: a static carcass and one moving part."""

    name: str
    """Unique name, used in mapping.yaml, key frames and prompts."""
    kind: str
    """door (revolute, vertical or horizontal hinge), drawer (prismatic) or lid (hinge on the back top edge)."""
    position: list[float]
    """Centre of the footprint at the bottom face [x, y, z_bottom], metres; the front faces -y before yaw."""
    size: list[float]
    """[width, depth, height] of the carcass, metres."""
    yaw_deg: float = 0.0
    """Rotation about the vertical axis, degrees (0 = front faces -y)."""
    hinge: str | None = None
    """door: left, right, top or bottom edge of the front; lid: back; drawer: front. None = the first."""
    limits: list[float] | None = None
    """Joint range [closed, open]: degrees for door/lid, metres for drawer; None = a kind default."""
    thickness: float = 0.02
    """Panel thickness, metres (thin objects use less)."""
    synonyms: list[str] = field(default_factory=list)
    """Other names a person may use for it."""
    description: str = ""
    """One sentence describing the object, for prompts.yaml."""
    schedule: ScheduleSpec = field(default_factory=ScheduleSpec)
    """State over time."""
    color: list[float] | None = None
    """Carcass base colour RGB in [0, 1]; None = drawn from the seed."""
    front_color: list[float] | None = None
    """Moving part base colour RGB; None = drawn from the seed."""


@dataclass
class JitterSpec:
    """Smooth hand shake added to the camera path."""

    position: float = 0.02
    """Amplitude of the positional shake, metres."""
    rotation_deg: float = 0.8
    """Amplitude of the rotational shake, degrees."""
    frequency_hz: float = 0.6
    """Typical shake frequency, Hz (a sum of three sinusoids around it)."""


@dataclass
class CameraPathSpec:
    """A handheld-like camera path."""

    kind: str = "orbit"
    """orbit (arc around a target) or walk (through waypoints, looking at a target)."""
    target: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.6])
    """Point looked at, metres."""
    radius: float = 1.6
    """orbit: horizontal distance from the target, metres (the default stays 0.4 m inside the default room's
    walls; 2.0 put the camera on the wall)."""
    height: float = 1.4
    """orbit: camera height above the floor, metres."""
    start_deg: float = -40.0
    """orbit: azimuth at the first frame, degrees; 0 = camera on the -y side of the target."""
    speed_deg_s: float = 10.0
    """orbit: angular speed, degrees per second (negative = clockwise)."""
    waypoints: list[list[float]] = field(default_factory=list)
    """walk: camera positions to pass through, metres."""
    speed_m_s: float = 0.3
    """walk: speed along the waypoints, metres per second (stops at the last)."""
    jitter: JitterSpec = field(default_factory=JitterSpec)
    """Hand shake."""


@dataclass
class KeyFrameSpec:
    """How densely the sparse key-frame states are annotated."""

    every: int = 8
    """Annotate every n-th video frame (starting at frame 0)."""
    include_last: bool = True
    """Also annotate the last frame."""
    noise_std: float = 0.0
    """Standard deviation of Gaussian annotation noise (state units), clipped to [0, 1]."""
    decimals: int = 3
    """Values are rounded to this many decimals, like a person typing them."""


@dataclass
class CaptureSpec:
    """Everything needed to render a capture deterministically."""

    name: str
    """Capture name (written to capture.json)."""
    room: list[float] = field(default_factory=lambda: [5.0, 4.0, 2.6])
    """Room interior [x, y, z] size, metres; floor at z = 0, centred on x = y = 0."""
    objects: list[ObjectSpec] = field(default_factory=list)
    """Articulated objects; mapping.yaml id k = position k in this list (1-based)."""
    furniture: list[FurnitureSpec] = field(default_factory=list)
    """Static boxes."""
    camera: CameraPathSpec = field(default_factory=CameraPathSpec)
    """Camera path."""
    video: VideoSpec = field(default_factory=VideoSpec)
    """Resolution and timing."""
    render: RenderSpec = field(default_factory=RenderSpec)
    """Shading."""
    key_frames: KeyFrameSpec = field(default_factory=KeyFrameSpec)
    """Sparse state annotation."""
    units: Units = field(default_factory=Units)
    """Output units."""
    mask_scope: str = "object"
    """object: carcass + moving part carry the object's id; moving: only the moving part."""
    seed: int = 0
    """Seed of every random choice (textures, colours, jitter, annotation noise)."""
    write_truth_images: bool = True
    """Also write lossless PNG frames to truth/images (the video is lossy)."""

    @property
    def object_names(self) -> list[str]:
        return [o.name for o in self.objects]


def spec_from_dict(data: dict[str, Any], path: str | Path = "<spec>") -> CaptureSpec:
    """Build a spec from parsed YAML (types checked against the fields), then check it can be rendered."""
    path = Path(path)
    spec = from_mapping(CaptureSpec, data, path=path, root="spec", error=CaptureSpecError)
    validate_spec(spec, path)
    return spec


def load_spec(path: str | Path) -> CaptureSpec:
    """Read a spec YAML file; errors name the file, the key and the fix."""
    path = Path(path)
    data = read_yaml_mapping(path, "a capture spec (name:, room:, objects:, camera:, video: ...; see "
                             "config/captures/demo.yaml)", error=CaptureSpecError)
    if not data:
        raise CaptureSpecError(path, "spec is empty", "write name:, room:, objects:, camera:, ...")
    data.setdefault("name", path.stem)
    return spec_from_dict(data, path)


CAMERA_EFFECT_KEYS = ("shutter", "blur_samples", "rolling_shutter", "noise_read", "noise_shot", "distortion")
"""The phone camera's effects among ``video``'s keys (docs/captures.md, "Phone camera effects")."""


def camera_effects(video: VideoSpec) -> dict[str, Any] | None:
    """The phone camera's effects of a spec as plain data, or None when every one is off (their defaults)."""
    if not (video.shutter > 0 or video.rolling_shutter > 0 or video.noise_read > 0 or video.noise_shot > 0
            or any(dataclasses.astuple(video.distortion))):
        return None
    out = {k: getattr(video, k) for k in CAMERA_EFFECT_KEYS}
    out["distortion"] = dataclasses.asdict(video.distortion)
    return out


def spec_to_dict(spec: CaptureSpec) -> dict[str, Any]:
    """Plain data (YAML-serialisable) of a spec; ``spec_from_dict`` inverts it.

    Without any phone camera effect their keys are left out (they read back as their defaults), so a capture of
    a spec that has none writes the truth/spec.yaml it wrote before the effects existed."""
    data = dataclasses.asdict(spec)
    if camera_effects(spec.video) is None:
        for k in CAMERA_EFFECT_KEYS:
            del data["video"][k]
    return data


def _vec(value: Any, n: int, path: Path, where: str, positive: bool = False) -> None:
    ok = isinstance(value, list | tuple) and len(value) == n and all(
        isinstance(v, int | float) and math.isfinite(v) for v in value)
    if not ok:
        raise CaptureSpecError(path, f"{where} is {value!r}, expected {n} numbers", f"write {where}: [{n} numbers]")
    if positive and any(v <= 0 for v in value):
        raise CaptureSpecError(path, f"{where} is {value!r}, all values must be > 0", "use positive sizes")


def _inside_room(room: list[float], position: list[float], size: list[float], yaw_deg: float, path: Path,
                 where: str) -> None:
    """A box (footprint centre at its bottom face, [width, depth, height], yaw) must stand inside the room: one
    outside it, or through a wall, is hidden by the walls or cut by them, and its masks and states then describe
    nothing the camera sees."""
    half_w, half_d = size[0] / 2, size[1] / 2
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    reach_x = abs(c) * half_w + abs(s) * half_d  # half extents of the yawed footprint along x and y
    reach_y = abs(s) * half_w + abs(c) * half_d
    eps = 1e-6  # flush against a wall or on the floor is inside
    lo = (position[0] - reach_x, position[1] - reach_y, position[2])
    hi = (position[0] + reach_x, position[1] + reach_y, position[2] + size[2])
    if (any(v < -r / 2 - eps for v, r in zip(lo[:2], room[:2], strict=True)) or lo[2] < -eps
            or any(v > r / 2 + eps for v, r in zip(hi[:2], room[:2], strict=True)) or hi[2] > room[2] + eps):
        box = ", ".join(f"{a:.3g}..{b:.3g}" for a, b in zip(lo, hi, strict=True))
        raise CaptureSpecError(
            path, f"{where} spans x, y, z = {box} m, outside the room ({-room[0] / 2:.3g}..{room[0] / 2:.3g}, "
            f"{-room[1] / 2:.3g}..{room[1] / 2:.3g}, 0..{room[2]:.3g})",
            "move it inside the room (its position is the centre of its footprint's bottom face) or make it smaller")


OVERLAP_TOLERANCE_M = 0.001
"""Boxes may touch (stacked drawers, a cabinet against a table) and interpenetrate by up to this much."""


def _footprint_corners(position: list[float], size: list[float], yaw_deg: float) -> np.ndarray:
    """The four corners [4, 2] of a yawed footprint (x, y)."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    half = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64) * np.array(size[:2]) / 2
    return half @ np.array([[c, s], [-s, c]]) + np.array(position[:2], dtype=np.float64)


def _penetration(a: tuple[list[float], list[float], float], b: tuple[list[float], list[float], float]) -> float:
    """How deep two boxes (position, size, yaw) interpenetrate, metres (<= 0: apart or touching): the smallest
    overlap over the separating axes of two upright boxes (each footprint's two edge directions, and z)."""
    (pa, sa, ya), (pb, sb, yb) = a, b
    depth = min(pa[2] + sa[2], pb[2] + sb[2]) - max(pa[2], pb[2])
    ca, cb = _footprint_corners(pa, sa, ya), _footprint_corners(pb, sb, yb)
    for yaw in (ya, yb):
        for axis in (np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw))]),
                     np.array([-math.sin(math.radians(yaw)), math.cos(math.radians(yaw))])):
            ra, rb = ca @ axis, cb @ axis
            depth = min(depth, min(ra.max(), rb.max()) - max(ra.min(), rb.min()))
    return float(depth)


def _no_overlaps(spec: CaptureSpec, path: Path) -> None:
    """An object's carcass must not interpenetrate another carcass or a piece of furniture: the masks would give the
    shared space to whichever box the renderer meets first, and a door or drawer would open through the other box.
    Pieces of furniture may overlap each other (an L-shaped counter of two boxes): both are background."""
    objects = [(f"objects[{i}] ({o.name})", (o.position, o.size, o.yaw_deg)) for i, o in enumerate(spec.objects)]
    furniture = [(f"furniture[{i}] ({f.name})", (f.position, f.size, f.yaw_deg)) for i, f in enumerate(spec.furniture)]
    pairs = [*itertools.combinations(objects, 2), *itertools.product(objects, furniture)]
    for (name_a, a), (name_b, b) in pairs:
        depth = _penetration(a, b)
        if depth > OVERLAP_TOLERANCE_M:
            raise CaptureSpecError(path, f"{name_a} and {name_b} overlap by {depth:.3g} m",
                                   "move one of them (position is the centre of the footprint's bottom face) or "
                                   "make it smaller; boxes may touch")


def _joint_range(o: ObjectSpec, path: Path, where: str) -> None:
    """An object's ``limits`` must open it (closed < open, 0 = shut against the carcass) without passing through
    its own carcass: a door or lid by at most 180 degrees, a drawer by at most the carcass's depth (a
    full-extension drawer; its tray, shorter than the carcass by the front panel and 1 cm of runners
    (``geometry._articulated``), already clears the carcass then, and further would float further in front)."""
    closed, opened = (float(v) for v in o.limits)
    if o.kind == "drawer":
        reach, unit = float(o.size[1]), "m"
        fix = f"give [closed, open] in metres with 0 <= closed < open <= {reach:.3g} (the carcass's depth)"
    else:
        reach, unit = 180.0, "degrees"
        fix = "give [closed, open] in degrees with 0 <= closed < open <= 180"
    if not 0.0 <= closed < opened <= reach:
        raise CaptureSpecError(path, f"{where}.limits {[closed, opened]} ({unit}) do not open the {o.kind} within "
                               f"its range (state 0 = closed, 1 = open; a negative value moves it into its carcass)",
                               fix)


MAX_BLUR_SAMPLES = 64
"""More sub-frame renders than this per frame would take hours for a preset and smooth nothing more."""
MAX_NOISE_READ = 0.2
MAX_NOISE_SHOT = 0.1
"""A standard deviation of ~0.37 at white (sqrt(0.2^2 + 0.1)): far beyond a phone in a dim room; above these the
frames would be mostly clipped noise."""


def _check_camera_effects(spec: CaptureSpec, path: Path) -> None:
    v = spec.video
    for key, hi, meaning in (("shutter", 1.0, "the exposure time as a fraction of the frame interval"),
                             ("rolling_shutter", 1.0, "the sensor's readout time as a fraction of the frame interval"),
                             ("noise_read", MAX_NOISE_READ, "a standard deviation in linear intensity, e.g. 0.01"),
                             ("noise_shot", MAX_NOISE_SHOT, "a variance per unit intensity, e.g. 0.005")):
        value = getattr(v, key)
        if not (math.isfinite(value) and 0.0 <= value <= hi):
            raise CaptureSpecError(path, f"video.{key} is {value}, outside [0, {hi:g}]", f"give {meaning}")
    if not 1 <= v.blur_samples <= MAX_BLUR_SAMPLES:
        raise CaptureSpecError(path, f"video.blur_samples is {v.blur_samples}, outside [1, {MAX_BLUR_SAMPLES}]",
                               "give the number of sub-frame renders averaged per frame, e.g. 8 (each costs a render)")
    for key, value in dataclasses.asdict(v.distortion).items():
        # before the fold check: a NaN coefficient is no distortion to Camera.has_distortion, so the check would pass
        # it and the truth camera would carry a NaN every reader of transforms.json refuses
        if not math.isfinite(value):
            raise CaptureSpecError(path, f"video.distortion.{key} is {value}",
                                   "give a finite coefficient (0 for none), e.g. k1: -0.05")
    from stages.scene.camera import distortion_fold

    from .lens import lens_camera  # imports this module

    problem = distortion_fold(lens_camera(v))
    if problem is not None:
        d = dataclasses.asdict(v.distortion)
        raise CaptureSpecError(path, f"video.distortion {d}: {problem}",
                               "give the coefficients of a phone lens: |k1| and |k2| of a few hundredths to tenths "
                               "(docs/captures.md, \"Phone camera effects\")")


def validate_spec(spec: CaptureSpec, path: str | Path = "<spec>") -> None:
    """Reject specs that cannot be rendered, naming the key and the fix."""
    path = Path(path)
    v = spec.video
    if v.width < 8 or v.height < 8 or v.n_frames < 1 or v.fps <= 0 or not 1 < v.fov_deg < 170:
        raise CaptureSpecError(path, f"video {dataclasses.asdict(v)} is out of range",
                               "use width, height >= 8, n_frames >= 1, fps > 0, 1 < fov_deg < 170")
    if not (0.0 <= v.exposure_jitter <= 1.0 and 0.0 <= v.white_balance_jitter <= 1.0):
        raise CaptureSpecError(path, f"video.exposure_jitter {v.exposure_jitter} / white_balance_jitter "
                               f"{v.white_balance_jitter} out of range", "give log-gain deviations in [0, 1], e.g. 0.1")
    _check_camera_effects(spec, path)
    _vec(spec.room, 3, path, "room", positive=True)
    if spec.units.per_metre <= 0:
        raise CaptureSpecError(path, "units.per_metre must be > 0", "write 1 for metres, 1000 for millimetres")
    if spec.render.supersample < 1 or spec.render.texture_size < 16 or spec.render.texels_per_metre <= 0:
        raise CaptureSpecError(path, "render.supersample >= 1, texture_size >= 16, texels_per_metre > 0 needed",
                               "fix the render section")
    if not spec.render.lights:
        raise CaptureSpecError(path, "render.lights is empty", "add at least one light")
    if not 0.0 <= spec.render.ambient <= 1.0:
        raise CaptureSpecError(path, f"render.ambient {spec.render.ambient} is outside [0, 1]",
                               "give the fraction of albedo seen in full shadow, e.g. 0.35")
    for i, light in enumerate(spec.render.lights):
        _vec(light.position, 3, path, f"render.lights[{i}].position")
        if light.intensity < 0:
            raise CaptureSpecError(path, f"render.lights[{i}].intensity {light.intensity} is negative (a light that "
                                   "darkens)", "give an intensity >= 0, e.g. 0.7")
    if spec.mask_scope not in MASK_SCOPES:
        raise CaptureSpecError(path, f"mask_scope {spec.mask_scope!r} unknown", f"use one of {MASK_SCOPES}")
    if len(spec.objects) > 254:
        raise CaptureSpecError(path, "more than 254 objects do not fit uint8 id masks", "use fewer objects")
    names = spec.object_names
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise CaptureSpecError(path, f"object names {dupes} appear more than once", "give each object a unique name")
    if (problem := names_read_alike(names)) is not None:
        raise CaptureSpecError(path, problem, "rename one of them in words (e.g. 'left drawer')")
    for i, o in enumerate(spec.objects):
        where = f"objects[{i}] ({o.name})"
        if (problem := object_name_problem(o.name)) is not None:
            raise CaptureSpecError(path, f"{where}: the name {problem}", "name the object in words (e.g. 'top drawer')")
        if o.kind not in OBJECT_KINDS:
            raise CaptureSpecError(path, f"{where}: kind {o.kind!r} unknown", f"use one of {OBJECT_KINDS}")
        if o.hinge is not None and o.hinge not in HINGES[o.kind]:
            raise CaptureSpecError(path, f"{where}: hinge {o.hinge!r} is not valid for a {o.kind}",
                                   f"use one of {HINGES[o.kind]}")
        _vec(o.position, 3, path, f"{where}.position")
        _vec(o.size, 3, path, f"{where}.size", positive=True)
        _inside_room(spec.room, o.position, o.size, o.yaw_deg, path, where)
        if o.limits is not None:
            _vec(o.limits, 2, path, f"{where}.limits")
            _joint_range(o, path, where)
        if not 0 < o.thickness < 0.5 * min(o.size):
            raise CaptureSpecError(path, f"{where}: thickness {o.thickness} must be > 0 and < half the smallest size",
                                   "use a panel thickness of a few centimetres")
        keys = o.schedule.keys
        if o.schedule.interpolation not in INTERPOLATIONS:
            raise CaptureSpecError(path, f"{where}: schedule.interpolation {o.schedule.interpolation!r} unknown",
                                   f"use one of {INTERPOLATIONS}")
        if not keys or any(not isinstance(k, list | tuple) or len(k) != 2 for k in keys):
            raise CaptureSpecError(path, f"{where}: schedule.keys must be a list of [time, state] pairs",
                                   "write keys: [[0.0, 0.0], [0.5, 1.0], ...]")
        times = [float(k[0]) for k in keys]
        if any(b < a for a, b in itertools.pairwise(times)):
            raise CaptureSpecError(path, f"{where}: schedule times {times} are not increasing",
                                   "sort the keys by time")
        if any(not 0.0 <= float(k[1]) <= 1.0 for k in keys):
            raise CaptureSpecError(path, f"{where}: schedule states must lie in [0, 1]",
                                   "0 = closed, 1 = open; put the joint range in limits")
    for i, f in enumerate(spec.furniture):
        _vec(f.position, 3, path, f"furniture[{i}].position")
        _vec(f.size, 3, path, f"furniture[{i}].size", positive=True)
        _inside_room(spec.room, f.position, f.size, f.yaw_deg, path, f"furniture[{i}] ({f.name})")
    _no_overlaps(spec, path)
    c = spec.camera
    if c.kind not in CAMERA_KINDS:
        raise CaptureSpecError(path, f"camera.kind {c.kind!r} unknown", f"use one of {CAMERA_KINDS}")
    _vec(c.target, 3, path, "camera.target")
    if c.kind == "walk":
        if len(c.waypoints) < 2:
            raise CaptureSpecError(path, "camera.kind walk needs at least 2 waypoints", "add camera.waypoints")
        for i, w in enumerate(c.waypoints):
            _vec(w, 3, path, f"camera.waypoints[{i}]")
    elif c.radius <= 0:
        raise CaptureSpecError(path, "camera.radius must be > 0", "give the orbit radius in metres")
    if spec.key_frames.every < 1 or spec.key_frames.noise_std < 0:
        raise CaptureSpecError(path, "key_frames.every >= 1 and noise_std >= 0 needed", "fix key_frames")
    if spec.key_frames.decimals < 0:
        raise CaptureSpecError(path, f"key_frames.decimals is {spec.key_frames.decimals}, which would round key "
                               "values to tens", "give the decimals a person types, >= 0 (e.g. 2)")
    from .camera_path import camera_path  # imports this module

    camera_path(spec, path)  # refuses a camera on its target or looking straight down before any frame is rendered
