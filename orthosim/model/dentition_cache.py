"""On-disk cache of built dentitions, so that a run starts from its teeth in milliseconds.

Building the parametric model takes seconds to tens of seconds (tooth shapes, boolean crown
centres, FCL contact searches, the upper-arch fit), and loading real teeth repairs and validates
every mesh; a run, a batch variant or a test that asks for the same model again should not pay for
that. The cache is keyed like the sphere-tree cache (`orthosim.spheretree.cache`): a SHA-256 of the
model's parameters, the bytes of every input file (meshes, axes), `BUILDER_VERSION` (bumped when a
builder changes its output on purpose) and the source text of the modules that build dentitions
(so an edited builder never serves a stale model). An entry is one .npz of plain arrays and a JSON
header (no pickle), checksummed and written atomically through `orthosim.storage.cacheentry`: two
processes building the same model at once both end with a whole file. An entry that fails its
checks (unreadable, wrong checksum or key, non-finite numbers, wrong shapes, face indices out of
range) is a miss, reported in one warning line naming it, rebuilt and overwritten; a folder that
cannot be written costs a rebuild next time, never a failure.
Warnings the build raised (mesh repairs) are stored with it and raised again on every load.

The folder is `$ORTHOSIM_CACHE/dentitions` when that is set, else `~/.cache/orthosim/dentitions`.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import warnings
from pathlib import Path
from typing import Callable, Iterable, Mapping

import numpy as np

from orthosim.errors import DamagedFileError
from orthosim.geometry.lazymesh import DERIVED, LazyMesh, derived_values, known_values
from orthosim.storage.cacheentry import ENTRY_FORMAT, DamagedEntryWarning, damaged, read_arrays, warn_damaged, write_arrays
from orthosim.storage.shipped import shipped_entry
from orthosim.storage.sourcedigest import source_digest
from orthosim.system.firstrun import preparing

BUILDER_VERSION = 2  # 2: entries keep the trimesh-derived values a run reads (orthosim.geometry.lazymesh)
ENTRY_KIND = "dentition"
# Modules whose code decides what a built dentition holds: their source is part of the key.
_BUILDER_MODULES = ("model/anatomy", "model/archform", "model/dentition", "model/fdi", "collision/interpenetration",
                    "exchange/meshload", "exchange/meshfolder", "geometry/meshrefine", "model/occlusion", "exchange/openfulljaw",
                    "model/parametric", "exchange/scanfolders", "exchange/scanframe", "model/tooth", "model/toothshape",
                    "geometry/meshquery", "geometry/penetration", "geometry/signeddistance",
                    "model/rootsynthesis", "exchange/labelledscan", "geometry/meshcut")
_PACKAGE = Path(__file__).resolve().parents[1]  # orthosim/


class DentitionCacheWarning(DamagedEntryWarning):
    """A cached dentition failed its checks (checksum, header, content); it is rebuilt."""


def default_cache_dir() -> Path:
    env = os.environ.get("ORTHOSIM_CACHE")
    return (Path(env) if env else Path.home() / ".cache" / "orthosim") / "dentitions"


def _builder_source_digest() -> str:
    return source_digest(_PACKAGE, _BUILDER_MODULES)


def parametric_parameters(resolution: int | str, third_molars: bool, diastema_mm: float) -> dict:
    """The key parameters of the parametric model (`orthosim.model.parametric.parametric_dentition`)."""
    return {"kind": "parametric", "resolution": resolution, "third_molars": bool(third_molars),
            "diastema_mm": float(diastema_mm)}


def cache_key(parameters: Mapping, input_files: Iterable[str | Path] = ()) -> str:
    """Hex SHA-256 of the model parameters (JSON), the input files' bytes, the builder (version, code)
    and the entry format (`orthosim.storage.cacheentry.ENTRY_FORMAT`)."""
    h = hashlib.sha256()
    h.update(json.dumps(parameters, sort_keys=True, default=str).encode())
    for path in sorted(Path(p) for p in input_files):
        h.update(path.name.encode())
        h.update(hashlib.sha256(path.read_bytes()).digest())
    h.update(f"|v{BUILDER_VERSION}|{_builder_source_digest()}|entry{ENTRY_FORMAT}".encode())
    return h.hexdigest()


def entry_path(parameters: Mapping, input_files: Iterable[str | Path] = (), cache_dir: str | Path | None = None) -> Path:
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return folder / f"{cache_key(parameters, input_files)}.npz"


def _jsonable(obj):
    """What the JSON header holds of `Dentition.info`: arrays as lists, paths and keys as strings."""
    return json.loads(json.dumps(obj, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def save_dentition(dent, path: str | Path, raised: list[tuple[str, str]] = ()) -> None:
    """Write a dentition as a checksummed .npz entry (atomically): per tooth its mesh, face parts,
    landmarks and frame; the entry's key is the file name's stem."""
    arrays: dict[str, np.ndarray] = {}
    teeth = []
    for n, t in dent.teeth.items():
        arrays[f"{n}_vertices"] = np.asarray(t.mesh.vertices, np.float64)
        arrays[f"{n}_faces"] = np.asarray(t.mesh.faces, np.int64)
        arrays[f"{n}_face_part"] = np.asarray(t.face_part)
        arrays[f"{n}_crown_center"] = np.asarray(t.crown_center, np.float64)
        arrays[f"{n}_apex"] = np.asarray(t.apex, np.float64)
        arrays[f"{n}_rest_pose"] = np.asarray(t.rest_pose, np.float64)
        for name, p in t.landmarks.items():
            arrays[f"{n}_landmark_{name}"] = np.asarray(p, np.float64)
        # areas and mass properties, so that a run's model build reads them instead of importing trimesh
        for name, value in derived_values(arrays[f"{n}_vertices"], arrays[f"{n}_faces"]).items():
            arrays[f"{n}_derived_{name}"] = value
        teeth.append({"fdi": n, "source": t.source, "landmarks": list(t.landmarks), "root": t.root_origin})
    for name, gum in dent.gingiva.items():
        arrays[f"gingiva_{name}_vertices"] = np.asarray(gum.vertices, np.float64)
        arrays[f"gingiva_{name}_faces"] = np.asarray(gum.faces, np.int64)
    header = {"description": dent.description, "info": _jsonable(dent.info), "teeth": teeth,
              "warnings": [list(w) for w in raised], "gingiva": list(dent.gingiva)}
    arrays["header"] = np.array(json.dumps(header))
    write_arrays(path, ENTRY_KIND, Path(path).stem, arrays)


def _tooth_arrays(path: Path, z: Mapping[str, np.ndarray], entry: Mapping) -> dict:
    """One tooth's arrays from an entry, checked for shape, finiteness and face indices."""
    n = int(entry["fdi"])
    names = {"vertices": (None, 3), "faces": (None, 3), "face_part": (None,), "crown_center": (3,), "apex": (3,),
             "rest_pose": (4, 4), **{f"landmark_{name}": (3,) for name in entry["landmarks"]}}
    out = {}
    for name, shape in names.items():
        a = z.get(f"{n}_{name}")
        if a is None or a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
            raise damaged(path, f"tooth {n}: {name} is missing or has the wrong shape")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise damaged(path, f"tooth {n}: {name} holds non-finite numbers")
        out[name] = a
    faces = out["faces"]
    if faces.dtype.kind not in "iu" or (faces.size and (faces.min() < 0 or faces.max() >= len(out["vertices"]))):
        raise damaged(path, f"tooth {n}: a face names a vertex that does not exist")
    if len(out["face_part"]) != len(faces):
        raise damaged(path, f"tooth {n}: {len(out['face_part'])} face parts for {len(faces)} faces")
    return out


def load_dentition(path: str | Path):
    """(dentition, warnings raised when it was built) from an entry written by `save_dentition`.

    Raises FileNotFoundError when absent, `DamagedFileError` when the entry fails its checksum,
    header or content checks (shapes, finite numbers, face indices). The teeth's meshes are
    `LazyMesh`es: a run that reads only their arrays never imports trimesh."""
    from orthosim.model.dentition import Dentition
    from orthosim.model.tooth import Tooth

    path = Path(path)
    z = read_arrays(path, ENTRY_KIND, path.stem)
    try:
        header = json.loads(str(z["header"]))
        teeth = {}
        for entry in header["teeth"]:
            n = int(entry["fdi"])
            a = _tooth_arrays(path, z, entry)
            mesh = LazyMesh(a["vertices"], a["faces"], _derived(path, z, n, len(a["faces"])))
            teeth[n] = Tooth(fdi=n, mesh=mesh, face_part=a["face_part"], crown_center=a["crown_center"], apex=a["apex"],
                             rest_pose=a["rest_pose"], source=entry["source"],
                             landmarks={name: a[f"landmark_{name}"] for name in entry["landmarks"]},
                             root_origin=_root_origin(path, entry.get("root", "scan")))
        gingiva = {name: _gingiva_mesh(path, z, name) for name in header.get("gingiva", [])}
        raised = [tuple(w) for w in header["warnings"]]
        return Dentition(teeth, header["description"], header["info"], gingiva), raised
    except (KeyError, TypeError, ValueError) as err:  # a header this version did not write
        raise damaged(path, f"its header does not describe a dentition ({type(err).__name__}: {err})") from None


def _derived(path: Path, z: Mapping[str, np.ndarray], n: int, n_faces: int) -> dict:
    """Tooth n's trimesh-derived values (`orthosim.geometry.lazymesh.DERIVED`), checked; {} when the
    entry has none (its LazyMesh then makes its trimesh when they are asked for)."""
    found = {name: z[f"{n}_derived_{name}"] for name in DERIVED if f"{n}_derived_{name}" in z}
    if not found:
        return {}
    shapes = {"area_faces": (n_faces,), "center_mass": (3,), "moment_inertia": (3, 3)}
    for name in DERIVED:
        a = found.get(name)
        if a is None or a.shape != shapes.get(name, ()):  # not checked finite: an open mesh's may not be, as trimesh's
            raise damaged(path, f"tooth {n}: derived {name} is missing or has the wrong shape")
    return known_values(found)


def _root_origin(path: Path, value) -> str:
    if value not in ("scan", "estimated"):
        raise damaged(path, f"a tooth's root is {value!r}, neither 'scan' nor 'estimated'")
    return value


def _gingiva_mesh(path: Path, z: Mapping[str, np.ndarray], name: str):
    """A scanned gum's mesh from an entry, checked like the teeth's arrays."""
    import trimesh

    v, f = z.get(f"gingiva_{name}_vertices"), z.get(f"gingiva_{name}_faces")
    if v is None or f is None or v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise damaged(path, f"gingiva {name}: vertices or faces missing or of the wrong shape")
    if not np.isfinite(v).all():
        raise damaged(path, f"gingiva {name}: vertices hold non-finite numbers")
    if f.dtype.kind not in "iu" or (f.size and (f.min() < 0 or f.max() >= len(v))):
        raise damaged(path, f"gingiva {name}: a face names a vertex that does not exist")
    return trimesh.Trimesh(v, f, process=False)


def _warning_class(qualified: str) -> type[Warning]:
    module, _, name = qualified.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module), name)
        return cls if isinstance(cls, type) and issubclass(cls, Warning) else UserWarning
    except (ImportError, AttributeError, ValueError):
        return UserWarning


def _replay(raised: Iterable[tuple[str, str]]) -> None:
    for category, message in raised:
        warnings.warn(message, _warning_class(category), stacklevel=3)


def is_cached(parameters: Mapping, input_files: Iterable[str | Path] = (), cache_dir: str | Path | None = None) -> bool:
    """Whether an entry for this model is on disk (it may still turn out unreadable)."""
    return entry_path(parameters, input_files, cache_dir).is_file()


def cached_dentition(parameters: Mapping, build: Callable[[], object], input_files: Iterable[str | Path] = (),
                     cache_dir: str | Path | None = None):
    """The dentition `build()` makes for these parameters and input files, through the disk cache.

    A hit returns the stored teeth (bit-identical arrays) and raises the build's warnings again. A
    miss builds, stores and returns what a later hit will return: `info` as JSON keeps it (arrays
    as lists, keys as strings), so a run's outputs do not depend on whether the cache was warm.
    """
    from orthosim.model.dentition import Dentition

    input_files = list(input_files)
    path = entry_path(parameters, input_files, cache_dir)
    # the user's cache first, then the entries shipped with the package (orthosim.storage.shipped)
    for found in (path, shipped_entry("dentitions", path.name)):
        if found is None or not found.is_file():
            continue
        try:
            dent, raised = load_dentition(found)
        except FileNotFoundError:
            pass  # removed since the look: a miss
        except DamagedFileError as err:
            warn_damaged("dentition", err, DentitionCacheWarning)
        else:
            _replay(raised)
            return dent
    with warnings.catch_warnings(record=True) as caught, preparing("the teeth of this model"):
        warnings.simplefilter("always")
        built = build()
    raised = [(f"{w.category.__module__}.{w.category.__qualname__}", str(w.message)) for w in caught]
    try:
        save_dentition(built, path, raised)
    except OSError:
        pass  # a read-only or full cache folder costs a rebuild next time, never a failure
    _replay(raised)
    return Dentition(built.teeth, built.description, _jsonable(built.info), built.gingiva)
