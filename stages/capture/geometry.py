"""Scene geometry built from boxes: the room, furniture and articulated objects.

Every surface is a box ("part") so that a ray hit's triangle index tells the
part (index // 12) and the face (index % 12 // 2, ordered -x, +x, -y, +y, -z,
+z), which is what the texture lookup needs. A moving part's pose is its rest
pose composed with its object's joint transform at the current state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from .camera_path import seeded_rng
from .spec import CaptureSpec, ObjectSpec

FACE_AXES = np.array([0, 0, 1, 1, 2, 2])
FACE_SIGNS = np.array([-1, 1, -1, 1, -1, 1])
# the two in-plane axes of each face, for 2D texture coordinates
FACE_UV_AXES = np.array([[1, 2], [1, 2], [0, 2], [0, 2], [0, 1], [0, 1]])
DEFAULT_LIMITS = {"door": [0.0, 100.0], "lid": [0.0, 80.0]}
HANDLE_DEPTH = 0.03


@dataclass
class Material:
    """Look of one surface class; textures.py turns it into a texture image."""

    name: str
    """Unique name; seeds the texture, so the same name always looks the same for a seed."""
    color: np.ndarray
    """Base RGB in [0, 1]."""
    style: str
    """Pattern family: blobs, grain, tiles or speckle."""


@dataclass
class Part:
    """One box of the scene."""

    name: str
    """object/part, for debugging."""
    object_id: int
    """0 = background (room, furniture), k = objects[k - 1] of the spec."""
    moving: bool
    """Moves with its object's joint."""
    half: np.ndarray
    """Half extents along the box's own axes, metres."""
    rest: np.ndarray
    """4x4 pose of the box centre: in the object frame for object parts, in the world otherwise."""
    materials: np.ndarray
    """Material index per face (6,), faces ordered -x, +x, -y, +y, -z, +z."""


@dataclass
class Joint:
    """The one degree of freedom of an articulated object, in its object frame."""

    kind: str
    """revolute or prismatic."""
    axis: np.ndarray
    """Unit axis: rotation axis (right-hand rule, sign folded in) or translation direction."""
    pivot: np.ndarray
    """A point on the rotation axis (unused for prismatic)."""
    limits: tuple[float, float]
    """Joint values at state 0 and state 1 (radians or metres)."""

    def value(self, state: float) -> float:
        lo, hi = self.limits
        return lo + float(state) * (hi - lo)

    def transform(self, state: float) -> np.ndarray:
        """4x4 motion of the moving part at ``state`` (0 closed, 1 open)."""
        q = self.value(state)
        m = np.eye(4)
        if self.kind == "prismatic":
            m[:3, 3] = self.axis * q
            return m
        r = Rotation.from_rotvec(self.axis * q).as_matrix()
        m[:3, :3] = r
        m[:3, 3] = self.pivot - r @ self.pivot
        return m


@dataclass
class SceneModel:
    """All parts, objects and materials of a spec, in metres."""

    parts: list[Part]
    materials: list[Material]
    joints: list[Joint]
    """One per spec object, in spec order."""
    object_frames: list[np.ndarray]
    """4x4 object-to-world per spec object."""
    room_box: np.ndarray
    """[[min xyz], [max xyz]] of the room interior, metres."""
    part_object: np.ndarray = field(init=False)
    part_moving: np.ndarray = field(init=False)
    face_materials: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.part_object = np.array([p.object_id for p in self.parts], dtype=np.int32)
        self.part_moving = np.array([p.moving for p in self.parts], dtype=bool)
        self.face_materials = np.stack([p.materials for p in self.parts]).astype(np.int32)

    def part_poses(self, states: np.ndarray) -> np.ndarray:
        """``[n_parts, 4, 4]`` world poses of every box at the given object states."""
        motions = [frame @ joint.transform(s) for frame, joint, s in
                   zip(self.object_frames, self.joints, states, strict=True)]
        out = np.empty((len(self.parts), 4, 4))
        for i, p in enumerate(self.parts):
            if p.object_id == 0:
                out[i] = p.rest
            elif p.moving:
                out[i] = motions[p.object_id - 1] @ p.rest
            else:
                out[i] = self.object_frames[p.object_id - 1] @ p.rest
        return out

    def mesh(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vertices ``[8 P, 3]`` float32 and triangles ``[12 P, 3]`` uint32 of all boxes."""
        halves = np.stack([p.half for p in self.parts])  # [P, 3]
        local = _CORNER_SIGNS[None] * halves[:, None, :]  # [P, 8, 3]
        verts = np.einsum("pij,pkj->pki", poses[:, :3, :3], local) + poses[:, None, :3, 3]
        tris = _BOX_TRIANGLES[None] + 8 * np.arange(len(self.parts))[:, None, None]
        return verts.reshape(-1, 3).astype(np.float32), tris.reshape(-1, 3).astype(np.uint32)


# corners indexed by bits (x, y, z): bit set = + side
_CORNER_SIGNS = np.array([[(-1) ** (1 - ((i >> k) & 1)) for k in range(3)] for i in range(8)], dtype=np.float64)


def _box_triangles() -> np.ndarray:
    """12 triangles, two per face in the order -x, +x, -y, +y, -z, +z, wound outwards."""
    tris = []
    for axis in range(3):
        for side in (0, 1):
            corners = [i for i in range(8) if ((i >> axis) & 1) == side]
            a, b = [k for k in range(3) if k != axis]
            # order the 4 corners around the face
            quad = sorted(corners, key=lambda i: np.arctan2(_CORNER_SIGNS[i, b], _CORNER_SIGNS[i, a]))
            normal = np.zeros(3)
            normal[axis] = 1 if side else -1
            p = _CORNER_SIGNS[quad]
            if np.dot(np.cross(p[1] - p[0], p[2] - p[0]), normal) < 0:
                quad = quad[::-1]
            tris += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
    return np.array(tris, dtype=np.int64)


_BOX_TRIANGLES = _box_triangles()


def pose(centre: list[float] | np.ndarray, yaw_deg: float = 0.0) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    m[:3, 3] = centre
    return m


class _Builder:
    """Collects parts and materials while the scene is assembled."""

    def __init__(self, spec: CaptureSpec) -> None:
        self.spec = spec
        self.parts: list[Part] = []
        self.materials: list[Material] = []
        self._index: dict[str, int] = {}

    def material(self, name: str, style: str, color: list[float] | None = None,
                 palette: tuple[tuple[float, float], ...] = ((0.35, 0.85),) * 3) -> int:
        if name in self._index:
            return self._index[name]
        if color is None:
            rng = seeded_rng(self.spec.seed, f"colour/{name}")
            color = [rng.uniform(lo, hi) for lo, hi in palette]
        self._index[name] = len(self.materials)
        self.materials.append(Material(name=name, color=np.clip(np.asarray(color, float), 0, 1), style=style))
        return self._index[name]

    def box(self, name: str, object_id: int, moving: bool, centre: list[float], half: list[float],
            outer: int, inner: int | None = None, inner_face: int | None = None, yaw_deg: float = 0.0) -> None:
        mats = np.full(6, outer, dtype=np.int32)
        if inner is not None and inner_face is not None:
            mats[inner_face] = inner
        self.parts.append(Part(name=name, object_id=object_id, moving=moving, half=np.asarray(half, float),
                               rest=pose(centre, yaw_deg), materials=mats))


WOOD = ((0.45, 0.8), (0.3, 0.6), (0.15, 0.4))
PAINT = ((0.4, 0.9), (0.4, 0.9), (0.4, 0.9))


def _room(b: _Builder) -> np.ndarray:
    x, y, z = b.spec.room
    slab = 0.05
    floor = b.material("room/floor", "grain", palette=WOOD)
    ceiling = b.material("room/ceiling", "speckle", palette=((0.75, 0.9),) * 3)
    b.box("room/floor", 0, False, [0, 0, -slab], [x / 2 + 2 * slab, y / 2 + 2 * slab, slab], floor)
    b.box("room/ceiling", 0, False, [0, 0, z + slab], [x / 2 + 2 * slab, y / 2 + 2 * slab, slab], ceiling)
    for name, centre, half in (
        ("x-", [-x / 2 - slab, 0, z / 2], [slab, y / 2 + 2 * slab, z / 2 + 2 * slab]),
        ("x+", [x / 2 + slab, 0, z / 2], [slab, y / 2 + 2 * slab, z / 2 + 2 * slab]),
        ("y-", [0, -y / 2 - slab, z / 2], [x / 2 + 2 * slab, slab, z / 2 + 2 * slab]),
        ("y+", [0, y / 2 + slab, z / 2], [x / 2 + 2 * slab, slab, z / 2 + 2 * slab]),
    ):
        b.box(f"room/wall{name}", 0, False, centre, half, b.material(f"room/wall{name}", "blobs", palette=PAINT))
    return np.array([[-x / 2, -y / 2, 0.0], [x / 2, y / 2, z]])


def _open_box(b: _Builder, o: ObjectSpec, oid: int, open_side: str, outer: int, inner: int) -> None:
    """Carcass: five panels, open at the front (-y) or the top (+z)."""
    w, d, h = o.size
    t = o.thickness
    n = o.name
    b.box(f"{n}/left", oid, False, [-w / 2 + t / 2, 0, h / 2], [t / 2, d / 2, h / 2], outer, inner, 1)
    b.box(f"{n}/right", oid, False, [w / 2 - t / 2, 0, h / 2], [t / 2, d / 2, h / 2], outer, inner, 0)
    b.box(f"{n}/back", oid, False, [0, d / 2 - t / 2, h / 2], [w / 2 - t, t / 2, h / 2], outer, inner, 2)
    if open_side == "front":
        b.box(f"{n}/bottom", oid, False, [0, -t / 2, t / 2], [w / 2 - t, d / 2 - t / 2, t / 2], outer, inner, 5)
        b.box(f"{n}/top", oid, False, [0, -t / 2, h - t / 2], [w / 2 - t, d / 2 - t / 2, t / 2], outer, inner, 4)
    else:
        b.box(f"{n}/front", oid, False, [0, -d / 2 + t / 2, h / 2], [w / 2 - t, t / 2, h / 2], outer, inner, 3)
        b.box(f"{n}/bottom", oid, False, [0, 0, t / 2], [w / 2 - t, d / 2 - t, t / 2], outer, inner, 5)


def _articulated(b: _Builder, o: ObjectSpec, oid: int) -> Joint:
    w, d, h = o.size
    t = o.thickness
    n = o.name
    outer = b.material(f"{n}/carcass", "grain" if oid % 2 else "blobs", o.color, WOOD if oid % 2 else PAINT)
    inner = b.material(f"{n}/interior", "speckle", palette=((0.2, 0.45),) * 3)
    front = b.material(f"{n}/front", "blobs" if oid % 2 else "tiles", o.front_color, PAINT)
    handle = b.material(f"{n}/handle", "speckle", palette=((0.1, 0.3),) * 3)
    hd = HANDLE_DEPTH
    limits = o.limits if o.limits is not None else DEFAULT_LIMITS.get(o.kind, [0.0, 0.75 * d])

    if o.kind == "lid":
        _open_box(b, o, oid, "top", outer, inner)
        b.box(f"{n}/lid", oid, True, [0, 0, h + t / 2], [w / 2, d / 2, t / 2], front)
        b.box(f"{n}/handle", oid, True, [0, -d / 2 - hd / 2, h + t / 2], [min(0.08, w / 4), hd / 2, t / 2], handle)
        return Joint("revolute", np.array([-1.0, 0, 0]), np.array([0, d / 2, h]),
                     tuple(np.deg2rad(limits)))

    _open_box(b, o, oid, "front", outer, inner)
    y_front = -d / 2 - t / 2
    if o.kind == "drawer":
        b.box(f"{n}/front", oid, True, [0, y_front, h / 2], [w / 2, t / 2, h / 2], front)
        gap = 0.005
        wi, hi, di = w - 2 * t - 2 * gap, 0.7 * (h - 2 * t - 2 * gap), d - t - 2 * gap
        yc = -d / 2 + di / 2
        z0 = t + gap
        b.box(f"{n}/tray-bottom", oid, True, [0, yc, z0 + t / 2], [wi / 2, di / 2, t / 2], inner)
        b.box(f"{n}/tray-left", oid, True, [-wi / 2 + t / 2, yc, z0 + hi / 2], [t / 2, di / 2, hi / 2], inner)
        b.box(f"{n}/tray-right", oid, True, [wi / 2 - t / 2, yc, z0 + hi / 2], [t / 2, di / 2, hi / 2], inner)
        b.box(f"{n}/tray-back", oid, True, [0, -d / 2 + di - t / 2, z0 + hi / 2], [wi / 2 - t, t / 2, hi / 2],
              inner)
        b.box(f"{n}/handle", oid, True, [0, -d / 2 - t - hd / 2, 0.6 * h], [min(0.1, w / 4), hd / 2, 0.012],
              handle)
        return Joint("prismatic", np.array([0.0, -1.0, 0.0]), np.zeros(3), (limits[0], limits[1]))

    hinge = o.hinge or "left"
    b.box(f"{n}/door", oid, True, [0, y_front, h / 2], [w / 2, t / 2, h / 2], front)
    y_out = -d / 2 - t
    if hinge in ("left", "right"):
        sx = 1 if hinge == "left" else -1  # handle on the side away from the hinge
        b.box(f"{n}/handle", oid, True, [sx * (w / 2 - min(0.06, w / 6)), y_out - hd / 2, h / 2],
              [0.012, hd / 2, min(0.1, h / 5)], handle)
        pivot = np.array([-sx * w / 2, y_out, 0.0])
        axis = np.array([0.0, 0.0, -sx])
    else:
        sz = 1 if hinge == "bottom" else -1
        zc = h / 2 + sz * (h / 2 - min(0.06, h / 6))
        b.box(f"{n}/handle", oid, True, [0, y_out - hd / 2, zc], [min(0.1, w / 5), hd / 2, 0.012], handle)
        pivot = np.array([0.0, y_out, 0.0 if hinge == "bottom" else h])
        axis = np.array([float(sz), 0.0, 0.0])
    return Joint("revolute", axis, pivot, tuple(np.deg2rad(limits)))


def build_scene(spec: CaptureSpec) -> SceneModel:
    """Assemble every part of a spec (deterministic for its seed)."""
    b = _Builder(spec)
    room_box = _room(b)
    for f in spec.furniture:
        w, d, h = f.size
        mat = b.material(f"furniture/{f.name}", "grain", f.color, WOOD)
        b.box(f"furniture/{f.name}", 0, False, [f.position[0], f.position[1], f.position[2] + h / 2],
              [w / 2, d / 2, h / 2], mat, yaw_deg=f.yaw_deg)
    joints, frames = [], []
    for k, o in enumerate(spec.objects, start=1):
        joints.append(_articulated(b, o, k))
        frames.append(pose(o.position, o.yaw_deg))
    return SceneModel(parts=b.parts, materials=b.materials, joints=joints, object_frames=frames, room_box=room_box)
