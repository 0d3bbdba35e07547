"""Sphere trees of teeth: the bounding-volume hierarchy the sphere-tree collision detectors descend.

`tree` (`SphereTree`, the data layout), `build` (`build_sphere_tree`: the octree or the optimising
builder), `fit` (the optimising fit of a node's spheres), `enclose` (minimal enclosing spheres),
`inside` (which points lie inside the mesh), `outside_band` (the outside-volume score, compiled),
`octree` (the paper's octree builder), `fitcache` (fits kept on disk), `cache` (`cached_sphere_tree`,
`cached_sphere_trees` for many meshes over every core), `sph` (`read_sph` / `write_sph`: Bradshaw's
Sphere-Tree Construction Toolkit format), `measure` (`measure_tree`: the paper's sphere outside
volume and the coverage).
"""

from orthosim.spheretree.build import build_sphere_tree
from orthosim.spheretree.cache import cached_sphere_tree, cached_sphere_trees
from orthosim.spheretree.measure import FitReport, measure_tree
from orthosim.spheretree.sph import read_sph, write_sph
from orthosim.spheretree.tree import SphereTree

__all__ = ["SphereTree", "build_sphere_tree", "cached_sphere_tree", "cached_sphere_trees", "measure_tree", "FitReport", "read_sph", "write_sph"]
