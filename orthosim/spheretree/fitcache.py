"""How well each tooth's sphere tree fits it (summed SOV, coverage), measured once and kept on disk.

`measure_tree` samples hundreds of thousands of points (seconds a tooth); a report that shows the
fit of every tooth of three cases would spend most of its time there, always on the same teeth.
The figures depend only on the mesh, the tree request and the sample counts, so they are stored as
a small JSON beside the tree cache (`<cache>/../treefits/`), keyed like the tree itself: a mesh
and its mirror image share one entry (the mirror's tree is the mirror of the tree, so its SOV and
coverage are the same quantities; the stored estimate is the first side's).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from orthosim.storage.atomic import write_json
from orthosim.spheretree.build import DEPTH, default_branching
from orthosim.spheretree.cache import _entry, cached_sphere_tree, default_cache_dir
from orthosim.spheretree.measure import FitReport, measure_tree

# Fewer samples than `orthosim spheretree eval`'s defaults: the summed SOV's standard error is
# about 0.007 at these counts (against 0.0025), enough for a table; the figure carries it.
REPORT_SAMPLES = {"sphere_samples": 40_000, "n_surface": 20_000, "n_interior": 10_000}


def fits_dir(cache_dir: str | Path | None = None) -> Path:
    trees = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return trees.parent / "treefits"


def cached_fit(mesh, method: str = "fit", branching: int | None = None, depth: int = DEPTH, cache_dir: str | Path | None = None,
               samples: dict | None = None) -> FitReport:
    """The FitReport of `mesh`'s cached sphere tree, from disk when measured before."""
    branching = default_branching(method, branching)
    samples = dict(REPORT_SAMPLES if samples is None else samples)
    entry = _entry(mesh, method, branching, depth, default_cache_dir() if cache_dir is None else Path(cache_dir))
    tag = "-".join(str(samples[k]) for k in sorted(samples))
    path = fits_dir(cache_dir) / f"{entry.path.stem}-{tag}.json"
    try:
        return FitReport(**json.loads(path.read_text()))
    except (OSError, ValueError, TypeError):
        pass  # absent or damaged: measure again and overwrite
    tree = cached_sphere_tree(mesh, method, branching, depth, cache_dir)
    report = measure_tree(tree, mesh.vertices, mesh.faces, seed=0, **samples)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, dataclasses.asdict(report))
    except OSError:
        pass  # a read-only cache costs a new measurement next time, never a failure
    return report
