"""A triangle mesh held as its two arrays, the trimesh made from them only when something asks for more.

Importing trimesh pulls scipy, networkx and more (over a second of a warm start on a loaded two-core
machine), yet a run's first step reads nothing of a tooth's mesh but its vertices and faces (the
sphere trees come from the cache, FCL takes the two arrays). A `LazyMesh` is what the dentition
cache hands out: `vertices` (n, 3) float64 mm and `faces` (m, 3) int64 are plain arrays; any other
attribute (`triangles`, `face_normals`, `copy()`, `apply_transform` ...) is the trimesh's, made once
on first use as `trimesh.Trimesh(vertices, faces, process=False)`, which is what the cache built
before this class existed, so every derived number is the same. A trimesh function that checks the
class of its argument (`trimesh.registration.icp`) takes `as_trimesh(mesh)`. It pickles as its two
arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class LazyMesh:
    """`vertices` (n, 3) float64 and `faces` (m, 3) int64 of a mesh (mm, its own frame); every other
    attribute is that of `trimesh.Trimesh(vertices, faces, process=False)`, made on first use."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, known: dict[str, Any] | None = None):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self._known = {k: v for k, v in (known or {}).items() if k in DERIVED}
        self._trimesh = None

    @property
    def built(self) -> bool:
        """Whether the trimesh has been made (its derived caches exist only then)."""
        return self._trimesh is not None

    @property
    def trimesh(self):
        """The `trimesh.Trimesh` of these arrays (process=False), made once."""
        if self._trimesh is None:
            import trimesh

            self._trimesh = trimesh.Trimesh(self.vertices, self.faces, process=False)
        return self._trimesh

    def __getattr__(self, name: str) -> Any:
        # only called for names this object lacks; dunders (pickle, copy) and the slot itself are never delegated
        if name.startswith("__") or name in ("_trimesh", "_known"):
            raise AttributeError(name)
        if name in self._known and self._trimesh is None:
            return self._known[name]
        return getattr(self.trimesh, name)

    def __reduce__(self):
        return (LazyMesh, (self.vertices, self.faces, self._known))

    def __repr__(self) -> str:
        return f"<LazyMesh: {len(self.vertices)} vertices, {len(self.faces)} faces{', built' if self.built else ''}>"


# trimesh's values, derived from the arrays alone, that building a run's model asks of a tooth
# (`orthosim.mechanics.biomechanics.build_mechanics`): name -> how it is stored (bool, float or array)
DERIVED = ("area_faces", "area", "is_volume", "volume", "center_mass", "moment_inertia")


def derived_values(vertices: np.ndarray, faces: np.ndarray) -> dict[str, np.ndarray]:
    """`DERIVED`'s values of the trimesh `LazyMesh(vertices, faces)` would make, as arrays (a bool or
    a float as a 0-d array), for a cache to keep beside the arrays."""
    mesh = LazyMesh(vertices, faces).trimesh
    return {name: np.array(getattr(mesh, name)) for name in DERIVED}


def known_values(arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """`derived_values`'s arrays as trimesh gives them (a bool, a float, a read-only array)."""
    out: dict[str, Any] = {}
    for name, a in arrays.items():
        if a.ndim == 0:
            out[name] = a.item() if a.dtype.kind == "b" else a[()]
        else:
            a = a.copy()
            a.flags.writeable = False
            out[name] = a
    return out


def as_trimesh(mesh):
    """The `trimesh.Trimesh` behind `mesh` (a `LazyMesh`'s, made if need be), or `mesh` itself."""
    return mesh.trimesh if isinstance(mesh, LazyMesh) else mesh
