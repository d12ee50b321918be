"""Each impossible spec value is refused with the key, and the value at the edge of the range is accepted."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from stages.capture import CaptureSpecError, spec_from_dict

TINY = Path(__file__).resolve().parents[2] / "config" / "captures" / "tiny.yaml"


def _tiny() -> dict:
    return yaml.safe_load(TINY.read_text())


def _walk(data: dict, waypoints: list) -> None:
    data["camera"] = {"kind": "walk", "target": [0.0, 1.2, 0.6], "waypoints": waypoints}


REFUSED = [
    (lambda d: d["video"].update(n_frames=0), "video"),
    (lambda d: d["video"].update(fov_deg=170), "video"),
    (lambda d: d["video"].update(height=7), "video"),
    (lambda d: d["video"].update(fps=0), "video"),
    (lambda d: d["video"].update(exposure_jitter=1.5), "video.exposure_jitter"),
    (lambda d: d["video"].update(white_balance_jitter=-0.1), "video.exposure_jitter"),
    (lambda d: d.update(room=[4.0, 0.0, 2.5]), "room is [4.0, 0.0, 2.5], all values must be > 0"),
    (lambda d: d.update(units={"name": "mm", "per_metre": 0}), "units.per_metre must be > 0"),
    (lambda d: d["render"].update(lights=[]), "render.lights is empty"),
    (lambda d: d["render"].update(supersample=0), "render.supersample"),
    (lambda d: d["render"].update(texture_size=8), "render.supersample"),
    (lambda d: d.update(mask_scope="parts"), "mask_scope 'parts' unknown"),
    (lambda d: d["objects"][1].update(name="cabinet"), "object names ['cabinet'] appear more than once"),
    (lambda d: d["objects"][1].update(name="a/b"), "objects[1] (a/b): the name holds a path separator"),
    (lambda d: d["objects"][0].update(hinge="back"), "objects[0] (cabinet): hinge 'back' is not valid for a door"),
    (lambda d: d["objects"][1].update(hinge="left"), "objects[1] (drawer): hinge 'left' is not valid for a drawer"),
    (lambda d: d["objects"][1].update(thickness=0.15), "objects[1] (drawer): thickness 0.15"),  # half of 0.3
    (lambda d: d["objects"][1].update(thickness=0.0), "objects[1] (drawer): thickness 0.0"),
    (lambda d: d["objects"][0]["schedule"].update(interpolation="cubic"), "schedule.interpolation 'cubic'"),
    (lambda d: d["objects"][0]["schedule"].update(keys=[[0.0, 0.0], [1.0, 1.5]]), "schedule states must lie in"),
    (lambda d: d["objects"][0]["schedule"].update(keys=[[0.0, -0.1]]), "schedule states must lie in"),
    (lambda d: d["objects"][0]["schedule"].update(keys=[]), "schedule.keys must be a list of [time, state]"),
    (lambda d: d["objects"][0].update(size=[0.6, 0.5]), "objects[0] (cabinet).size is [0.6, 0.5], expected 3"),
    (lambda d: d["objects"][0].update(limits=[0.0]), "objects[0] (cabinet).limits is [0.0], expected 2"),
    (lambda d: d["camera"].update(kind="drone"), "camera.kind 'drone' unknown"),
    (lambda d: d["camera"].update(radius=0.0), "camera.radius must be > 0"),
    (lambda d: _walk(d, [[0.0, -1.0, 1.5]]), "camera.kind walk needs at least 2 waypoints"),
    (lambda d: _walk(d, [[0.0, -1.0, 1.5], [1.0, -1.0]]), "camera.waypoints[1] is [1.0, -1.0], expected 3"),
    (lambda d: d["key_frames"].update(every=0), "key_frames.every >= 1"),
    (lambda d: d["key_frames"].update(noise_std=-0.01), "key_frames.every >= 1 and noise_std >= 0"),
    (lambda d: d["render"]["lights"][0].update(position=[0.0, 0.0]), "render.lights[0].position"),
    (lambda d: d["furniture"][0].update(size=[0.8, 0.0, 0.7]), "furniture[0].size"),
    # tiny.yaml's drawer: depth 0.5
    (lambda d: d["objects"][1].update(limits=[0.0, 0.51]), "objects[1] (drawer).limits [0.0, 0.51] (m) do not open"),
    (lambda d: d["objects"][1].update(limits=[-0.1, 0.3]), "objects[1] (drawer).limits [-0.1, 0.3] (m)"),
    (lambda d: d["objects"][0].update(limits=[100, 0]), "objects[0] (cabinet).limits [100.0, 0.0] (degrees)"),
    (lambda d: d["objects"][0].update(limits=[0, 0]), "objects[0] (cabinet).limits [0.0, 0.0] (degrees)"),
    (lambda d: d["objects"][0].update(limits=[-90, 0]), "objects[0] (cabinet).limits [-90.0, 0.0] (degrees)"),
    (lambda d: d["objects"][0].update(limits=[0, 181]), "with 0 <= closed < open <= 180"),
    (lambda d: d["key_frames"].update(decimals=-1), "key_frames.decimals is -1"),
    # tiny.yaml's room is 4.0 x 3.6 x 2.5; a camera at 2.47 m is within 5 cm of the ceiling
    (lambda d: d["camera"].update(height=2.47), "is outside the room, or within 0.05 m of a wall"),
    (lambda d: d["camera"].update(radius=3.0), "is outside the room"),  # x = 3 sin(57 deg) = 2.5 > 2.0
    # the table spans x -1.5..-0.7, y 0.2..0.8, z 0..0.72; the cabinet x -0.75..-0.15, y 1.25..1.75, z 0..0.9
    (lambda d: _walk(d, [[-1.4, 0.5, 0.5], [-0.8, 0.5, 0.5]]), "is inside furniture[0] (table)"),
    (lambda d: _walk(d, [[-0.6, 1.4, 0.5], [-0.3, 1.4, 0.5]]), "is inside objects[0] (cabinet)"),
    (lambda d: d["camera"].update(height=0.03), "is outside the room, or within 0.05 m of a wall, the floor"),
    # the drawer (0.7 wide) at x = 0.1 spans -0.25..0.45, 0.1 m into the cabinet (-0.75..-0.15)
    (lambda d: d["objects"][1].update(position=[0.1, 1.5, 0.0]), "objects[0] (cabinet) and objects[1] (drawer) "
                                                                 "overlap by 0.1 m"),
    # the cabinet (0.6 x 0.5) at x = -0.5, y = 0.5 spans x -0.8..-0.2, y 0.25..0.75: 0.1 m into the table along x
    # (-1.5..-0.7), all 0.5 m of its depth along y (0.2..0.8), and 0.72 m along z
    (lambda d: d["objects"][0].update(position=[-0.5, 0.5, 0.0]), "objects[0] (cabinet) and furniture[0] (table) "
                                                                   "overlap by 0.1 m"),
    (lambda d: d["render"].update(ambient=-0.1), "render.ambient -0.1 is outside [0, 1]"),
    (lambda d: d["render"].update(ambient=1.5), "render.ambient 1.5 is outside [0, 1]"),
    (lambda d: d["render"]["lights"][0].update(intensity=-0.5), "render.lights[0].intensity -0.5 is negative"),
    (lambda d: d["video"].update(shutter=1.5), "video.shutter is 1.5, outside [0, 1]"),
    (lambda d: d["video"].update(shutter=-0.1), "video.shutter is -0.1, outside [0, 1]"),
    (lambda d: d["video"].update(rolling_shutter=1.2), "video.rolling_shutter is 1.2, outside [0, 1]"),
    (lambda d: d["video"].update(blur_samples=0), "video.blur_samples is 0, outside [1, 64]"),
    (lambda d: d["video"].update(blur_samples=65), "video.blur_samples is 65, outside [1, 64]"),
    (lambda d: d["video"].update(noise_read=-0.01), "video.noise_read is -0.01, outside [0, 0.2]"),
    (lambda d: d["video"].update(noise_read=float("nan")), "video.noise_read is nan"),
    (lambda d: d["video"].update(noise_shot=0.5), "video.noise_shot is 0.5, outside [0, 0.1]"),
    (lambda d: d["video"].update(distortion={"k3": 0.1}), "spec.video.distortion has unknown keys ['k3']"),
    # tiny.yaml's 70-degree view reaches a normalised radius of 0.87 in its corners: a barrel lens of k1 = -0.5
    # bends no ray that far (r (1 - 0.5 r^2) peaks at 0.54), and one of k2 = -0.6 neither (r (1 - 0.6 r^4): 0.61)
    (lambda d: d["video"].update(distortion={"k1": -0.5}), "video.distortion {'k1': -0.5, 'k2': 0.0, 'p1': 0.0, "
                                                           "'p2': 0.0}: pixel ("),
    (lambda d: d["video"].update(distortion={"k2": -0.6}), "is the image of no ray"),
    # nor one of k1 = -0.2, just (r (1 - 0.2 r^2) peaks at 0.861 < 0.865)
    (lambda d: d["video"].update(distortion={"k1": -0.2}), "is the image of no ray"),
    # a NaN coefficient makes Camera.has_distortion False (abs(nan) > 0 is False): the fold check passed it, the
    # frames were a pinhole's and truth/transforms.json carried k1 NaN, which every reader refuses
    (lambda d: d["video"].update(distortion={"k1": float("nan")}), "video.distortion.k1 is nan"),
    (lambda d: d["video"].update(distortion={"p2": float("-inf")}), "video.distortion.p2 is -inf"),
]


@pytest.mark.parametrize(("edit", "words"), REFUSED)
def test_an_impossible_value_is_refused_with_its_key(edit, words):
    data = _tiny()
    edit(data)
    with pytest.raises(CaptureSpecError) as info:
        spec_from_dict(data, TINY)
    message = str(info.value)
    assert message.startswith(f"{TINY}: ") and "; fix: " in message
    assert words in message, message


ACCEPTED = [
    lambda d: d["video"].update(n_frames=1, width=8, height=8),
    lambda d: d["video"].update(exposure_jitter=1.0, white_balance_jitter=0.0),
    lambda d: d["objects"][1].update(thickness=0.149),
    lambda d: d["objects"][0]["schedule"].update(keys=[[0.0, 0.0], [0.5, 0.0], [0.5, 1.0]], interpolation="step"),
    lambda d: _walk(d, [[0.0, -1.0, 1.5], [1.0, -1.0, 1.5]]),
    lambda d: d["key_frames"].update(every=1, noise_std=0.0),
    lambda d: d.update(mask_scope="moving"),
    lambda d: d["objects"][1].update(limits=[0.0, 0.5]),  # pulled out by its whole depth
    lambda d: _walk(d, [[-1.4, 0.5, 0.8], [-0.8, 0.5, 0.8]]),  # over the table (0.72 m high)
    lambda d: d["camera"].update(height=2.4),
    lambda d: d["objects"][1].update(position=[0.2, 1.5, 0.0]),  # flush against the cabinet's side
    # the shelf 0.1 m into the table: two pieces of furniture may overlap (an L-shaped counter), both are background
    lambda d: d["furniture"][1].update(position=[-0.6, 0.5, 0.0]),
    # on top of the cabinet (0.9 m high), their footprints overlapping: touching, one above the other
    lambda d: d["objects"][1].update(position=[-0.45, 1.5, 0.9]),
    # the cabinet (0.6 x 0.5) turned by 45 degrees: its corners reach (0.3 + 0.25) / sqrt(2) = 0.389 m from its
    # centre along x and y (its bounding square), and its side facing +x, +y lies on x + y = 0.3 sqrt(2) = 0.424 m
    # (offsets from its centre). 0.25 m left of and below the shelf's corner (1.4, 0.65) its bounding square reaches
    # 0.139 m into the shelf but its side passes the corner (0.25 + 0.25 = 0.5 > 0.424): its own axes part them
    lambda d: d["objects"][0].update(position=[1.15, 0.4, 0.0], yaw_deg=45),
    # 1 cm left of the shelf's side (its corner at x = 1.001 + 0.389 = 1.39): the shelf's axes part them
    lambda d: d["objects"][0].update(position=[1.001, 0.85, 0.0], yaw_deg=45),
    lambda d: d["objects"][0].update(limits=[10, 180]),
    lambda d: d["key_frames"].update(decimals=0),
    lambda d: d["render"].update(ambient=0.0),
    lambda d: d["render"].update(ambient=1.0),
    lambda d: d["render"]["lights"][0].update(intensity=0.0),
    lambda d: d["video"].update(shutter=1.0, blur_samples=64, rolling_shutter=1.0, noise_read=0.2, noise_shot=0.1),
    lambda d: d["video"].update(shutter=0.0, blur_samples=1),
    lambda d: d["video"].update(distortion={"k1": -0.2, "k2": 0.05, "p1": 0.002, "p2": -0.002}),  # a phone's
    lambda d: d["video"].update(distortion={"k1": 0.2}),  # pincushion
]


def _table_turned_by_30_degrees_and_a_still_camera(data: dict, x: float, y: float) -> None:
    data["furniture"][0].update(yaw_deg=30)
    _walk(data, [[x, y, 0.5], [x, y, 0.505]])
    data["camera"]["jitter"] = {"position": 0.0, "rotation_deg": 0.0}


# the table (0.8 x 0.6, centre -1.1, 0.5) turned by 30 degrees: a point 0.38 m along its turned width and +-0.28 m
# along its turned depth from its centre lies inside it, at x, y = -1.1 + 0.38 cos 30 -+ 0.28 sin 30,
# 0.5 + 0.38 sin 30 +- 0.28 cos 30; both points lie outside the unturned table (0.43 m along y, 0.47 m along x)
@pytest.mark.parametrize(("x", "y"), [(-0.911, 0.933), (-0.631, 0.448)])
def test_a_camera_inside_a_turned_box_is_refused(x, y):
    data = _tiny()
    _table_turned_by_30_degrees_and_a_still_camera(data, x, y)
    with pytest.raises(CaptureSpecError, match=r"is inside furniture\[0\] \(table\)"):
        spec_from_dict(data, TINY)


def test_a_camera_beside_a_turned_box_is_accepted():
    # 0.37 m along x and -0.27 m along y from the table's centre: inside the unturned table, but in the turned
    # table's axes 0.37 cos 30 - 0.27 sin 30 = 0.185 along its width and -0.37 sin 30 - 0.27 cos 30 = -0.419
    # along its depth, beyond its half depth of 0.3
    data = _tiny()
    _table_turned_by_30_degrees_and_a_still_camera(data, -0.73, 0.23)
    spec_from_dict(data, TINY)


@pytest.mark.parametrize("edit", ACCEPTED)
def test_a_value_at_the_edge_of_its_range_is_accepted(edit):
    data = _tiny()
    edit(data)
    spec_from_dict(data, TINY)


def test_254_objects_fit_the_uint8_masks_and_255_do_not():
    data = {"name": "many", "room": [30.0, 30.0, 2.5]}
    box = {"kind": "drawer", "size": [0.5, 0.5, 0.5]}
    data["objects"] = [
        {**box, "name": f"box {k}", "position": [-14.0 + k % 25, -14.0 + k // 25, 0.0]} for k in range(254)
    ]
    assert len(spec_from_dict(data).objects) == 254
    data["objects"].append({**box, "name": "one more", "position": [10.0, 12.0, 0.0]})
    with pytest.raises(CaptureSpecError, match="more than 254 objects"):
        spec_from_dict(data)


@pytest.mark.parametrize(
    ("camera", "problem"),
    [
        # a walk that starts on the point it looks at
        (
            {"kind": "walk", "target": [0.0, 1.2, 0.6], "waypoints": [[0.0, 1.2, 0.6], [0.5, 1.2, 0.6]]},
            "on camera.target",
        ),
        # a walk right above the target: look_at's right vector vanishes (NaN poses before this check)
        (
            {"kind": "walk", "target": [0.0, 1.2, 0.6], "waypoints": [[0.0, 1.2, 2.0], [0.0, 1.21, 2.0]]},
            "straight above",
        ),
        # an orbit of 1 cm radius 1.4 m above its target: 0.4 degree off vertical
        ({"kind": "orbit", "target": [0.0, 1.2, 0.6], "radius": 0.01, "height": 2.0}, "straight above"),
    ],
)
def test_a_camera_without_a_view_direction_is_refused_before_rendering(camera, problem):
    data = _tiny()
    data["camera"] = camera
    with pytest.raises(CaptureSpecError, match=problem) as err:
        spec_from_dict(data, "room.yaml")
    assert "room.yaml" in str(err.value) and "frame 0" in str(err.value)


def test_a_steep_camera_two_degrees_off_vertical_is_accepted():
    data = _tiny()
    # 5 cm off the target's vertical at 1.4 m above it: atan(0.05 / 1.4) = 2.0 degrees, shake off
    data["camera"] = {
        "kind": "orbit",
        "target": [0.0, 1.2, 0.6],
        "radius": 0.05,
        "height": 2.0,
        "jitter": {"position": 0.0, "rotation_deg": 0.0},
    }
    spec_from_dict(data, "room.yaml")
