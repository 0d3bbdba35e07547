"""What a sphere-tree request means when it leaves the branching out, in a module with no builder
behind it: loading a cached tree computes the same cache key as building one (`spheretree.cache`),
and a run that only loads its trees should not import the optimising builder (numba, scipy).

The optimising builder's branching when none is asked: 9 (1, 9, 81 and up to 729 leaves at depth
4). Smaller leaves leave thinner caps on the ridges and cusps teeth meet with, where the discrete
detector's false contacts come from: on real teeth, poses 0.1-0.25 mm apart read touching 17 % of
the time at 512 leaves (branching 8), 6-10 % at 729 (DEVELOPERS.md, "9-ary trees by default").
"""

FIT_BRANCHING = 9
