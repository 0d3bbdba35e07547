"""How well each tooth's sphere tree fits it (summed SOV, coverage), measured once and kept on disk.

`measure_tree` samples hundreds of thousands of points (seconds a tooth); a report that shows the
fit of every tooth of three cases would spend most of its time there, always on the same teeth.
The figures depend only on the mesh, the tree request and the sample counts, so they are stored as
a small JSON in the tree cache's `treefits/` folder, keyed like the tree itself: a mesh
and its mirror image share one entry (the mirror's tree is the mirror of the tree, so its SOV and
coverage are the same quantities; the stored estimate is the first side's). Entries are checksummed
(`orthosim.storage.cacheentry`): a damaged one is named in one warning and measured again.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from orthosim.errors import DamagedFileError
from orthosim.storage.cacheentry import DamagedEntryWarning, damaged, read_json, warn_damaged, write_json
from orthosim.spheretree.build import DEPTH, default_branching
from orthosim.spheretree.cache import _entry, cached_sphere_tree, default_cache_dir
from orthosim.spheretree.measure import FitReport, measure_tree

# Fewer samples than `orthosim spheretree eval`'s defaults: the summed SOV's standard error is
# about 0.007 at these counts (against 0.0025), enough for a table; the figure carries it.
REPORT_SAMPLES = {"sphere_samples": 40_000, "n_surface": 20_000, "n_interior": 10_000}


ENTRY_KIND = "treefit"


def _read_fit(path: Path) -> FitReport:
    """A stored FitReport, checked (`orthosim.storage.cacheentry`: checksum, key) and its numbers finite."""
    payload = read_json(path, ENTRY_KIND, path.stem)
    try:
        report = FitReport(**payload)
    except TypeError as err:
        raise damaged(path, f"does not hold a tree fit ({err})") from None
    numbers = [v for v in dataclasses.asdict(report).values() if isinstance(v, (int, float))]
    if not all(math.isfinite(v) for v in numbers):
        raise damaged(path, "holds non-finite figures")
    return report


def fits_dir(cache_dir: str | Path | None = None) -> Path:
    """Where the fits live: inside the tree cache folder (`$ORTHOSIM_CACHE/treefits` when that is set),
    never beside it, so that everything a cache keeps stays under its folder."""
    trees = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return trees / "treefits"


def cached_fit(mesh, method: str = "fit", branching: int | None = None, depth: int = DEPTH, cache_dir: str | Path | None = None,
               samples: dict | None = None) -> FitReport:
    """The FitReport of `mesh`'s cached sphere tree, from disk when measured before."""
    branching = default_branching(method, branching)
    samples = dict(REPORT_SAMPLES if samples is None else samples)
    entry = _entry(mesh, method, branching, depth, default_cache_dir() if cache_dir is None else Path(cache_dir))
    tag = "-".join(str(samples[k]) for k in sorted(samples))
    path = fits_dir(cache_dir) / f"{entry.path.stem}-{tag}.json"
    try:
        return _read_fit(path)
    except FileNotFoundError:
        pass
    except DamagedFileError as err:
        warn_damaged("tree-fit", err, DamagedEntryWarning)
    tree = cached_sphere_tree(mesh, method, branching, depth, cache_dir)
    report = measure_tree(tree, mesh.vertices, mesh.faces, seed=0, **samples)
    try:
        write_json(path, ENTRY_KIND, path.stem, dataclasses.asdict(report))
    except OSError:
        pass  # a read-only cache costs a new measurement next time, never a failure
    return report
