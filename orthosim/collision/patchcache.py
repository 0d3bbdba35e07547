"""The first step's patches kept between runs: which faces of two teeth lie near each other at rest.

A run's exact queries cut each close pair's patches (`orthosim.collision.queries`) with a k-d tree
of face centroids. At the first step every pair is cut, at the poses the teeth start from, and
every run of the same teeth starts from the same poses whatever its plan: so the faces each cut
kept are stored here and read back by the next run, which then needs neither the k-d trees nor
scipy.spatial before its first step (importing it took 0.3-0.45 s of a 0.95 s warm start on this
two-core machine, 2026-11-29; the cuts 0.1-0.2 s more). Later steps' poses depend on the plan and
the step, and are not kept: they would fill the folder with cuts no run asks for again.

An entry is keyed by everything the cut reads: both meshes' vertices and faces, the two relative
poses' exact bytes, the reach, and the source text of the module that cuts (an edited cut never
reads an older one's faces). It is a checksummed cache entry (`orthosim.storage.cacheentry`); on
reading, the face indices are also checked against the meshes (1-D integers, each a face of its
mesh, none twice). A damaged entry gives one warning and is cut and written again; a folder that
cannot be written costs only the time to cut. The folder is `$ORTHOSIM_CACHE/patches`, else
`~/.cache/orthosim/patches`.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

import numpy as np

from orthosim.errors import DamagedFileError
from orthosim.storage.cacheentry import arrays_digest, damaged, read_arrays, warn_damaged, write_arrays
from orthosim.storage.sourcedigest import source_digest

ENTRY_KIND = "patches"
_CUTTING_MODULES = ("queries", "patchcache")  # the cut and this file's key: their source enters the key


def default_cache_dir() -> Path:
    env = os.environ.get("ORTHOSIM_CACHE")
    return (Path(env) if env else Path.home() / ".cache" / "orthosim") / "patches"


@functools.cache
def _cut_source_digest() -> str:
    return source_digest(Path(__file__).resolve().parent, _CUTTING_MODULES)


def mesh_digest(vertices: np.ndarray, faces: np.ndarray) -> str:
    """Hex SHA-256 of a mesh's vertices and faces (dtype, shape and bytes of each)."""
    return arrays_digest({"vertices": vertices, "faces": faces})


class PatchCache:
    """The kept cuts in one folder: `key` names a cut, `get` reads its faces, `put` stores them."""

    def __init__(self, folder: str | Path | None = None):
        self.folder = Path(folder) if folder is not None else default_cache_dir()

    def key(self, mesh_i: str, mesh_j: str, rel_ij: np.ndarray, rel_ji: np.ndarray, reach_mm: float) -> str:
        """The cut of meshes with digests mesh_i and mesh_j at relative poses rel_ij (i in j's frame)
        and rel_ji (j in i's), each (3, 4) float64, within reach_mm."""
        h = hashlib.sha256(f"{_cut_source_digest()}\0{mesh_i}\0{mesh_j}\0{float(reach_mm).hex()}\0".encode())
        for pose in (rel_ij, rel_ji):
            h.update(np.ascontiguousarray(pose, np.float64).tobytes())
        return h.hexdigest()

    def get(self, key: str, faces_in_i: int, faces_in_j: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The kept faces of i and of j (nearest the other tooth first), or None when not stored
        (or damaged: warned once, and left for `put` to replace)."""
        path = self.folder / f"{key}.npz"
        if not path.is_file():  # no entry, or no folder (or a file where the folder should be)
            return None
        try:
            arrays = read_arrays(path, ENTRY_KIND, key)
            return _checked(path, arrays, "faces_i", faces_in_i), _checked(path, arrays, "faces_j", faces_in_j)
        except FileNotFoundError:  # removed meanwhile
            return None
        except DamagedFileError as err:
            warn_damaged("patch", err)
            return None

    def put(self, key: str, faces_i: np.ndarray, faces_j: np.ndarray) -> None:
        """Store a cut's faces, atomically; a folder that cannot be written is left as it is."""
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            write_arrays(self.folder / f"{key}.npz", ENTRY_KIND, key,
                         {"faces_i": np.asarray(faces_i, np.int64), "faces_j": np.asarray(faces_j, np.int64)})
        except OSError:
            pass


def _checked(path: Path, arrays: dict, name: str, n_faces: int) -> np.ndarray:
    faces = arrays.get(name)
    if faces is None or faces.ndim != 1 or faces.dtype != np.int64:
        raise damaged(path, f"its {name} is not a list of face indices")
    if len(faces) and (faces.min() < 0 or faces.max() >= n_faces or len(np.unique(faces)) != len(faces)):
        raise damaged(path, f"its {name} names faces its mesh does not have, or one twice")
    return faces
