"""Length of one small vector, the number `np.linalg.norm` gives, without its per-call overhead.

`np.linalg.norm(v)` of a 1-D float vector is sqrt(v.dot(v)); for a 3-vector its argument checks
cost ten times the arithmetic, and a step asks for a few hundred lengths. Same dot, same
correctly rounded square root: the same bits.
"""

from __future__ import annotations

import math

import numpy as np


def length(v) -> float:
    """|v| of a 1-D vector (as `float(np.linalg.norm(v))`)."""
    v = np.asarray(v, float)
    return math.sqrt(v.dot(v))
