"""Geometry shared by the dental model and collision detection, with no detector behind it.

`meshquery`: exact queries on triangle meshes through python-fcl (BVH objects, poses, intersection,
distance) and the vertex-based interpenetration depth.
"""
