"""Sphere trees of teeth: the bounding-volume hierarchy the sphere-tree collision detectors descend.

`SphereTree` (tree.py) is the data layout; `build_sphere_tree` builds one with the octree or the
optimising builder; `cached_sphere_tree` does the same through an on-disk cache, `cached_sphere_trees` for many
meshes at once over every core; `read_sph` /
`write_sph` exchange trees with Bradshaw's Sphere-Tree Construction Toolkit; `measure_tree` gives
the paper's error figures (sphere outside volume) and coverage.
"""

from orthosim.spheretree.build import build_sphere_tree
from orthosim.spheretree.cache import cached_sphere_tree, cached_sphere_trees
from orthosim.spheretree.measure import FitReport, measure_tree
from orthosim.spheretree.sph import read_sph, write_sph
from orthosim.spheretree.tree import SphereTree

__all__ = ["SphereTree", "build_sphere_tree", "cached_sphere_tree", "cached_sphere_trees", "measure_tree", "FitReport", "read_sph", "write_sph"]
