"""Semantic goldens: what each pixel of a render shows (which tooth, which contact, nothing) and how far away it is.

A render is drawn a second time in a cheap label pass (flat colours, no lighting; see
`Renderer.render_labels` and shaders/label.*): every pixel gets the id of what it shows, and the
depth buffer of that pass gives its distance from the camera. The ids are explained by a legend:
a tooth by its FDI number, a contact marker by the two teeth whose contact it marks, plus the kinds
`gingiva` (reserved: orthosim draws no gingiva yet) and `marker` (a contact sphere of no listed
pair). With the camera (field of view, size) a shift in pixels becomes millimetres in the view
plane, and with each tooth's dental axes projected into the image (mesial, occlusal, facial) a
shift gets its dental direction. `orthosim_render.explain` compares two such frames.

Beside GOLDEN.png they are stored losslessly as GOLDEN.labels.npz (`labels` (h, w) uint16,
`depth_mm` (h, w) float32, NaN where nothing is drawn) and GOLDEN.labels.json (format, legend,
camera, the SHA-256 of the npz file and of the pixels of the PNG they belong to). `read_labels`
checks all of it and refuses a damaged or mismatched pair in one line (ImageInputError), so a
label file is used whole or not at all.
"""

from __future__ import annotations

import hashlib
import io
import json
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim.model.fdi import is_fdi, quadrant, tooth_type
from orthosim.storage.atomic import write_bytes, write_json

from orthosim_render.imageerrors import ImageInputError

LABELS_FORMAT = "orthosim-labels/1"
BACKGROUND_ID = 0
GINGIVA_ID = 1  # reserved for a drawn gingiva
MARKER_ID = 2  # a contact sphere that no listed pair of teeth accounts for
FIRST_CONTACT_ID = 100  # contacts: 100, 101, ... in the order of the legend; teeth: their FDI number
KINDS = ("tooth", "contact", "marker", "gingiva")
FIX = "render the golden again (pytest --orthosim-force-regen, or orthosim imgdiff --update)"


@dataclass(frozen=True)
class LabelEntry:
    """One label id of a frame: what it shows and, for a tooth, its dental axes as the camera sees them.

    `mesial`, `occlusal`, `facial`: unit (3,) vectors in the camera frame of the image (x along the
    image's columns, y down its rows, z away from the camera), the directions in which the tooth
    would move mesially, occlusally (incisally) and facially (labially or buccally). For a contact,
    `center_mm`: the mean centre of the contact spheres drawn for it, in that camera frame (mm), and
    `spheres`: how many were drawn (hidden ones included: the patch is the contact, not what shows).
    """

    id: int
    kind: str  # one of KINDS
    teeth: tuple[int, ...] = ()  # (fdi,) for a tooth, (a, b) with a < b for a contact, () otherwise
    mesial: tuple[float, float, float] | None = None
    occlusal: tuple[float, float, float] | None = None
    facial: tuple[float, float, float] | None = None
    center_mm: tuple[float, float, float] | None = None
    spheres: int | None = None

    @property
    def key(self) -> tuple:
        """What the entry shows, independent of its id: ("tooth", 13), ("contact", 13, 14), ("gingiva",)."""
        return (self.kind, *self.teeth)

    @property
    def name(self) -> str:
        if self.kind == "tooth":
            return f"tooth {self.teeth[0]}"
        if self.kind == "contact":
            return f"contact {self.teeth[0]}-{self.teeth[1]}"
        return self.kind

    def to_json(self) -> dict:
        data = {"id": self.id, "kind": self.kind, "teeth": list(self.teeth)}
        for axis in ("mesial", "occlusal", "facial", "center_mm"):
            value = getattr(self, axis)
            if value is not None:
                data[axis] = [round(float(v), 6) for v in value]
        if self.spheres is not None:
            data["spheres"] = self.spheres
        return data

    @classmethod
    def from_json(cls, data, where) -> "LabelEntry":
        def bad(field, problem):
            return ImageInputError(where, f"legend {field}", problem, FIX)

        if not isinstance(data, dict) or not isinstance(data.get("id"), int) or not 0 <= data["id"] < 65536:
            raise bad("id", f"entry {data!r} has no label id from 0 to 65535")
        kind, teeth = data.get("kind"), data.get("teeth")
        if kind not in KINDS:
            raise bad("kind", f"{kind!r} is not one of {', '.join(KINDS)}")
        want = {"tooth": 1, "contact": 2}.get(kind, 0)
        if not isinstance(teeth, list) or len(teeth) != want or not all(is_fdi(t) for t in teeth):
            raise bad("teeth", f"of label {data['id']} ({kind}) is {teeth!r}, not {want} FDI number(s)")
        axes = {}
        spheres = data.get("spheres")
        if spheres is not None and (not isinstance(spheres, int) or spheres < 0):
            raise bad("spheres", f"of label {data['id']} is {spheres!r}, not a count")
        for axis in ("mesial", "occlusal", "facial", "center_mm"):
            value = data.get(axis)
            if value is not None and not (isinstance(value, list) and len(value) == 3
                                          and all(isinstance(v, (int, float)) for v in value)):
                raise bad(axis, f"of label {data['id']} is {value!r}, not [x, y, z] in the camera frame")
            axes[axis] = tuple(float(v) for v in value) if value is not None else None
        return cls(data["id"], kind, tuple(teeth), spheres=spheres, **axes)


@dataclass(frozen=True)
class LabelCamera:
    """The camera of a label frame: preset name, image size (w, h) px, vertical field of view (radians)."""

    view: str
    size: tuple[int, int]
    yfov: float

    def mm_per_px(self, depth_mm) -> np.ndarray:
        """Size in mm, in the view plane, of one pixel at distance `depth_mm` (mm along the view axis)."""
        return 2.0 * np.asarray(depth_mm, float) * np.tan(self.yfov / 2) / self.size[1]

    def pixel_of(self, point_mm) -> np.ndarray:
        """(2,) (column, row) pixel index of a (3,) camera-frame point (mm: x right, y down, z away)."""
        p = np.asarray(point_mm, float)
        centre = np.array([self.size[0] / 2 - 0.5, self.size[1] / 2 - 0.5])
        return centre + p[:2] / (self.mm_per_px(1.0) * p[2])

    def displacement_mm(self, pixel: tuple[float, float], depth_mm: float, shift_px, shift_depth_mm: float) -> np.ndarray:
        """(3,) mm in the camera frame (x right, y down, z away): the move of the surface point seen at
        `pixel` (column, row) and `depth_mm` whose image moved by `shift_px` (column, row) and whose depth
        changed by `shift_depth_mm`. Perspective included: a move toward the camera also moves the image."""
        k = self.mm_per_px(1.0)  # mm per pixel per mm of depth
        centre = np.array([self.size[0] / 2 - 0.5, self.size[1] / 2 - 0.5])  # image centre, pixel index units
        offset = np.asarray(pixel, float) - centre
        z1 = depth_mm + shift_depth_mm
        lateral = k * ((offset + np.asarray(shift_px, float)) * z1 - offset * depth_mm)
        return np.array([lateral[0], lateral[1], shift_depth_mm])


@dataclass(frozen=True, eq=False)
class LabelFrame:
    """What each pixel of one image shows: `labels` (h, w) uint16 ids, `depth_mm` (h, w) float32 (mm from
    the camera along its axis, NaN where nothing is drawn), the `legend` of the ids and the `camera`."""

    labels: np.ndarray
    depth_mm: np.ndarray
    legend: tuple[LabelEntry, ...]
    camera: LabelCamera

    def by_key(self) -> dict[tuple, LabelEntry]:
        return {e.key: e for e in self.legend}

    def mask(self, key: tuple) -> np.ndarray:
        """(h, w) bool: the pixels showing `key` (e.g. ("tooth", 13)); all False when it is not in the image."""
        entry = self.by_key().get(key)
        return self.labels == entry.id if entry is not None else np.zeros(self.labels.shape, bool)


# ------------------------------------------------------------------------------------- the label pass
_vertex_trees: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()  # Tooth -> cKDTree of its vertices (local, mm)
NEAR_MM = 3.0  # a contact sphere farther than this from a tooth's surface is not that tooth's contact


def _local(scene, fdi: int, points: np.ndarray) -> np.ndarray:
    pose = np.asarray(scene.teeth[fdi].node._matrix, float)
    return (points - pose[:3, 3]) @ pose[:3, :3]


def _within_reach(scene, fdi: int, points: np.ndarray) -> np.ndarray:
    """(n,) bool: the arch-frame points inside tooth `fdi`'s bounding sphere grown by NEAR_MM."""
    drawable = scene.teeth[fdi]
    return np.linalg.norm(_local(scene, fdi, points) - drawable.center_local, axis=1) <= drawable.radius_local + NEAR_MM


def _nearest_distance(scene, fdi: int, points: np.ndarray, which: np.ndarray) -> np.ndarray:
    """(n,) mm: from each arch-frame point picked by `which` to the nearest vertex of tooth `fdi` as
    posed in the scene; inf for the others and beyond NEAR_MM (the query stops there)."""
    from scipy.spatial import cKDTree

    tooth = scene.dentition.teeth[fdi]
    tree = _vertex_trees.get(tooth)
    if tree is None:
        tree = _vertex_trees[tooth] = cKDTree(tooth.mesh.vertices)
    distance = np.full(len(points), np.inf)
    if which.any():
        distance[which] = tree.query(_local(scene, fdi, points[which]), distance_upper_bound=NEAR_MM)[0]
    return distance


def _set_marker_ids(scene) -> list[tuple[tuple[int, int], np.ndarray, int]]:
    """Give each contact sprite the scene draws its label id (texture coordinate y, which the colour
    shader does not read); for each pair of teeth, numbered from FIRST_CONTACT_ID: (the pair, the mean
    centre of its spheres in the labels' camera frame (mm), how many)."""
    if not scene.marker_mesh.is_visible or scene.marker_style != "sprite":
        return []  # instanced sphere markers are one node: labelled MARKER_ID as a whole
    centers = np.asarray(scene.markers._positions, np.float32)
    ids, pairs = _marker_ids(scene, centers)
    tex = np.array(scene.markers._texcoord_0, np.float32)
    if not np.array_equal(tex[:, 1], ids):
        tex[:, 1] = ids
        scene.markers._texcoord_0 = tex
        scene.buffer_versions[scene.markers] = scene.buffer_versions.get(scene.markers, 0) + 1
    pose = scene.current_view.pose
    camera = (centers.astype(float) - pose[:3, 3]) @ pose[:3, :3] * np.array([1.0, -1.0, -1.0])
    out = []
    for k, pair in enumerate(pairs):
        mine = ids == FIRST_CONTACT_ID + k
        out.append((pair, camera[mine].mean(axis=0) if mine.any() else np.zeros(3), int(mine.sum())))
    return out


def _marker_ids(scene, centers: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The label id of each contact sphere: the listed pair of teeth nearest to it (sum of distances)."""
    state = scene.state
    pairs = sorted({tuple(sorted(p)) for p in (state.contact_pairs if state is not None else ())
                    if all(t in scene.teeth for t in p)})
    if not len(centers) or not pairs:
        return np.full(len(centers), MARKER_ID, np.float32), []
    points = centers.astype(float)
    teeth = {t for p in pairs for t in p}
    reach = {t: _within_reach(scene, t, points) for t in teeth}
    need = {t: np.zeros(len(points), bool) for t in teeth}
    for a, b in pairs:  # a tooth's tree is asked only about spheres that both teeth of a pair reach
        both = reach[a] & reach[b]
        need[a] |= both
        need[b] |= both
    distance = {t: _nearest_distance(scene, t, points, need[t]) for t in teeth}
    cost = np.stack([np.where(reach[a] & reach[b], distance[a] + distance[b], np.inf) for a, b in pairs], axis=1)
    ids = (FIRST_CONTACT_ID + cost.argmin(axis=1)).astype(np.float32)
    ids[~np.isfinite(cost.min(axis=1))] = MARKER_ID  # near no listed pair
    return ids, pairs


def _tooth_axes(scene, fdis: list[int]) -> dict[int, dict]:
    """Each dental axis of each tooth in `fdis` in the camera frame (see LabelEntry)."""
    # camera pose columns: image right, image up, toward the viewer; the labels' frame: right, down, away
    to_camera = scene.current_view.pose[:3, :3].T * np.array([1.0, -1.0, -1.0])[:, None]
    axes = {}
    for fdi in fdis:
        tooth = scene.dentition.teeth[fdi]
        rotation = np.asarray(scene.teeth[fdi].node._matrix, float)[:3, :3]
        local = np.stack([tooth.mesial, tooth.long_axis, tooth.labial])
        vectors = local @ rotation.T @ to_camera.T
        axes[fdi] = {name: tuple(round(float(x), 6) for x in v) for name, v in zip(("mesial", "occlusal", "facial"), vectors)}
    return axes


def render_labelled(renderer, scene, view: str | None = None) -> tuple[np.ndarray, LabelFrame]:
    """(the image `renderer.render(scene, view)` draws, its `LabelFrame`), drawn in one pass.

    `renderer`: an `orthosim_render.renderer.Renderer` (lean, no multisampling); `view`: a camera
    preset (default: the scene's current one). Reads the scene's state, never changes it.
    """
    if view is not None:
        scene.set_view(view)
    pairs = _set_marker_ids(scene)
    node_labels = {d.node: fdi for fdi, d in scene.teeth.items()}
    node_labels[scene.marker_node] = MARKER_ID
    image, labels, window = renderer.render_labelled(scene, node_labels)
    v = scene.current_view
    camera = LabelCamera(v.name, (int(labels.shape[1]), int(labels.shape[0])), float(v.yfov))
    ndc = 2.0 * window.astype(np.float64) - 1.0
    depth = 2.0 * v.znear * v.zfar / (v.zfar + v.znear - ndc * (v.zfar - v.znear))
    depth_mm = np.where(window < 1.0, depth, np.nan).astype(np.float32)
    present = [int(i) for i in np.flatnonzero(np.bincount(labels.ravel())) if i != BACKGROUND_ID]
    axes = _tooth_axes(scene, [label for label in present if label in scene.teeth])
    legend = []
    for label in present:
        if label == MARKER_ID:
            legend.append(LabelEntry(label, "marker"))
        elif label >= FIRST_CONTACT_ID:
            pair, center, count = pairs[label - FIRST_CONTACT_ID]
            legend.append(LabelEntry(label, "contact", pair, center_mm=tuple(round(float(v), 6) for v in center),
                                     spheres=count))
        else:
            legend.append(LabelEntry(label, "tooth", (label,), **axes[label]))
    return image, LabelFrame(labels, depth_mm, tuple(legend), camera)


# ------------------------------------------------------------------------------------------ storage
def labels_paths(png: str | Path) -> tuple[Path, Path]:
    """GOLDEN.png -> (GOLDEN.labels.npz, GOLDEN.labels.json)."""
    png = Path(png)
    return png.with_suffix(".labels.npz"), png.with_suffix(".labels.json")


def pixels_sha256(image: np.ndarray) -> str:
    """SHA-256 of an image's pixels and shape (not of its PNG bytes, which change with the encoder)."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    return hashlib.sha256(repr(image.shape).encode() + image.tobytes()).hexdigest()


def write_labels(png: str | Path, frame: LabelFrame, image: np.ndarray) -> tuple[Path, Path]:
    """Store `frame` beside `png` as the labels of `image` (its pixels), each file atomically."""
    npz_path, json_path = labels_paths(png)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, labels=np.ascontiguousarray(frame.labels, np.uint16),
                        depth_mm=np.ascontiguousarray(frame.depth_mm, np.float32))
    data = buffer.getvalue()
    write_bytes(npz_path, data)
    write_json(json_path, {
        "format": LABELS_FORMAT,
        "image_sha256": pixels_sha256(image),
        "labels_sha256": hashlib.sha256(data).hexdigest(),
        "camera": {"view": frame.camera.view, "size": list(frame.camera.size), "yfov_rad": frame.camera.yfov},
        "legend": [e.to_json() for e in frame.legend],
    })
    return npz_path, json_path


def remove_labels(png: str | Path) -> None:
    """Delete the label files of `png` (a golden rewritten from an image without labels must not keep old ones)."""
    for path in labels_paths(png):
        path.unlink(missing_ok=True)


def _read_legend(json_path: Path) -> dict:
    try:
        meta = json.loads(json_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ImageInputError(json_path, None, f"is unreadable ({type(err).__name__})", FIX) from None
    if not isinstance(meta, dict) or meta.get("format") != LABELS_FORMAT:
        raise ImageInputError(json_path, "format", f"is not {LABELS_FORMAT!r}", FIX)
    for field in ("image_sha256", "labels_sha256"):
        if not isinstance(meta.get(field), str):
            raise ImageInputError(json_path, field, "is missing", FIX)
    cam = meta.get("camera")
    if not (isinstance(cam, dict) and isinstance(cam.get("view"), str) and isinstance(cam.get("yfov_rad"), (int, float))
            and 0 < cam["yfov_rad"] < np.pi and isinstance(cam.get("size"), list) and len(cam["size"]) == 2
            and all(isinstance(v, int) and v > 0 for v in cam["size"])):
        raise ImageInputError(json_path, "camera", f"is {cam!r}, not {{view, size [w, h], yfov_rad}}", FIX)
    if not isinstance(meta.get("legend"), list):
        raise ImageInputError(json_path, "legend", "is not a list of labels", FIX)
    return meta


def _read_arrays(npz_path: Path, meta: dict, json_path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        data = npz_path.read_bytes()
    except OSError as err:
        raise ImageInputError(npz_path, None, f"is unreadable ({err.strerror or err})", FIX) from None
    if hashlib.sha256(data).hexdigest() != meta["labels_sha256"]:
        raise ImageInputError(npz_path, None, f"does not match the checksum in {json_path.name} (damaged or replaced)",
                              FIX)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            labels, depth = npz["labels"], npz["depth_mm"]
    except (OSError, ValueError, KeyError, EOFError) as err:
        raise ImageInputError(npz_path, None, f"is not a label archive ({type(err).__name__})", FIX) from None
    if labels.dtype != np.uint16 or depth.dtype != np.float32 or labels.ndim != 2 or labels.shape != depth.shape:
        raise ImageInputError(npz_path, "labels", f"are {labels.dtype} {labels.shape} with depth {depth.dtype} "
                                                  f"{depth.shape}, not two (h, w) uint16 / float32 arrays", FIX)
    return labels, depth


def read_labels(png: str | Path, image: np.ndarray) -> LabelFrame | None:
    """The labels stored beside `png`, checked against `image` (the pixels of that PNG); None when it has none.

    ImageInputError (one line) when only one of the two files is there, either is damaged, or they
    belong to other pixels: a label file is never used in part.
    """
    npz_path, json_path = labels_paths(png)
    if not npz_path.exists() and not json_path.exists():
        return None
    for path, other in ((npz_path, json_path), (json_path, npz_path)):
        if not path.is_file():
            raise ImageInputError(path, None, f"is missing but {other.name} is there",
                                  f"restore it, or delete {other.name} to compare pixels only")
    meta = _read_legend(json_path)
    labels, depth = _read_arrays(npz_path, meta, json_path)
    if labels.shape != tuple(np.shape(image)[:2]) or meta["camera"]["size"] != [labels.shape[1], labels.shape[0]]:
        raise ImageInputError(npz_path, "labels", f"are {labels.shape[1]}x{labels.shape[0]} but the image is "
                                                  f"{np.shape(image)[1]}x{np.shape(image)[0]}", FIX)
    if pixels_sha256(image) != meta["image_sha256"]:
        raise ImageInputError(json_path, "image_sha256", f"belongs to other pixels than {Path(png).name}", FIX)
    legend = tuple(LabelEntry.from_json(e, json_path) for e in meta["legend"])
    ids = {e.id for e in legend}
    if len(ids) != len(legend):
        raise ImageInputError(json_path, "legend", "names one label id twice", FIX)
    unknown = set(np.unique(labels).tolist()) - ids - {BACKGROUND_ID}
    if unknown:
        raise ImageInputError(json_path, "legend", f"does not name label id {min(unknown)} of {npz_path.name}", FIX)
    cam = meta["camera"]
    return LabelFrame(labels, depth, legend, LabelCamera(cam["view"], tuple(cam["size"]), float(cam["yfov_rad"])))


def dental_terms(fdi: int) -> dict[str, tuple[str, str]]:
    """For each axis, the words for a move along it and against it: mesially/distally,
    occlusally (incisally)/apically, buccally (labially)/lingually (palatally)."""
    anterior = tooth_type(fdi).is_anterior
    upper = quadrant(fdi) in (1, 2)
    return {"mesial": ("mesially", "distally"),
            "occlusal": ("incisally" if anterior else "occlusally", "apically"),
            "facial": ("labially" if anterior else "buccally", "palatally" if upper else "lingually")}
