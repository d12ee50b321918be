"""The capture camera's lens: a pinhole of the spec's field of view with OpenCV radial-tangential distortion
(docs/captures.md, "Phone camera effects").

Rays leave each pixel in the direction ``stages.scene.camera.undistort_normalized`` finds for it; the truth camera in
truth/transforms.json carries the same coefficients, so every reader of the truth renders through the same lens.
Which coefficients an image can take is the scene module's rule (``distortion_fold``), the one every reader of a
transforms.json applies, so a capture never writes a camera its own pipeline would refuse.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from stages.scene import Camera

from .spec import VideoSpec


def lens_camera(video: VideoSpec) -> Camera:
    """The capture camera: ``fov_deg`` is the undistorted pinhole's horizontal field of view (a barrel lens, k1 < 0,
    then sees more than it at the edges); coefficients left at 0 are not written."""
    camera = Camera.from_fov(np.deg2rad(video.fov_deg), video.width, video.height)
    coefficients = {k: float(v) for k, v in dataclasses.asdict(video.distortion).items() if v != 0.0}
    return dataclasses.replace(camera, distortion=coefficients) if coefficients else camera
