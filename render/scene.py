"""The drawable scene: built once from a `Dentition`, then updated per frame from a `FrameState`.

Built once: one pyrender node per tooth holding ONE primitive whose vertex colours carry the
crown (ivory) / root (pale bluish grey) split, so a tooth costs one draw call whatever its parts;
one primitive for all contact markers (one draw call for up to thousands: a point sprite per
sphere, or an instanced low-poly sphere); a camera with the fixed light rig attached to it, so every preset is lit
the same way relative to the viewer and images are reproducible.

Updated per frame (`update`): node poses, visibility of extracted teeth, the moving-tooth tint
(a per-tooth material colour factor, a uniform: nothing re-uploaded), the marker instances and,
optionally, the vertex colours of teeth inside contact spheres. GPU buffers are never touched
here: changed buffers get a new version number in `buffer_versions`, and the renderer, which owns
the GL context, uploads what changed before drawing.
"""

from __future__ import annotations

import itertools

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch, arch_of
from orthosim.model.tooth import CROWN, ROOT

from orthosim_render.cej import CejCut, cut_at_cej, vertex_blend
from orthosim_render.cameras import VIEW_NAMES, CameraView, check_view, frame_view
from orthosim_render.frame_state import FrameState
from orthosim_render.pyrender_setup import load_pyrender

# Colours, linear RGB in [0, 1]; chosen for clinicians: ivory enamel, roots clearly paler and
# cooler than crowns, moving teeth a distinct mint, contacts a saturated red-magenta that no
# lit tooth surface can produce.
CROWN_COLOR = (0.94, 0.90, 0.80)
ROOT_COLOR = (0.70, 0.75, 0.84)
ESTIMATED_ROOT_COLOR = (0.86, 0.74, 0.52)  # an estimated root (crown-only input): warm sand, never a scanned root's blue-grey
GINGIVA_COLOR = (0.86, 0.45, 0.50)  # scanned gum: pink
GINGIVA_ALPHA = 0.45  # translucent, so the roots stay visible through it
MOVING_TINT = (0.66, 1.00, 0.80)  # multiplies the tooth's colours
CONTACT_COLOR = (1.00, 0.04, 0.32)
BACKGROUND = (0.10, 0.11, 0.14)  # dark slate, like the black card of intra-oral photographs
AMBIENT = (0.22, 0.22, 0.24)
# Fixed light rig in the camera frame (x right, y up, camera looks along -z): a key light from
# the upper left, a weaker fill from the right and a low rim from below, each a direction the
# light travels along.
LIGHT_RIG = (
    ((0.45, -0.55, -0.70), (1.00, 0.98, 0.94), 0.62),
    ((-0.60, -0.10, -0.80), (0.90, 0.94, 1.00), 0.30),
    ((0.00, 0.80, -0.60), (1.00, 1.00, 1.00), 0.14),
)
ENAMEL_ROUGHNESS = 0.5  # weak specular highlight (see shaders/mesh.frag)
OCCLUSAL_MARGIN = 1.5  # mm: contacts this close to the occlusal plane show in both occlusal views
_scene_ids = itertools.count(1)


def _drawn_parts(hide_roots: bool) -> list:
    return [CROWN] if hide_roots else [CROWN, ROOT]


def used_vertices(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """(the vertices `faces` use, ascending; `faces` renumbered into that list): what
    `np.unique(faces, return_inverse=True)` gives, by marking and counting in O(n) rather than
    sorting (a third of a scene's set-up time with np.unique)."""
    mark = np.zeros(n_vertices, bool)
    mark[faces] = True
    slot = np.cumsum(mark) - 1
    return np.flatnonzero(mark), slot[faces]


def _split_by_part(mesh: trimesh.Trimesh, face_part: np.ndarray, hide_roots: bool, smooth_cej: bool = True,
                   root_color: tuple = ROOT_COLOR):
    """Vertices duplicated along the CEJ so crown and root faces get their own colour.

    smooth_cej: triangles straddling the CEJ plane are cut along it (`orthosim_render.cej`), so the line is
    smooth, not a staircase; `origin` says where each drawn face and vertex came from, so a
    picture that colours the model's faces or crown vertices still can.

    Normals are the full mesh's smooth vertex normals, so the shading runs on across the seam and
    only the colour changes there. Returns positions (n, 3) float32 mm, normals (n, 3) float32,
    colours (n, 4) float32, indices (m, 3) uint32, and origin: (model face of each drawn face (m,),
    ends (n, 2) and t (n,) of each drawn vertex, as in `CejCut`, and how many drawn vertices,
    first, are the crown's).
    """
    if smooth_cej:
        cut = cut_at_cej(mesh, face_part)
    else:
        same = np.arange(len(mesh.vertices))
        cut = CejCut(mesh.vertices, mesh.vertex_normals, np.asarray(mesh.faces), face_part,
                     np.arange(len(mesh.faces)), np.stack([same, same], axis=1), np.zeros(len(same)))
    parts = _drawn_parts(hide_roots)
    pos, nrm, col, idx, source_face, ends, t = [], [], [], [], [], [], []
    offset = n_crown = 0
    for part in parts:
        chosen = cut.part == part
        faces = cut.faces[chosen]
        if not len(faces):
            continue
        used, inverse = used_vertices(faces.reshape(-1), len(cut.vertices))
        pos.append(cut.vertices[used])
        nrm.append(cut.normals[used])
        colour = CROWN_COLOR if part == CROWN else root_color
        col.append(np.tile([*colour, 1.0], (len(used), 1)))
        idx.append(inverse.reshape(-1, 3) + offset)
        source_face.append(cut.source_face[chosen])
        ends.append(cut.ends[used])
        t.append(cut.t[used])
        offset += len(used)
        n_crown += len(used) if part == CROWN else 0
    return (np.concatenate(pos).astype(np.float32), np.concatenate(nrm).astype(np.float32),
            np.concatenate(col).astype(np.float32), np.concatenate(idx).astype(np.uint32),
            (np.concatenate(source_face), np.concatenate(ends), np.concatenate(t), n_crown))


class _ToothDrawable:
    """One tooth's node, primitive and the data needed to recolour it."""

    def __init__(self, pyrender, fdi: int, tooth, hide_roots: bool, keep_kdtree: bool, smooth_cej: bool = True):
        self.fdi = fdi
        self.arch = arch_of(fdi)
        root_color = ESTIMATED_ROOT_COLOR if tooth.root_kind == "estimated" else ROOT_COLOR
        pos, nrm, col, idx, origin = _split_by_part(tooth.mesh, tooth.face_part, hide_roots, smooth_cej, root_color)
        self.face_of_row, ends, t, n_crown = origin
        self.base_colors = col  # (n_vertices, 4) float32
        self.material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=ENAMEL_ROUGHNESS,
            doubleSided=hide_roots,  # an open crown shows its inside through the cut
        )
        self.primitive = pyrender.Primitive(positions=pos, normals=nrm, color_0=col.copy(), indices=idx,
                                            material=self.material)
        self.mesh = pyrender.Mesh([self.primitive], name=f"tooth {fdi}")
        self.node = pyrender.Node(name=f"tooth {fdi}", mesh=self.mesh, matrix=tooth.rest_pose)
        self.kdtree = cKDTree(pos.astype(np.float64)) if keep_kdtree else None  # local frame: built once
        self.indices = idx  # (m, 3) drawn vertices of each drawn face; face_of_row: its model face
        # the crown's drawn vertices (the first block) as blends of the model's crown vertices, in
        # the order of `Tooth.crown_vertices`, for pictures coloured per crown vertex
        crown, _ = used_vertices(tooth.mesh.faces[tooth.face_part == CROWN], len(tooth.mesh.vertices))
        self.crown_blend = vertex_blend(crown, ends[:n_crown], t[:n_crown], pos[:n_crown], tooth.mesh.vertices)
        self.hits: np.ndarray | None = None  # drawn vertices painted in the contact colour now
        # bounding sphere in the local frame, to skip teeth far from every contact
        self.center_local = pos.mean(axis=0).astype(np.float64)
        self.radius_local = float(np.linalg.norm(pos - self.center_local, axis=1).max())
        self.tinted = False
        self.painted = False  # vertex colours currently differ from base_colors


def _gingiva_node(pyrender, name: str, gum: trimesh.Trimesh):
    """The scanned gum of one arch (arch frame, mm), translucent pink, lit from both sides; never posed."""
    material = pyrender.MetallicRoughnessMaterial(baseColorFactor=[*GINGIVA_COLOR, GINGIVA_ALPHA], metallicFactor=0.0,
                                                  roughnessFactor=1.0, alphaMode="BLEND", doubleSided=True)
    colours = np.ones((len(gum.vertices), 4), np.float32)
    primitive = pyrender.Primitive(positions=np.asarray(gum.vertices, np.float32),
                                   normals=np.asarray(gum.vertex_normals, np.float32), color_0=colours,
                                   indices=np.asarray(gum.faces, np.uint32), material=material)
    return pyrender.Node(name=f"gingiva {name}", mesh=pyrender.Mesh([primitive], name=f"gingiva {name}"))


def _unit_sphere(subdivisions: int):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return (s.vertices.astype(np.float32), s.vertex_normals.astype(np.float32), s.faces.astype(np.uint32))


class DentitionScene:
    """A pyrender scene of one dentition, its contact markers, the camera and the light rig."""

    def __init__(self, dentition: Dentition, size: tuple[int, int] = (640, 480), *, hide_roots: bool = False,
                 contact_faces: bool = False, contact_faces_exact: bool = False, show_markers: bool = True,
                 marker_style: str = "sprite",
                 marker_subdivisions: int = 1, frame_points: np.ndarray | None = None, unique_markers: bool = True,
                 smooth_cej: bool = True):
        """`marker_style`: "sprite" draws each contact sphere as a ray-cast point sprite (cheap at
        thousands of markers); "mesh" as an instanced icosphere (80 triangles at the default
        `marker_subdivisions`). `show_markers=False` with `contact_faces=True` shows contacts
        as coloured tooth surface only. `frame_points` ((n, 3) arch frame, mm) replace the rest-pose
        vertices as what the camera presets are framed on. `unique_markers`: a contact sphere
        listed several times is drawn once (see `_update_markers`); False draws every listing."""
        pyrender = load_pyrender()
        self.uid = next(_scene_ids)  # names this scene in the renderer's caches
        self._frame_points = None if frame_points is None else np.asarray(frame_points, float).reshape(-1, 3)
        self.dentition = dentition
        self.size = (int(size[0]), int(size[1]))
        self.hide_roots = hide_roots
        self.contact_faces = contact_faces or contact_faces_exact
        self.contact_faces_exact = contact_faces_exact
        self.show_markers = show_markers
        self.unique_markers = unique_markers
        self.scene = pyrender.Scene(bg_color=[*BACKGROUND, 0.0], ambient_light=AMBIENT)
        # primitive -> version; the renderer re-uploads a primitive whose version it has not seen
        self.buffer_versions: dict[object, int] = {}

        self.teeth: dict[int, _ToothDrawable] = {}
        for fdi in dentition.fdis:
            d = _ToothDrawable(pyrender, fdi, dentition.teeth[fdi], hide_roots, self.contact_faces, smooth_cej)
            self.teeth[fdi] = d
            self.scene.add_node(d.node)
        if not hide_roots:  # the gum would hide the cervical crown that a crowns-only picture shows
            for name, gum in dentition.gingiva.items():
                self.scene.add_node(_gingiva_node(pyrender, name, gum))

        self.marker_style = marker_style
        self.marker_material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=[*CONTACT_COLOR, 1.0], metallicFactor=0.0, roughnessFactor=1.0,
            emissiveFactor=[0.35 * c for c in CONTACT_COLOR],  # stays saturated on the shadow side
        )
        if marker_style == "sprite":
            # one point per sphere, (radius, 0) in texcoord_0; see shaders/marker.vert
            self.markers = pyrender.Primitive(positions=np.zeros((1, 3), np.float32),
                                              texcoord_0=np.zeros((1, 2), np.float32),
                                              mode=pyrender.GLTF.POINTS, material=self.marker_material)
        elif marker_style == "mesh":
            pos, nrm, idx = _unit_sphere(marker_subdivisions)
            self.markers = pyrender.Primitive(positions=pos, normals=nrm, indices=idx, material=self.marker_material,
                                              poses=np.eye(4, dtype=np.float32)[None])
        else:
            raise ValueError(f"marker_style must be 'sprite' or 'mesh', not {marker_style!r}")
        self.marker_mesh = pyrender.Mesh([self.markers], name="contact markers")
        self.marker_mesh.is_visible = False
        self.marker_node = pyrender.Node(name="contact markers", mesh=self.marker_mesh)
        self.scene.add_node(self.marker_node)

        self.camera = pyrender.PerspectiveCamera(yfov=1.0, aspectRatio=self.size[0] / self.size[1])
        self.camera_node = pyrender.Node(name="camera", camera=self.camera)
        self.scene.add_node(self.camera_node)
        for i, (direction, colour, intensity) in enumerate(LIGHT_RIG):
            light = pyrender.DirectionalLight(color=colour, intensity=intensity)
            self.scene.add_node(pyrender.Node(name=f"light {i}", light=light, matrix=_look_along(direction)),
                                parent_node=self.camera_node)

        self._views: dict[str, CameraView] = {}
        self._view: CameraView | None = None
        self._marker_arches = None
        self._extracted: frozenset[int] = frozenset()
        self._exact_faces = None  # orthosim_render.contact_faces.ExactContactFaces, built on first use
        self.state: FrameState | None = None
        self.set_view("frontal")

    # ----------------------------------------------------------------------------------- views
    def view(self, name: str) -> CameraView:
        """The preset `name`, framed from the rest-pose vertices of the arches it shows (cached)."""
        name = check_view(name)
        if name not in self._views:
            from orthosim_render.cameras import PRESETS

            arches = PRESETS[name][2]
            if self._frame_points is not None:
                pts = [self._frame_points]
            else:
                pts = [self._drawn_vertices(f) for f in self.dentition.fdis if arch_of(f) in arches]
            self._views[name] = frame_view(name, np.concatenate(pts), self.size)
        return self._views[name]

    def _drawn_vertices(self, fdi: int) -> np.ndarray:
        """(n, 3) arch-frame rest-pose vertices of what is drawn of `fdi` (crown only with hide_roots)."""
        t = self.dentition.teeth[fdi]
        return t.to_world(t.crown_vertices if self.hide_roots else t.mesh.vertices)

    def set_view(self, name: str) -> CameraView:
        v = self.view(name)
        self._view = v
        self.camera.yfov = v.yfov
        self.camera.znear = v.znear
        self.camera.zfar = v.zfar
        self.camera.aspectRatio = v.aspect
        self.scene.set_pose(self.camera_node, v.pose)
        self._apply_visibility()
        if self.state is not None and self._marker_arches != self._arch_filter():
            self._update_markers(self.state.contact_centers, self.state.contact_radii)
        return v

    @property
    def current_view(self) -> CameraView:
        return self._view

    def _apply_visibility(self):
        arches = self._view.arches if self._view is not None else None
        for fdi, d in self.teeth.items():
            d.mesh.is_visible = fdi not in self._extracted and (arches is None or d.arch in arches)

    # ----------------------------------------------------------------------------------- state
    def update(self, state: FrameState) -> None:
        """Make the scene show `state`: poses, extracted and moving teeth, contacts."""
        self.state = state
        for fdi, d in self.teeth.items():
            pose = state.poses.get(fdi)
            if pose is not None:
                # Node.matrix would decompose every pose into a quaternion and recompose it
                # (tens of microseconds per tooth per frame); our poses are already valid rigid 4x4s.
                d.node._matrix = np.asarray(pose, dtype=np.float64)
            tint = fdi in state.moving
            if tint != d.tinted:
                d.material.baseColorFactor = [*MOVING_TINT, 1.0] if tint else [1.0, 1.0, 1.0, 1.0]
                d.tinted = tint
        if state.extracted != self._extracted:
            self._extracted = state.extracted
            self._apply_visibility()
        self._update_markers(state.contact_centers, state.contact_radii)
        if self.contact_faces:
            self._paint_contact_faces(state)

    def _arch_filter(self):
        return None if self._view is None or len(self._view.arches) != 1 else next(iter(self._view.arches))

    def _update_markers(self, centers: np.ndarray, radii: np.ndarray) -> None:
        # An occlusal view shows one arch, seen through where the other arch would be: contacts
        # between teeth of the hidden arch would float over the shown one. Keep the markers on
        # the shown arch's side of the occlusal plane (y = 0), with a margin for the contacts
        # between the arches, which lie on that plane and matter in both views.
        arch = self._arch_filter()
        self._marker_arches = arch
        if arch is not None and len(radii):
            y = centers[:, 1]
            keep = y > -OCCLUSAL_MARGIN if arch is Arch.UPPER else y < OCCLUSAL_MARGIN
            centers, radii = centers[keep], radii[keep]
        n = len(radii) if self.show_markers else 0
        self.marker_mesh.is_visible = n > 0
        if n == 0:
            return
        # (centre, radius) as drawn: float32
        spheres = np.empty((n, 4), np.float32)
        spheres[:, :3] = centers
        spheres[:, 3] = radii
        if self.unique_markers and n > 1:
            # A simulation step lists a leaf sphere once per leaf of the other tooth it overlaps:
            # three quarters of its markers repeat one already listed, and large overlapping
            # sprites are what llvmpipe spends a frame's time on. A repeat is drawn after its
            # first listing at exactly the same depth, which the depth test (GL_LESS, opaque, no
            # blending) rejects at every pixel, so dropping the repeats, first listings kept in
            # order, leaves every pixel as it was.
            _, first = np.unique(spheres.view(np.dtype((np.void, 16))).ravel(), return_index=True)
            if len(first) < n:
                spheres = spheres[np.sort(first)]
                n = len(spheres)
        centers, radii = spheres[:, :3], spheres[:, 3]
        if self.marker_style == "sprite":
            # set the arrays directly: the setters would copy and re-derive buffer flags
            self.markers._positions = np.ascontiguousarray(centers)
            tex = np.zeros((n, 2), np.float32)
            tex[:, 0] = radii
            self.markers._texcoord_0 = tex
        else:
            poses = np.zeros((n, 4, 4), np.float32)
            poses[:, 0, 0] = poses[:, 1, 1] = poses[:, 2, 2] = radii
            poses[:, :3, 3] = centers
            poses[:, 3, 3] = 1.0
            self.markers._poses = poses  # already (n, 4, 4) float32 contiguous
        self.markers._bounds = None
        self.buffer_versions[self.markers] = self.buffer_versions.get(self.markers, 0) + 1

    def _pose(self, state: FrameState, fdi: int) -> np.ndarray:
        return np.asarray(state.poses.get(fdi, self.dentition.teeth[fdi].rest_pose), float)

    def _exact_hits(self, state: FrameState, fdi: int, d: _ToothDrawable) -> np.ndarray | None:
        """Drawn vertices of the triangles of tooth `fdi` that touch a tooth it is in contact with."""
        partners = [b if a == fdi else a for a, b in state.contact_pairs if fdi in (a, b)]
        partners = [p for p in partners if p in self.teeth and p not in state.extracted]
        if not partners:
            return None
        if self._exact_faces is None:
            from orthosim_render.contact_faces import ExactContactFaces

            self._exact_faces = ExactContactFaces(self.dentition)
        faces = self._exact_faces.faces(fdi, self._pose(state, fdi), [(p, self._pose(state, p)) for p in partners],
                                        state.contact_centers, state.contact_radii)
        if not len(faces):
            return None
        named = np.zeros(len(self.dentition.teeth[fdi].mesh.faces), bool)
        named[faces] = True
        rows = np.flatnonzero(named[d.face_of_row])  # a cut face is drawn as up to three
        return np.unique(d.indices[rows]) if len(rows) else None

    def _paint_contact_faces(self, state: FrameState) -> None:
        """Colour the vertices of each tooth that lie inside a contact sphere (the paper's Figure 7),
        or with `contact_faces_exact` the triangles that touch the other tooth."""
        centers, radii = state.contact_centers, state.contact_radii
        involved = {f for pair in state.contact_pairs for f in pair}
        for fdi, d in self.teeth.items():
            hits = None
            if self.contact_faces_exact:
                if len(radii) and fdi in involved and fdi not in state.extracted:
                    hits = self._exact_hits(state, fdi, d)
            elif len(radii) and (not state.contact_pairs or fdi in involved) and fdi not in state.extracted:
                pose = self._pose(state, fdi)
                local = (centers - pose[:3, 3]) @ pose[:3, :3]
                near = np.linalg.norm(local - d.center_local, axis=1) <= radii + d.radius_local
                if near.any():
                    lists = d.kdtree.query_ball_point(local[near], radii[near])
                    found = [i for lst in lists for i in lst]
                    if found:
                        hits = np.unique(np.asarray(found, dtype=np.int64))
            if hits is None and not d.painted:
                continue
            if hits is not None and d.painted and np.array_equal(hits, d.hits):
                continue  # painted as it should be: nothing to upload
            d.hits = hits
            colors = d.base_colors.copy()
            if hits is not None:
                colors[hits, :3] = CONTACT_COLOR
            d.primitive.color_0 = colors
            d.painted = hits is not None
            self.buffer_versions[d.primitive] = self.buffer_versions.get(d.primitive, 0) + 1


def paint_crowns(scene: DentitionScene, colors: dict[int, np.ndarray]) -> None:
    """Colour the crown vertices of the teeth in `colors` (FDI -> (k, 3) linear RGB in [0, 1], one
    row per vertex of `Tooth.crown_vertices`, in that order); other teeth get their base colours.

    For pictures that colour the surface by a per-vertex figure (the distance map, contact areas).
    The crown part is the first block of a tooth's drawn vertices (see `_split_by_part`); where the
    CEJ cut added vertices, their colours blend those of the model vertices they lie between."""
    for fdi, d in scene.teeth.items():
        c = colors.get(fdi)
        if c is None and not d.painted:
            continue
        out = d.base_colors.copy()
        if c is not None:
            out[:len(d.crown_blend.a), :3] = d.crown_blend.apply(np.asarray(c, np.float32))
        d.primitive.color_0 = out
        d.painted = c is not None
        d.hits = None  # painted by a figure, not by contacts
        scene.buffer_versions[d.primitive] = scene.buffer_versions.get(d.primitive, 0) + 1


def _look_along(direction) -> np.ndarray:
    """Pose whose -z axis points along `direction` (pyrender lights shine along their -z)."""
    z = -np.asarray(direction, float)
    z /= np.linalg.norm(z)
    helper = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = x, y, z
    return T


__all__ = ["DentitionScene", "VIEW_NAMES", "CROWN_COLOR", "ROOT_COLOR", "ESTIMATED_ROOT_COLOR", "GINGIVA_COLOR", "MOVING_TINT", "CONTACT_COLOR", "BACKGROUND"]
