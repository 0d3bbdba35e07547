"""Geometry shared by the dental model and collision detection, with no detector behind it.

`pose` (4x4 poses, rotations about an axis). `motion`: how a tooth moves between the two ends of a
step (numpy only, for the drawing side as well as the detectors). `meshquery`: exact queries on
triangle meshes through python-fcl (BVH objects, poses, intersection, distance) and the vertex-based
interpenetration depth. `signeddistance`: the signed distance from points to a closed mesh (closest
points on a hierarchy of its faces, the pseudonormals' sign), which the distance map, the bite's
closure and `penetration` ask (numba; imported on demand). `penetration`: the interpenetration depth
on every point of the triangles and by the largest ball inside both meshes, and the cheaper one on
vertices and edges a simulation step asks (numba; imported on demand). `meshcut` (a mesh cut by a
plane), `meshrefine` (a coarse mesh subdivided where detail is needed), `lazymesh` (a mesh held as
its two arrays, its trimesh made on first use: what the dentition cache hands out, so that a run's
first step never imports trimesh).
"""
