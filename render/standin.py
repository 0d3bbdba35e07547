"""A stand-in dentition of simple tooth-shaped solids of revolution, for renderer tests and benchmarks.

It has the shape of the real thing where the renderer cares: 28 (or 32) closed meshes of at least
2,000 triangles each, crown and root faces labelled, in the arch frame of `orthosim.model.dentition`
(upper crowns pointing down, lower crowns up, upper arch labial to the lower one, crowns meeting
near the occlusal plane y = 0). It is not anatomy: use `orthosim.model.parametric` for that. The
renderer uses it only when the parametric model cannot be built (see `default_dentition`).
"""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch, arch_of, position, side
from orthosim.geometry.pose import frame_pose
from orthosim.model.tooth import Tooth, part_of_faces

# Mesiodistal crown widths (mm) by position 1..8, rounded textbook values.
_WIDTH = {Arch.UPPER: (8.5, 6.5, 7.5, 7.0, 6.5, 10.0, 9.0, 8.5), Arch.LOWER: (5.5, 6.0, 7.0, 7.0, 7.0, 11.0, 10.5, 10.0)}
# Arch half-widths and depths (mm) of the ellipse the crown centres sit on.
_ARCH = {Arch.UPPER: (27.0, 42.0), Arch.LOWER: (24.5, 39.5)}
CROWN_HEIGHT = 9.0  # mm, CEJ to the tip along the long axis
ROOT_LENGTH = 13.0  # mm, CEJ to apex
OCCLUSAL_GAP = 0.3  # mm, each crown tip stops this far past the occlusal plane (slight overlap)


def _standin_tooth(fdi: int, segments: int = 48) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A closed surface of revolution about the long axis: tapering root, bulging crown, round tip.

    A ring of vertices sits exactly on the CEJ (local y = 0), so every face is wholly crown or
    wholly root. ~2,500 triangles at 48 segments.
    """
    w = _WIDTH[arch_of(fdi)][position(fdi) - 1]
    R = w / 2  # mm, crown half-width at its height of contour
    depth = 0.85 if position(fdi) > 3 else 0.7  # labio-lingual / mesio-distal: incisors are flatter
    ys = np.concatenate([np.linspace(-ROOT_LENGTH, 0.0, 12)[1:], np.linspace(0.0, CROWN_HEIGHT, 16)[1:-1]])
    r = np.where(ys < 0, 0.8 * R * np.sqrt(np.clip(1 - (ys / ROOT_LENGTH) ** 2, 0, 1)) ** 0.8,
                 np.where(ys < 3.0, R * (0.8 + 0.2 * ys / 3.0),
                          R * np.sqrt(np.clip(1 - ((ys - 3.0) / (CROWN_HEIGHT - 3.0)) ** 2, 0, 1)) ** 0.6))
    theta = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(theta), np.zeros_like(theta), -np.sin(theta) * depth], axis=1)
    verts = [[0.0, -ROOT_LENGTH, 0.0]]
    for y, radius in zip(ys, r):
        verts.extend(ring * radius + [0.0, y, 0.0])
    verts.append([0.0, CROWN_HEIGHT, 0.0])
    verts = np.asarray(verts)
    n_rings, faces = len(ys), []
    j = np.arange(segments)
    k = (j + 1) % segments
    faces += [np.stack([np.zeros(segments, int), 1 + k, 1 + j], axis=1)]
    for i in range(n_rings - 1):
        a, b = 1 + i * segments, 1 + (i + 1) * segments
        faces += [np.stack([a + j, a + k, b + k], axis=1), np.stack([a + j, b + k, b + j], axis=1)]
    top = len(verts) - 1
    a = 1 + (n_rings - 1) * segments
    faces += [np.stack([np.full(segments, top), a + j, a + k], axis=1)]
    m = trimesh.Trimesh(verts, np.concatenate(faces), process=True)
    if m.volume < 0:
        m.invert()
    return m, np.array([0.0, -ROOT_LENGTH, 0.0])


def _arch_positions(arch: Arch, n_per_side: int):
    """(FDI, centre (3,), outward normal (3,)) walking from the midline along a half ellipse."""
    a, b = _ARCH[arch]
    t = np.linspace(0, np.pi / 2 * 1.15, 2000)
    pts = np.stack([a * np.sin(t), np.zeros_like(t), b * np.cos(t) - b * 0.55], axis=1)
    arc = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    out = []
    s = 0.0
    for p in range(1, n_per_side + 1):
        w = _WIDTH[arch][p - 1]
        s_mid = s + w / 2
        s += w
        i = int(np.searchsorted(arc, s_mid))
        i = min(i, len(t) - 2)
        c = pts[i]
        tangent = pts[i + 1] - pts[i]
        tangent /= np.linalg.norm(tangent)
        normal = np.array([tangent[2], 0.0, -tangent[0]])  # outward for x >= 0
        out.append((p, c, normal))
    return out


def standin_dentition(third_molars: bool = False, segments: int = 48) -> Dentition:
    """28 stand-in teeth (32 with third molars), >= 2,000 triangles each at the default `segments`."""
    n_per_side = 8 if third_molars else 7
    teeth = {}
    for arch in (Arch.UPPER, Arch.LOWER):
        up = -1.0 if arch is Arch.UPPER else 1.0  # direction the crowns point
        for p, c, normal in _arch_positions(arch, n_per_side):
            for quadrant in ((1, 2) if arch is Arch.UPPER else (4, 3)):
                fdi = 10 * quadrant + p
                sx = side(fdi)
                centre = c * np.array([sx, 1.0, 1.0])
                n = normal * np.array([sx, 1.0, 1.0])
                y_axis = np.array([0.0, up, 0.0])
                # CEJ sits CROWN_HEIGHT (minus the overlap) away from the occlusal plane
                origin = centre + np.array([0.0, -up * (CROWN_HEIGHT - OCCLUSAL_GAP), 0.0])
                pose = frame_pose(origin, np.cross(y_axis, n), y_axis)
                mesh, apex = _standin_tooth(fdi, segments)
                parts = part_of_faces(mesh)
                crown_center = mesh.triangles_center[parts == 0].mean(axis=0)
                teeth[fdi] = Tooth(fdi=fdi, mesh=mesh, face_part=parts, crown_center=crown_center,
                                   apex=apex, rest_pose=pose, source="standin")
    return Dentition(teeth, description="renderer stand-in: solids of revolution on an elliptic arch")


def default_dentition() -> tuple[Dentition, str]:
    """The parametric normal-occlusion model when it can be built, else the stand-in; with its name."""
    try:
        from orthosim.model.parametric import parametric_dentition  # type: ignore[import-not-found]
    except ImportError:
        return standin_dentition(), "standin"
    return parametric_dentition(resolution="smooth", third_molars=False), "parametric-smooth"
