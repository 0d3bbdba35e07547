"""Sphere trees of teeth: the bounding-volume hierarchy the sphere-tree collision detectors descend.

`tree` (`SphereTree`, the data layout), `build` (`build_sphere_tree`: the octree or the optimising
builder), `defaults` (a request's default branching, without the builders), `fit` (the optimising
fit of a node's spheres), `enclose` (minimal enclosing spheres), `inside` (which points lie inside
the mesh), `outside_band` (the outside-volume score, compiled), `octree` (the paper's octree
builder), `fitcache` (fits kept on disk), `cache` (`cached_sphere_tree`, `cached_sphere_trees` for
many meshes over every core), `sph` (`read_sph` / `write_sph`: Bradshaw's Sphere-Tree Construction
Toolkit format), `measure` (`measure_tree`: the paper's sphere outside volume and the coverage).
"""

from orthosim.system.lazy import lazy_names

# The package's names, imported on first use (PEP 562): a run that loads its trees from the cache
# (`cache`) must not pull the optimising builder (numba, scipy) in with `orthosim.spheretree`.
_FROM = {
    "SphereTree": "orthosim.spheretree.tree", "build_sphere_tree": "orthosim.spheretree.build",
    "cached_sphere_tree": "orthosim.spheretree.cache", "cached_sphere_trees": "orthosim.spheretree.cache",
    "FitReport": "orthosim.spheretree.measure", "measure_tree": "orthosim.spheretree.measure",
    "read_sph": "orthosim.spheretree.sph", "write_sph": "orthosim.spheretree.sph",
}
__all__ = sorted(_FROM)
__getattr__ = lazy_names(__name__, _FROM)
