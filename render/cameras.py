"""The camera presets orthodontists photograph with, framed automatically from the model's bounds.

Five views, named as in clinical records:
  frontal              from in front of the lips (+z), teeth in occlusion, patient's right on the
                       image's left;
  right_buccal         from the patient's right (-x), incisors toward the image's right edge;
  left_buccal          from the patient's left (+x), incisors toward the image's left edge;
  maxillary_occlusal   from below, looking up at the upper arch only, incisors at the top;
  mandibular_occlusal  from above, looking down at the lower arch only, incisors at the bottom
                       (the two occlusal views open like a book, as on a records sheet).
A view is framed once from the rest-pose geometry plus a margin, and then kept fixed for the whole
run, so that an animation shows the teeth moving, not the camera.

Camera convention is OpenGL's (pyrender's): the camera looks along its local -z, +y is up in the
image, +x to the right. Poses are camera -> arch frame, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim.errors import OrthosimError
from orthosim.model.fdi import Arch

# name -> (viewing direction in the arch frame, image-up direction, arches shown)
PRESETS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float], frozenset[Arch]]] = {
    "frontal": ((0, 0, -1), (0, 1, 0), frozenset({Arch.UPPER, Arch.LOWER})),
    "right_buccal": ((1, 0, 0), (0, 1, 0), frozenset({Arch.UPPER, Arch.LOWER})),
    "left_buccal": ((-1, 0, 0), (0, 1, 0), frozenset({Arch.UPPER, Arch.LOWER})),
    "maxillary_occlusal": ((0, 1, 0), (0, 0, 1), frozenset({Arch.UPPER})),
    "mandibular_occlusal": ((0, -1, 0), (0, 0, -1), frozenset({Arch.LOWER})),
}
VIEW_NAMES: tuple[str, ...] = tuple(PRESETS)
ALIASES = {"maxillary": "maxillary_occlusal", "mandibular": "mandibular_occlusal", "upper_occlusal": "maxillary_occlusal",
           "lower_occlusal": "mandibular_occlusal", "right": "right_buccal", "left": "left_buccal", "front": "frontal"}

YFOV = np.radians(24.0)  # narrow, like a clinical macro lens: little perspective distortion
MARGIN = 1.10  # frame 10 % wider than the bounds so that moving teeth stay in the picture


class ViewError(OrthosimError):
    """An unknown camera preset was asked for."""


@dataclass(frozen=True)
class CameraView:
    name: str
    pose: np.ndarray  # (4, 4) camera -> arch frame, mm
    yfov: float  # radians
    aspect: float  # width / height
    znear: float  # mm
    zfar: float  # mm
    arches: frozenset[Arch]  # arches drawn in this view

    def project(self, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """(n, 3) arch-frame points -> (n, 2) pixel (column, row) with row 0 at the image top."""
        w, h = size
        p = np.asarray(points, float).reshape(-1, 3)
        R, t = self.pose[:3, :3], self.pose[:3, 3]
        cam = (p - t) @ R  # into the camera frame
        f = 1.0 / np.tan(self.yfov / 2)
        x_ndc = f / self.aspect * cam[:, 0] / -cam[:, 2]
        y_ndc = f * cam[:, 1] / -cam[:, 2]
        return np.stack([(x_ndc + 1) / 2 * w, (1 - y_ndc) / 2 * h], axis=1)


def check_view(name: str) -> str:
    """The preset's canonical name (accepting the short aliases), or a one-line ViewError."""
    name = ALIASES.get(name, name)
    if name not in PRESETS:
        raise ViewError("--view", name, "is not a camera preset", f"use one of {', '.join(VIEW_NAMES)}")
    return name


def frame_view(name: str, points: np.ndarray, size: tuple[int, int]) -> CameraView:
    """Place preset `name` so that `points` ((n, 3) arch frame, mm: the teeth it shows) fill the image.

    The distance is the smallest at which every point lies inside the field of view, horizontally
    and vertically, enlarged by MARGIN; near and far planes hug the points' depth range.
    """
    name = check_view(name)
    forward, up, arches = PRESETS[name]
    forward = np.asarray(forward, float)
    z = -forward  # camera looks along its -z
    y = np.asarray(up, float)
    x = np.cross(y, z)
    R = np.stack([x, y, z], axis=1)
    pts = np.asarray(points, float).reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    center = (lo + hi) / 2
    rel = (pts - center) @ R  # columns: image-x, image-y, toward-camera
    w, h = size
    aspect = w / h
    tan_y = np.tan(YFOV / 2)
    tan_x = tan_y * aspect
    need = np.maximum(np.abs(rel[:, 0]) * MARGIN / tan_x, np.abs(rel[:, 1]) * MARGIN / tan_y) + rel[:, 2]
    d = float(need.max())
    depth = d - rel[:, 2]
    znear = max(1.0, float(depth.min()) * 0.5)
    zfar = float(depth.max()) * 1.5 + 10.0
    pose = np.eye(4)
    pose[:3, :3] = R
    pose[:3, 3] = center + z * d
    return CameraView(name, pose, float(YFOV), aspect, znear, zfar, arches)
