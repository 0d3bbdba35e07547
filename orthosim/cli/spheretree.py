"""`orthosim spheretree build|eval`: sphere trees for a mesh, a folder of meshes or a case, and their figures.

`build` writes one tree per tooth (Bradshaw `.sph` by default), going through the on-disk cache. A
tree is named by FDI number (`11.sph`) only where the numbering is known: a case or an
Open-Full-Jaw folder (whose `tooth_N.stl` are Universal numbers, converted), or mesh files with
`--numbering fdi|universal` saying how to read the number in their names; otherwise by the file's
own stem (`tooth_11.sph`), since `tooth_11` is FDI 11 in one dataset and Universal 11 (FDI 23) in
another. `eval` builds each tree afresh (so the build time it reports is real),
measures the paper's sphere outside volume and the coverage with `measure_tree`, and writes one JSON
file: per tooth `fdi`, `leaves`, `sov_sum`, `sov_union`, `surface_coverage`, `build_s` (and more),
and a `summary` (mean, min, max). Sources: a mesh file (STL/OBJ/PLY, used in its own frame), a
folder of them, an Open-Full-Jaw folder (`tooth_N.stl` + `teeth_axes_*.json`), or a case (.toml);
the last two give teeth in their local frames, as the simulator uses them. `eval` takes several
sources at once (both arches of a patient) and reads an Open-Full-Jaw folder's meshes as scanned:
its figures do not depend on the frame, so it needs no axes file entry per tooth. Open-Full-Jaw
files are named by Universal number (`tooth_3.stl` is FDI 16): rows carry both numbers.
"""

from __future__ import annotations

import re
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import click
import numpy as np

from orthosim.errors import SphereTreeError
from orthosim.spheretree.build import FIT_BRANCHING, METHODS, check_request, default_branching

MESH_SUFFIXES = (".stl", ".obj", ".ply")


@dataclass(frozen=True)
class NamedMesh:
    name: str  # output file stem: the FDI number when known, else the file's stem
    fdi: int | None
    vertices: np.ndarray  # (n, 3) float64, mm
    faces: np.ndarray  # (m, 3) int64
    universal: int | None = None  # the Universal number an Open-Full-Jaw file is named by


def _from_dentition(dent) -> list[NamedMesh]:
    return [
        NamedMesh(str(n), n, np.asarray(t.mesh.vertices, float), np.asarray(t.mesh.faces, np.int64))
        for n, t in sorted(dent.teeth.items())
    ]


NUMBERINGS = ("fdi", "universal")


def _fdi_in_name(path: Path, numbering: str | None) -> int | None:
    """The FDI number of a mesh file from the last number in its name, read as `numbering` says;
    None when no numbering is given (the file keeps its own name)."""
    from orthosim.model.fdi import is_fdi, universal_to_fdi

    if numbering is None:
        return None
    numbers = re.findall(r"\d+", path.stem)
    number = int(numbers[-1]) if numbers else None
    if numbering == "universal" and number is not None and 1 <= number <= 32:
        return universal_to_fdi(number)
    if numbering == "fdi" and is_fdi(number):
        return number
    raise SphereTreeError(path, "--numbering", f"the name holds no {numbering.upper()} tooth number",
                          "rename the file (e.g. tooth_11.stl) or leave out --numbering to keep the file's name")


def _open_full_jaw_as_scanned(folder: Path) -> list[NamedMesh]:
    """The `tooth_N.stl` meshes of an Open-Full-Jaw folder in the scan frame, named by FDI number."""
    from orthosim.model.fdi import universal_to_fdi
    from orthosim.exchange.meshload import load_tooth_mesh

    out = []
    for p in sorted(folder.glob("tooth_*.stl")):
        match = re.fullmatch(r"tooth_(\d+)", p.stem)
        if not match:
            continue
        universal = int(match.group(1))
        try:
            fdi = universal_to_fdi(universal)
        except ValueError:
            raise SphereTreeError(p, None, f"{universal} is not a Universal tooth number (1-32)",
                                  "rename the file tooth_N.stl with N in 1-32") from None
        mesh = load_tooth_mesh(p)
        out.append(NamedMesh(str(fdi), fdi, np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), universal))
    return sorted(out, key=lambda m: m.fdi)


def _is_open_full_jaw(folder: Path) -> bool:
    return folder.is_dir() and any(folder.glob("teeth_axes_*.json")) and any(folder.glob("tooth_*.stl"))


def load_source(source: Path, numbering: str | None = None, as_scanned: bool = False) -> list[NamedMesh]:
    """The tooth meshes named by `source` (see the module text), in a stable order.

    numbering: how to read the tooth number in mesh file names ("fdi" or "universal"); None: the
    trees keep the files' names. Cases and Open-Full-Jaw folders know their numbering already.
    as_scanned: an Open-Full-Jaw folder gives its meshes in the scan frame (no arch import)."""
    if not source.exists():
        raise SphereTreeError(source, None, "not found", "give a mesh file, a folder of meshes or a case .toml")
    if source.is_file() and source.suffix.lower() == ".toml":
        from orthosim.exchange.case import load_case

        return _from_dentition(load_case(source).build_dentition())
    from orthosim.exchange.meshload import load_tooth_mesh

    if source.is_file():
        if source.suffix.lower() not in MESH_SUFFIXES:
            raise SphereTreeError(source, None, f"unsupported file type '{source.suffix}'", "give an STL, OBJ or PLY mesh, a folder, or a case .toml")
        files = [source]
    else:
        if _is_open_full_jaw(source):
            if as_scanned:
                return _open_full_jaw_as_scanned(source)
            from orthosim.exchange.openfulljaw import load_open_full_jaw

            return _from_dentition(load_open_full_jaw(source))
        files = sorted(p for p in source.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
        if not files:
            raise SphereTreeError(source, None, "holds no STL, OBJ or PLY meshes", "point at the folder that holds the tooth meshes")
    out = []
    for p in files:
        mesh = load_tooth_mesh(p)
        fdi = _fdi_in_name(p, numbering)
        out.append(NamedMesh(str(fdi) if fdi else p.stem, fdi, np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)))
    names = [m.name for m in out]
    if len(set(names)) != len(names):
        raise SphereTreeError(source, None, "two meshes would get the same output name", "give each tooth file a distinct tooth number in its name")
    return out


def mean_errors(key: str, values: np.ndarray, stderrs: np.ndarray) -> dict:
    """Errors of the mean of per-tooth figures: `<key>_sem`, the standard error over the teeth (sample
    standard deviation / sqrt(n); 0 for one tooth), and `<key>_mean_mc_stderr`, the Monte Carlo error
    of the mean from the per-tooth standard errors."""
    n = len(values)
    sem = float(values.std(ddof=1) / np.sqrt(n)) if n > 1 else 0.0
    return {f"{key}_sem": sem, f"{key}_mean_mc_stderr": float(np.sqrt((stderrs**2).sum()) / n)}


def _progress(items, desc: str, total: int | None = None):
    from tqdm import tqdm

    return tqdm(items, desc=desc, total=total, unit="tooth", disable=not sys.stderr.isatty())


def _request_options(f):
    f = click.option("--numbering", type=click.Choice(NUMBERINGS), default=None,
                     help="How to read the tooth number in mesh file names (trees are then named by FDI). "
                          "Default: keep the file names. Cases and Open-Full-Jaw folders need none.")(f)
    f = click.option("--depth", type=int, default=None, help="Levels with the root [default: 4 for fit, 6 for octree].")(f)
    f = click.option("--branch", "branching", type=int, default=None,
                     help=f"Branching factor [default: {FIT_BRANCHING} for fit, 8 for octree].")(f)
    f = click.option("--method", type=click.Choice(METHODS), default="fit", show_default=True,
                     help="fit: optimising builder (tight); octree: equal spheres per level (the paper's comparison).")(f)
    return f


def _depth(method: str, depth: int | None) -> int:
    return depth if depth is not None else (6 if method == "octree" else 4)


@click.group("spheretree")
def spheretree() -> None:
    """Sphere trees of teeth: build them, export them to Bradshaw's .sph, measure their fit."""


@spheretree.command("build")
@click.argument("source", type=click.Path(path_type=Path))
@_request_options
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Output folder.")
@click.option("--format", "fmt", type=click.Choice(["sph", "npz"]), default="sph", show_default=True,
              help="sph: Bradshaw's text format; npz: orthosim's own (keeps the face-to-leaf map).")
@click.option("--cache-dir", type=click.Path(path_type=Path), default=None,
              help="Tree cache folder [default: $ORTHOSIM_CACHE or ~/.cache/orthosim/spheretrees].")
@click.option("--no-cache", is_flag=True, help="Always build; neither read nor write the cache.")
def build(source: Path, method: str, branching: int, depth: int | None, out_dir: Path, fmt: str,
          cache_dir: Path | None, no_cache: bool, numbering: str | None) -> None:
    """Build the sphere tree of every tooth in SOURCE (mesh, folder or case .toml) into OUT."""
    import tempfile

    from orthosim.spheretree.cache import cached_sphere_trees, save_tree
    from orthosim.spheretree.sph import write_sph

    depth = _depth(method, depth)
    branching = default_branching(method, branching)
    check_request(method, branching, depth, where="spheretree build")
    meshes = load_source(source, numbering)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="orthosim-trees-") as scratch, _progress(None, "sphere trees", len(meshes)) as bar:
        # --no-cache: a throw-away cache, so nothing is read or kept, yet mirror pairs still build once
        trees = cached_sphere_trees([(m.vertices, m.faces) for m in meshes], method, branching, depth,
                                    scratch if no_cache else cache_dir, progress=bar.update)
    build_s = time.perf_counter() - t0
    for m, tree in zip(meshes, trees):
        if fmt == "sph":
            write_sph(tree, out_dir / f"{m.name}.sph")
        else:
            save_tree(tree, out_dir / f"{m.name}.npz")
    leaves = [tree.n_leaves for tree in trees]
    click.echo(f"{len(meshes)} trees ({method}, branching {branching}, depth {depth}, "
               f"{np.mean(leaves):.0f} leaves on average) in {build_s:.2f} s -> {out_dir}")


@spheretree.command("eval")
@click.argument("sources", nargs=-1, required=True, type=click.Path(path_type=Path))
@_request_options
@click.option("--out", "out_file", type=click.Path(path_type=Path), required=True, help="Output JSON file.")
@click.option("--samples", type=int, default=400_000, show_default=True, help="Monte Carlo points in the leaf spheres, per tooth.")
@click.option("--surface-samples", type=int, default=200_000, show_default=True, help="Surface points for the coverage, per tooth.")
@click.option("--seed", type=int, default=0, show_default=True)
def evaluate(sources: tuple[Path, ...], method: str, branching: int, depth: int | None, out_file: Path, samples: int,
             surface_samples: int, seed: int, numbering: str | None) -> None:
    """Build and measure the trees of SOURCES (meshes, folders, cases): SOV (summed, union), coverage,
    build time -> JSON, per tooth and as a mean with its standard error."""
    from orthosim.storage.atomic import write_json
    from orthosim.spheretree.build import build_sphere_tree
    from orthosim.spheretree.measure import measure_tree

    depth = _depth(method, depth)
    branching = default_branching(method, branching)
    check_request(method, branching, depth, where="spheretree eval")
    if surface_samples < 100_000:
        raise SphereTreeError("spheretree eval", "--surface-samples", f"{surface_samples} is too few to vouch for coverage", "use at least 100000")
    if samples < 10_000:
        raise SphereTreeError("spheretree eval", "--samples", f"{samples} gives a useless error bar", "use at least 10000")
    meshes = [(source, m) for source in sources for m in load_source(source, numbering, as_scanned=True)]
    names = [m.name for _, m in meshes]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise SphereTreeError("spheretree eval", "SOURCES", f"tooth {twice[0]} is given twice",
                              "give each tooth once (e.g. the two arches of one patient)")
    rows = []
    for source, m in _progress(meshes, "sphere trees"):
        t0 = time.perf_counter()
        tree = build_sphere_tree((m.vertices, m.faces), method, branching, depth)
        build_s = time.perf_counter() - t0
        rep = measure_tree(tree, m.vertices, m.faces, sphere_samples=samples, n_surface=surface_samples, seed=seed)
        row = {"fdi": m.fdi, "universal": m.universal, "name": m.name, "source": str(source),
               "faces": len(m.faces), "leaves": rep.leaves,
               "sov_sum": rep.sov_sum, "sov_union": rep.sov_union, "surface_coverage": rep.surface_coverage,
               "build_s": build_s}
        row.update({k: v for k, v in asdict(rep).items() if k not in row})
        rows.append(row)

    def col(key):
        return np.array([r[key] for r in rows], dtype=float)

    summary = {
        "teeth": len(rows),
        "sov_sum_mean": float(col("sov_sum").mean()),
        **mean_errors("sov_sum", col("sov_sum"), col("sov_sum_stderr")),
        "sov_sum_min": float(col("sov_sum").min()),
        "sov_sum_max": float(col("sov_sum").max()),
        "sov_union_mean": float(col("sov_union").mean()),
        **mean_errors("sov_union", col("sov_union"), col("sov_union_stderr")),
        "sov_union_min": float(col("sov_union").min()),
        "sov_union_max": float(col("sov_union").max()),
        "surface_coverage_min": float(col("surface_coverage").min()),
        "interior_coverage_min": float(col("interior_coverage").min()),
        "leaves_mean": float(col("leaves").mean()),
        "leaves_min": int(col("leaves").min()),
        "leaves_max": int(col("leaves").max()),
        "build_s_total": float(col("build_s").sum()),
        "build_s_mean": float(col("build_s").mean()),
        "build_s_max": float(col("build_s").max()),
    }
    write_json(out_file, {
        "sources": [str(s) for s in sources], "method": method, "branching": branching, "depth": depth,
        "estimator": ("SOV relative to the tooth volume, Monte Carlo: points uniform in each leaf sphere "
                      "(count proportional to its volume); summed = sum_i V_i * share outside the tooth; union = "
                      "sum_i V_i * mean(outside / number of leaves holding the point); *_stderr: one standard error; "
                      "summary *_sem: standard error of the mean over the teeth (their spread); *_mean_mc_stderr: "
                      "the Monte Carlo part of the mean's error alone"),
        "teeth": rows, "summary": summary,
    })
    click.echo(f"{len(rows)} teeth, {method} {branching}/{depth}: SOV summed mean {summary['sov_sum_mean']:.3f} "
               f"+/- {summary['sov_sum_sem']:.3f} "
               f"({summary['sov_sum_min']:.3f}-{summary['sov_sum_max']:.3f}), union mean {summary['sov_union_mean']:.3f}, "
               f"surface coverage min {summary['surface_coverage_min']:.4%}, build {summary['build_s_total']:.1f} s -> {out_file}")
