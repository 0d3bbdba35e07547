"""A glTF 2.0 binary (GLB) writer: one buffer, accessors over numpy arrays, nodes, meshes, one animation.

glTF is a small JSON document plus one binary buffer; what orthosim writes (meshes with normals,
nodes with translation/rotation/scale, one animation of keyframes, materials of one colour each)
needs a few dozen lines of numpy and struct, so it is written here rather than through trimesh's
exporter (which writes still scenes only) or a glTF object library. Layout as the specification
(Khronos glTF 2.0, sections 3.6 "Binary data storage" and 4.4 "GLB file format", read) asks: every
accessor's data starts at a multiple of its component size, every buffer view at a multiple of 4,
the JSON chunk padded with spaces and the binary chunk with zeros to 4 bytes; POSITION accessors
and animation inputs carry min and max; quaternions are unit and (x, y, z, w).
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field

import numpy as np

ARRAY_BUFFER = 34962  # bufferView.target: vertex attributes
ELEMENT_ARRAY_BUFFER = 34963  # bufferView.target: indices
_COMPONENTS = {np.dtype(np.float32): 5126, np.dtype(np.uint32): 5125, np.dtype(np.uint16): 5123,
               np.dtype(np.int16): 5122, np.dtype(np.uint8): 5121, np.dtype(np.int8): 5120}
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
GLB_MAGIC = 0x46546C67  # "glTF"
JSON_CHUNK = 0x4E4F534A  # "JSON"
BIN_CHUNK = 0x004E4942  # "BIN\0"


def srgb_to_linear(c) -> list[float]:
    """An sRGB-encoded colour (what our frames draw, components in [0, 1]) as the linear factor glTF
    materials hold (glTF 2.0, section 3.9.2: baseColorFactor is linear), so other viewers show it the same."""
    c = np.clip(np.asarray(c, float), 0.0, 1.0)
    return [round(float(v), 6) for v in np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)]


@dataclass
class GltfBuilder:
    """Collects a glTF document and its binary buffer; `glb()` gives the file's bytes."""

    doc: dict = field(default_factory=lambda: {"asset": {"version": "2.0", "generator": "orthosim"},
                                               "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [],
                                               "materials": [], "accessors": [], "bufferViews": [], "buffers": []})
    _chunks: list = field(default_factory=list)
    _size: int = 0

    def _view(self, data: bytes, target: int | None) -> int:
        pad = (-self._size) % 4
        if pad:
            self._chunks.append(b"\0" * pad)
            self._size += pad
        view = {"buffer": 0, "byteOffset": self._size, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self._chunks.append(data)
        self._size += len(data)
        self.doc["bufferViews"].append(view)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, array: np.ndarray, target: int | None = None, *, bounds: bool = False,
                 normalized: bool = False) -> int:
        """Add `array` ((n,) or (n, k), a dtype glTF has) in its own buffer view; returns the accessor index.
        bounds: write min and max (required for POSITION and animation inputs)."""
        array = np.ascontiguousarray(array)
        if array.dtype not in _COMPONENTS:
            raise ValueError(f"glTF has no component type for {array.dtype}")
        width = 1 if array.ndim == 1 else int(np.prod(array.shape[1:]))
        acc = {"bufferView": self._view(array.tobytes(), target), "componentType": _COMPONENTS[array.dtype],
               "count": int(array.shape[0]), "type": _TYPES[width]}
        if normalized:
            acc["normalized"] = True
        if bounds:
            flat = array.reshape(len(array), width)
            as_number = float if array.dtype.kind == "f" else int
            acc["min"] = [as_number(v) for v in flat.min(axis=0)]
            acc["max"] = [as_number(v) for v in flat.max(axis=0)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def add(self, kind: str, item: dict) -> int:
        """Append `item` to the top-level list `kind` ("nodes", "meshes", "materials", ...); its index."""
        self.doc.setdefault(kind, []).append(item)
        return len(self.doc[kind]) - 1

    def glb(self) -> bytes:
        """The GLB file: 12-byte header, the JSON chunk, the binary chunk."""
        doc = dict(self.doc)
        doc["buffers"] = [{"byteLength": self._size}]
        doc = {k: v for k, v in doc.items() if v != []}
        text = json.dumps(doc, separators=(",", ":")).encode()
        text += b" " * ((-len(text)) % 4)
        binary = b"".join(self._chunks)
        binary += b"\0" * ((-len(binary)) % 4)
        total = 12 + 8 + len(text) + 8 + len(binary)
        return b"".join([struct.pack("<III", GLB_MAGIC, 2, total), struct.pack("<II", len(text), JSON_CHUNK), text,
                         struct.pack("<II", len(binary), BIN_CHUNK), binary])


@dataclass(frozen=True)
class Glb:
    """A GLB read back: its JSON document and binary chunk, with accessors as numpy arrays."""

    doc: dict
    binary: bytes

    def array(self, accessor: int) -> np.ndarray:
        """Accessor `accessor` as an (count,) or (count, k) array of its component type (normalized
        integers as they are stored, not scaled)."""
        acc = self.doc["accessors"][accessor]
        view = self.doc["bufferViews"][acc["bufferView"]]
        dtype = {v: k for k, v in _COMPONENTS.items()}[acc["componentType"]]
        width = {v: k for k, v in _TYPES.items()}[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        data = np.frombuffer(self.binary, dtype, acc["count"] * width, start)
        return data if width == 1 else data.reshape(acc["count"], width)


class GlbFormatError(ValueError):
    """Bytes that are not a GLB file this module can read."""


def read_glb(data: bytes) -> Glb:
    """Parse GLB bytes (header, JSON chunk, binary chunk); GlbFormatError when they are not one."""
    if len(data) < 20:
        raise GlbFormatError(f"{len(data)} bytes are too few for a GLB file")
    magic, version, total = struct.unpack_from("<III", data, 0)
    if magic != GLB_MAGIC or version != 2 or total != len(data):
        raise GlbFormatError(f"header (magic {magic:#x}, version {version}, length {total}) is not a glTF 2.0 binary of {len(data)} bytes")
    length, kind = struct.unpack_from("<II", data, 12)
    if kind != JSON_CHUNK:
        raise GlbFormatError("the first chunk is not JSON")
    doc = json.loads(data[20:20 + length])
    binary = b""
    rest = 20 + length
    if rest + 8 <= len(data):
        blength, bkind = struct.unpack_from("<II", data, rest)
        if bkind != BIN_CHUNK:
            raise GlbFormatError("the second chunk is not BIN")
        binary = data[rest + 8:rest + 8 + blength]
    return Glb(doc, binary)


def quaternion_xyzw(rotations: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices -> (n, 4) unit quaternions (x, y, z, w), w >= 0, float64.

    Shepperd's method: from the largest of the trace and the diagonal, so no branch divides by a
    small number."""
    R = np.asarray(rotations, float).reshape(-1, 3, 3)
    q = np.empty((len(R), 4))
    tr = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    diag = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    which = diag.argmax(axis=1)
    for k in range(4):
        m = which == k
        if not m.any():
            continue
        r = R[m]
        if k == 0:
            s = np.sqrt(1.0 + tr[m]) * 2
            q[m] = np.stack([(r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                             (r[:, 1, 0] - r[:, 0, 1]) / s, 0.25 * s], axis=1)
        else:
            i = k - 1
            j, l = (i + 1) % 3, (i + 2) % 3
            s = np.sqrt(1.0 + r[:, i, i] - r[:, j, j] - r[:, l, l]) * 2
            out = np.empty((len(r), 4))
            out[:, i] = 0.25 * s
            out[:, j] = (r[:, j, i] + r[:, i, j]) / s
            out[:, l] = (r[:, l, i] + r[:, i, l]) / s
            out[:, 3] = (r[:, l, j] - r[:, j, l]) / s
            q[m] = out
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1
    return q


def rotation_of_quaternion(q: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (x, y, z, w) -> (n, 3, 3) rotation matrices (normalised first)."""
    q = np.asarray(q, float).reshape(-1, 4)
    x, y, z, w = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1)], axis=1)
