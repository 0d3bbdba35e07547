"""A treatment as one animated glTF scene (`animation.glb`): every tooth a node, every step a keyframe.

What any glTF tool (Blender, three.js's editor, a web viewer) plays, and what `viewer.html` carries:
  - metres, y up, +z to the front (glTF 2.0, section 3.4: right-handed, +Y up, the asset's front
    facing +Z): the arch frame of `orthosim.model.dentition` is already that (+x the patient's left,
    y up, +z anterior, right-handed), so coordinates are only scaled by 0.001;
  - one node `tooth_<FDI>` per tooth whose translation and rotation are the tooth's pose (its mesh
    stays in the tooth's local frame, the model's own vertices and faces, crown and root as two
    primitives of one vertex buffer); under it two children, `still` and `moving`, showing the same
    geometry in the frames' colours and in the moving tint, one of them scaled to 0 at each step
    (glTF animates transforms, not colours); a tooth extracted is scaled to 0 from its day;
  - the scanned gum of a labelled scan as `gingiva_<arch>` (translucent, never moves);
  - one marker node `contact_<a>_<b>` per pair of teeth that touch at some step, at the mean centre
    of that pair's contact spheres, scaled in where the pair touches and out where it does not;
  - one animation, `treatment`: keyframe k at k * STEP_SECONDS, teeth LINEAR (a translation on a
    straight line and a rotation at constant angular velocity: the motion law the continuous
    detector checks and the frames interpolate, `orthosim.geometry.motion`), everything else STEP.
The scene's `extras.orthosim` tells `viewer.html` what glTF has no word for: each keyframe's step and
day, and the five camera presets of `orthosim_render.cameras` (each view's direction, its arches and
the convex hull of the rest-pose vertices it frames, so the page frames it exactly as the frames do,
at any window shape).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

import numpy as np

from orthosim.model.fdi import Arch, arch_of
from orthosim.model.tooth import CROWN

from orthosim_render.cameras import MARGIN, PRESETS, YFOV
from orthosim_render.gltf import ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, GltfBuilder, quaternion_xyzw, srgb_to_linear
from orthosim_render.scene import (CONTACT_COLOR, CROWN_COLOR, ESTIMATED_ROOT_COLOR, GINGIVA_ALPHA, GINGIVA_COLOR,
                                   MOVING_TINT, ROOT_COLOR)

MM = 0.001  # metres per millimetre
STEP_SECONDS = 0.25  # animation seconds per keyframe in other glTF players (the page has its own slider)
CONTACT_MARKER_RADIUS_MM = 1.0  # one marker per touching pair: a sphere this size at the contact centre (shows past the teeth)
SCENE_FORMAT = "orthosim-scene/1"
MAX_GLB_BYTES = 30_000_000  # a scene over this is simplified (issue 41: the page must stay interactive)
VIEW_TOLERANCE_MM = 0.3  # the most a tooth's surface may move when a scene is simplified to fit MAX_GLB_BYTES
NEAR_MM = 3.0  # a contact sphere farther than this from a tooth is not that tooth's contact


@dataclass(frozen=True)
class ContactMarker:
    """One touching pair of teeth at one keyframe: `pair` (a < b, FDI) and `center_mm` (3,), arch frame."""

    pair: tuple[int, int]
    center_mm: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class SceneKeyframe:
    """What the scene shows at one keyframe: a simulation step (or a staging's stage) and its day."""

    step: int
    day: float
    poses: Mapping[int, np.ndarray]  # FDI -> (4, 4) tooth local -> arch frame, mm
    hidden: frozenset[int] = frozenset()  # teeth not there (extracted)
    moving: frozenset[int] = frozenset()  # teeth drawn with the moving tint
    contacts: tuple[ContactMarker, ...] = ()


class ContactLocator:
    """Groups a step's contact spheres by the pair of teeth they belong to, for one marker per pair.

    A sphere belongs to the touching pair whose two teeth's nearest vertices are closest to it in
    sum (each within NEAR_MM); the marker sits at the mean centre of the pair's spheres. The teeth's
    vertex trees are built once, in their local frames."""

    def __init__(self, dentition):
        self.dentition = dentition
        self._trees: dict[int, object] = {}

    def _distance(self, fdi: int, pose: np.ndarray, points: np.ndarray) -> np.ndarray:
        from scipy.spatial import cKDTree

        if fdi not in self._trees:
            self._trees[fdi] = cKDTree(np.asarray(self.dentition.teeth[fdi].mesh.vertices))
        local = (points - pose[:3, 3]) @ pose[:3, :3]
        return self._trees[fdi].query(local, distance_upper_bound=NEAR_MM)[0]

    def markers(self, poses: Mapping[int, np.ndarray], pairs: Iterable, centers: np.ndarray) -> tuple[ContactMarker, ...]:
        """One marker per pair in `pairs` that has a sphere among `centers` ((n, 3) mm, arch frame)."""
        pairs = sorted({tuple(sorted(p)) for p in pairs if all(t in self.dentition.teeth for t in p)})
        centers = np.asarray(centers, float).reshape(-1, 3)
        if not pairs or not len(centers):
            return ()
        teeth = {t for p in pairs for t in p}
        distance = {t: self._distance(t, np.asarray(poses[t], float), centers) for t in teeth}
        cost = np.stack([distance[a] + distance[b] for a, b in pairs], axis=1)
        owner = cost.argmin(axis=1)
        found = np.isfinite(cost.min(axis=1))
        out = []
        for k, pair in enumerate(pairs):
            mine = found & (owner == k)
            if mine.any():
                out.append(ContactMarker(pair, tuple(float(v) for v in centers[mine].mean(axis=0))))
        return tuple(out)


def keyframe_of_record(record, extracted: frozenset[int], locator: ContactLocator) -> SceneKeyframe:
    """The keyframe of one `orthosim.movement.records.StepRecord` (extracted teeth hidden from day 0,
    as a case's extractions are)."""
    poses = {n: np.array(p, float) for n, p in record.poses.items()}
    return SceneKeyframe(int(record.step), float(record.time_days), poses, frozenset(extracted),
                         frozenset(record.moving), locator.markers(poses, record.touching, record.contact_centers))


# ------------------------------------------------------------------------------------------ the scene
class _Materials:
    """The frames' colours as glTF materials (linear factors of the sRGB colours the frames draw),
    each added on first use (an unused one is an object glTF tools report)."""

    COLOURS = {"crown": (CROWN_COLOR, {}), "root": (ROOT_COLOR, {}), "estimated root": (ESTIMATED_ROOT_COLOR, {}),
               "gingiva": (GINGIVA_COLOR, {"alpha": GINGIVA_ALPHA, "alphaMode": "BLEND", "doubleSided": True}),
               "contact": (CONTACT_COLOR, {"emissiveFactor": srgb_to_linear(np.multiply(CONTACT_COLOR, 0.35))})}

    def __init__(self, builder: GltfBuilder):
        self.builder = builder
        self.ids: dict[str, int] = {}

    def __getitem__(self, name: str) -> int:
        if name not in self.ids:
            base = name.removesuffix(" moving")
            rgb, extra = self.COLOURS[base]
            extra = dict(extra)
            rgb = np.multiply(rgb, MOVING_TINT) if name != base else rgb
            alpha = extra.pop("alpha", 1.0)
            self.ids[name] = self.builder.add("materials", {
                "name": name, **extra, "pbrMetallicRoughness": {"baseColorFactor": [*srgb_to_linear(rgb), alpha],
                                                               "metallicFactor": 0.0, "roughnessFactor": 0.5}})
        return self.ids[name]


def _indices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    return np.asarray(faces, np.uint16 if n_vertices < 65536 else np.uint32).reshape(-1)


def _tooth_meshes(builder: GltfBuilder, fdi: int, tooth, materials: _Materials, shape=None) -> tuple[int, int]:
    """(still mesh, moving mesh) of one tooth: crown and root primitives over one vertex buffer (metres).
    shape: (mesh, face_part) to show instead of the tooth model's own (a staging's stage models)."""
    mesh, face_part = shape if shape is not None else (tooth.mesh, tooth.face_part)
    positions = builder.accessor(np.asarray(mesh.vertices, np.float32) * np.float32(MM), ARRAY_BUFFER, bounds=True)
    normals = np.array(mesh.vertex_normals, np.float64)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    normals = builder.accessor(normals.astype(np.float32), ARRAY_BUFFER)
    parts = []
    root = "estimated root" if tooth.root_kind == "estimated" else "root"
    for part, material in ((CROWN, "crown"), (1 - CROWN, root)):
        faces = np.asarray(mesh.faces)[np.asarray(face_part) == part]
        if len(faces):
            parts.append((material, builder.accessor(_indices(faces, len(mesh.vertices)), ELEMENT_ARRAY_BUFFER)))

    def primitives(suffix):
        return [{"attributes": {"POSITION": positions, "NORMAL": normals}, "indices": idx, "mode": 4,
                 "material": materials[name + suffix], "extras": {"part": "crown" if name == "crown" else "root"}}
                for name, idx in parts]
    still = builder.add("meshes", {"name": f"tooth_{fdi}", "primitives": primitives("")})
    moving = builder.add("meshes", {"name": f"tooth_{fdi}_moving", "primitives": primitives(" moving")})
    return still, moving


def _gum_mesh(builder: GltfBuilder, name: str, gum, material: int) -> int:
    vertices = np.asarray(gum.vertices)
    normals = np.array(gum.vertex_normals, np.float64)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    attributes = {"POSITION": builder.accessor(vertices.astype(np.float32) * np.float32(MM), ARRAY_BUFFER, bounds=True),
                  "NORMAL": builder.accessor(normals.astype(np.float32), ARRAY_BUFFER)}
    indices = builder.accessor(_indices(gum.faces, len(vertices)), ELEMENT_ARRAY_BUFFER)
    return builder.add("meshes", {"name": f"gingiva_{name}", "primitives": [
        {"attributes": attributes, "indices": indices, "mode": 4, "material": material}]})


def _marker_mesh(builder: GltfBuilder, material: int) -> int:
    """A unit icosphere (radius 1: the marker nodes scale it to their radius in metres)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    attributes = {"POSITION": builder.accessor(np.asarray(sphere.vertices, np.float32), ARRAY_BUFFER, bounds=True),
                  "NORMAL": builder.accessor(np.asarray(sphere.vertex_normals, np.float32), ARRAY_BUFFER)}
    indices = builder.accessor(_indices(sphere.faces, len(sphere.vertices)), ELEMENT_ARRAY_BUFFER)
    return builder.add("meshes", {"name": "contact_marker", "primitives": [
        {"attributes": attributes, "indices": indices, "mode": 4, "material": material}]})


class _Animation:
    """The one animation: samplers over the shared keyframe times, channels to node paths."""

    def __init__(self, builder: GltfBuilder, n_keyframes: int):
        self.builder = builder
        times = (np.arange(n_keyframes) * STEP_SECONDS).astype(np.float32)
        self.times = builder.accessor(times, bounds=True)
        self.samplers: list[dict] = []
        self.channels: list[dict] = []

    def channel(self, node: int, path: str, values: np.ndarray, interpolation: str) -> None:
        output = self.builder.accessor(np.asarray(values, np.float32))
        self.samplers.append({"input": self.times, "output": output, "interpolation": interpolation})
        self.channels.append({"sampler": len(self.samplers) - 1, "target": {"node": node, "path": path}})

    def finish(self) -> None:
        if self.channels:
            self.builder.add("animations", {"name": "treatment", "samplers": self.samplers, "channels": self.channels})


def _shown(flags: np.ndarray) -> np.ndarray:
    """(k,) bool -> (k, 3) scales: 1 where shown, 0 where not."""
    return np.repeat(flags.astype(np.float32)[:, None], 3, axis=1)


def _add_tooth(builder, animation: _Animation, fdi: int, tooth, keyframes, materials, shape=None,
               changed: tuple[int, tuple] | None = None) -> int:
    """The tooth's node (pose keyframes; scaled out where hidden) and its still and moving children.
    changed: (keyframe k, shape): from keyframe k on the tooth shows `shape` instead (a staging's tooth
    after its interproximal reduction), as a second pair of children scaled in from k."""
    poses = np.stack([np.asarray(k.poses.get(fdi, tooth.rest_pose), float) for k in keyframes])
    translation = poses[:, :3, 3] * MM
    rotation = quaternion_xyzw(poses[:, :3, :3])
    present = np.array([fdi not in k.hidden for k in keyframes])
    moving = np.array([fdi in k.moving for k in keyframes]) & present
    after = np.arange(len(keyframes)) >= (changed[0] if changed else len(keyframes))
    children = []
    for span, form in ((~after, shape), (after, changed[1] if changed else None)):
        if not span.any():
            continue
        still_mesh, moving_mesh = _tooth_meshes(builder, fdi, tooth, materials, form)
        for role, mesh, shown in (("still", still_mesh, ~moving & span), ("moving", moving_mesh, moving & span)):
            node = builder.add("nodes", {"name": f"tooth_{fdi}_{role}", "mesh": mesh, "extras": {"role": role},
                                         **({} if shown[0] else {"scale": [0.0, 0.0, 0.0]})})
            children.append(node)
            if shown.any() and not shown.all():
                animation.channel(node, "scale", _shown(shown), "STEP")
    node = {"name": f"tooth_{fdi}", "children": children, "translation": [float(v) for v in translation[0]],
            "rotation": [float(v) for v in rotation[0]],
            "extras": {"fdi": fdi, "arch": "upper" if arch_of(fdi) is Arch.UPPER else "lower"}}
    if not present[0]:
        node["scale"] = [0.0, 0.0, 0.0]
    index = builder.add("nodes", node)
    animation.channel(index, "translation", translation, "LINEAR")
    animation.channel(index, "rotation", rotation, "LINEAR")
    if not present.all():
        animation.channel(index, "scale", _shown(present), "STEP")
    return index


def _add_contacts(builder, animation: _Animation, keyframes, materials: _Materials) -> list[int]:
    """One marker node per pair that touches at some keyframe: there and scaled in where it touches."""
    pairs = sorted({m.pair for k in keyframes for m in k.contacts})
    if not pairs:
        return []
    mesh = _marker_mesh(builder, materials["contact"])
    nodes = []
    for pair in pairs:
        where = [next((m.center_mm for m in k.contacts if m.pair == pair), None) for k in keyframes]
        first = next(c for c in where if c is not None)
        centres, last = [], first
        for c in where:  # where the pair does not touch, the marker waits (scaled out) where it last was
            last = c if c is not None else last
            centres.append(last)
        touching = np.array([c is not None for c in where])
        translation = np.asarray(centres, float) * MM
        radius = CONTACT_MARKER_RADIUS_MM * MM
        node = builder.add("nodes", {"name": f"contact_{pair[0]}_{pair[1]}", "mesh": mesh,
                                     "translation": [float(v) for v in translation[0]],
                                     "scale": [radius if touching[0] else 0.0] * 3,
                                     "extras": {"role": "contact", "teeth": list(pair)}})
        animation.channel(node, "translation", translation, "STEP")
        animation.channel(node, "scale", _shown(touching) * np.float32(radius), "STEP")
        nodes.append(node)
    return nodes


def view_frames(dentition) -> dict[str, dict]:
    """Each camera preset as the page needs it: viewing direction, image up, arches shown, and the
    convex hull (metres) of the rest-pose vertices it is framed on (`DentitionScene.view`: every
    tooth of the arches it shows, roots included), enough for `cameras.frame_view`'s fit at any aspect."""
    from scipy.spatial import ConvexHull

    out = {}
    for name, (forward, up, arches) in PRESETS.items():
        shown = [n for n in dentition.fdis if arch_of(n) in arches]
        if not shown:  # a one-arch scan has no occlusal view of the other arch
            continue
        points = np.concatenate([dentition.teeth[n].to_world(dentition.teeth[n].mesh.vertices) for n in shown])
        hull = points[ConvexHull(points).vertices] * MM
        out[name] = {"forward": list(forward), "up": list(up),
                     "arches": sorted("upper" if a is Arch.UPPER else "lower" for a in arches),
                     "hull": [round(float(v), 7) for v in hull.reshape(-1)]}
    return out


def _mesh_bytes(vertices: int, faces: int) -> int:
    """GLB bytes of one mesh as written: float32 positions and normals, 16- or 32-bit indices."""
    return 24 * vertices + faces * 3 * (2 if vertices < 65536 else 4)


def fitted_shapes(dentition, keyframes: Sequence[SceneKeyframe], shapes: Mapping[int, tuple],
                  max_bytes: int) -> dict[int, tuple]:
    """The tooth shapes to write: the models' own, unless the scene would pass `max_bytes`; then every
    tooth is simplified (`_simplified`) to the share of triangles that fits, its faces' crown/root
    parts taken again from the CEJ plane. The gum and the keyframes are not simplified; they are counted."""
    from orthosim.model.tooth import part_of_faces

    own = {n: shapes.get(n, (dentition.teeth[n].mesh, dentition.teeth[n].face_part)) for n in dentition.fdis}
    teeth = sum(_mesh_bytes(len(m.vertices), len(m.faces)) for m, _ in own.values())
    fixed = sum(_mesh_bytes(len(g.vertices), len(g.faces)) for g in dentition.gingiva.values())
    fixed += len(keyframes) * len(own) * 40 + 200_000  # keyframe samplers, the JSON, markers
    if teeth + fixed <= max_bytes:
        return own
    share = max(0.05, (max_bytes - fixed) / teeth)
    out = {}
    for n, (mesh, _) in own.items():
        smaller = _simplified(mesh, max(200, int(len(mesh.faces) * share)))
        out[n] = (smaller, part_of_faces(smaller))
    return out


def _simplified(mesh, max_triangles: int):
    """`mesh` (mm) with at most about `max_triangles` triangles: manifold3d's edge collapse (the surface
    kept within a tolerance, closed kept), the tolerance doubled from 0.01 mm until it fits, up to
    VIEW_TOLERANCE_MM (a picture's, not a simulation's: `meshload.simplify_to_budget` stops at 0.02 mm);
    a mesh manifold3d cannot take (not closed) is kept as it is."""
    import manifold3d
    import trimesh

    solid = manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32),
                                                tri_verts=np.asarray(mesh.faces, np.uint32)))
    if solid.status() != manifold3d.Error.NoError:
        return mesh
    tolerance = 0.01
    smaller = solid.simplify(tolerance)
    while smaller.num_tri() > max_triangles and tolerance < VIEW_TOLERANCE_MM:
        tolerance *= 2
        smaller = solid.simplify(tolerance)
    out = smaller.to_mesh()
    return trimesh.Trimesh(np.asarray(out.vert_properties)[:, :3], np.asarray(out.tri_verts), process=False)


def treatment_glb(dentition, keyframes: Sequence[SceneKeyframe], *, title: str, timeline: str = "day",
                  shapes: Mapping[int, tuple] | None = None, labels: Sequence[str] | None = None,
                  changed: Mapping[int, tuple[int, tuple]] | None = None, max_bytes: int = MAX_GLB_BYTES) -> bytes:
    """The animated scene of `keyframes` (at least one) as GLB bytes (see the module doc).
    timeline: what the page's slider counts, "day" (a run), "stage" (a staging) or "pose" (named
    poses, `labels`: one name per keyframe, a report's before and after).
    shapes: FDI -> (mesh, face_part) shown instead of the tooth model's (local frame, mm).
    changed: FDI -> (keyframe k, (mesh, face_part)): the tooth's shape from keyframe k on (a staging's
    interproximal reduction); not simplified.
    max_bytes: a scene that would be larger gets simplified teeth (`fitted_shapes`)."""
    shapes = fitted_shapes(dentition, keyframes, shapes or {}, max_bytes)
    if not keyframes:
        raise ValueError("a treatment scene needs at least one keyframe")
    builder = GltfBuilder()
    builder.doc["asset"]["extras"] = {"title": title}
    materials = _Materials(builder)
    animation = _Animation(builder, len(keyframes))
    roots = [_add_tooth(builder, animation, n, dentition.teeth[n], keyframes, materials, shapes[n],
                        (changed or {}).get(n)) for n in dentition.fdis]
    for name, gum in sorted(dentition.gingiva.items()):
        mesh = _gum_mesh(builder, name, gum, materials["gingiva"])
        roots.append(builder.add("nodes", {"name": f"gingiva_{name}", "mesh": mesh,
                                           "extras": {"role": "gingiva", "arch": name}}))
    roots += _add_contacts(builder, animation, keyframes, materials)
    animation.finish()
    builder.doc["scenes"][0]["nodes"] = roots
    builder.doc["scenes"][0]["extras"] = {"orthosim": {
        "format": SCENE_FORMAT, "title": title, "timeline": timeline, "step_seconds": STEP_SECONDS,
        "steps": [k.step for k in keyframes], "days": [round(k.day, 6) for k in keyframes],
        "views": view_frames(dentition), "yfov": float(YFOV), "margin": MARGIN,
        **({"labels": list(labels)} if labels is not None else {})}}
    return builder.glb()
