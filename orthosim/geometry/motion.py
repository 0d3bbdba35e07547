"""How a tooth moves between the two ends of a step, and how far that motion strays from a straight line.

The continuous detector and its exact ground truth must agree on the motion between the poses at
t = 0 and t = 1, because two different interpolations of the same end poses sweep different
volumes. orthosim uses, for every tooth:

    translation of the local origin: linear, p(t) = p0 + t (p1 - p0)
    rotation: constant angular velocity about the local origin (the CEJ centre on the long axis),
        R(t) = exp(t log(R1 R0^T)) R0, the shortest rotation (angle in [0, pi]) scaled by t.

A point x of the tooth (local frame) is at X(t) = R(t) x + p(t). The paper's continuous test
interpolates sphere centres along the chord X(0) -> X(1); the true path leaves the chord when the
tooth rotates. With v = x (its distance from the local origin |x| = rho) the deviation
d(t) = X(t) - [(1 - t) X(0) + t X(1)] vanishes at both ends and |d''(t)| = theta^2 rho_perp <=
theta^2 rho, so |d(t)| <= theta^2 rho t (1 - t) / 2 <= theta^2 rho / 8 (and always <= 2 rho).
Inflating a sphere of centre x by that bound makes the chord test conservative.
"""

from __future__ import annotations

import numpy as np


def rotation_vector(T0: np.ndarray, T1: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vector (radians, arch frame) of R1 R0^T, angle in [0, pi]. T: (..., 4, 4).

    Within 1e-6 rad of a half turn, where the axis's sign is not fixed by the matrix, the axis is
    taken from the largest column of R + I, oriented to a non-negative largest component: any
    fixed choice is valid as long as the detector and its ground truth share it (both call this).
    """
    T0 = np.asarray(T0, float)
    T1 = np.asarray(T1, float)
    R = np.einsum("...ij,...kj->...ik", T1[..., :3, :3], T0[..., :3, :3])
    theta = rotation_angle(T0, T1)
    skew = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    sin = np.sin(theta)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(theta < 1e-8, 0.5, theta / (2.0 * sin))
    w = skew * scale[..., None]
    near_pi = np.pi - theta < 1e-6
    if np.any(near_pi):
        S = R[near_pi] + np.eye(3)
        cols = np.linalg.norm(S, axis=-2)  # norms of the columns
        k = np.argmax(cols, axis=-1)
        axis = np.take_along_axis(S, k[:, None, None], axis=-1)[..., 0] / cols[np.arange(len(k)), k][:, None]
        big = np.take_along_axis(axis, np.argmax(np.abs(axis), axis=-1)[:, None], axis=-1)
        axis = axis * np.where(big < 0, -1.0, 1.0)
        w[near_pi] = axis * theta[near_pi][:, None]
    return w


def rotation_matrix(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation of each rotation vector w (..., 3) (radians), by Rodrigues' formula."""
    w = np.asarray(w, float)
    theta = np.linalg.norm(w, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(theta[..., None] > 1e-12, w / theta[..., None], 0.0)
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    s, c = np.sin(theta)[..., None, None], np.cos(theta)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def rotation_angle(T0: np.ndarray, T1: np.ndarray) -> np.ndarray:
    """(...,) radians turned between the two poses, in [0, pi].

    atan2(|skew part| / 2, (trace - 1) / 2) of R1 R0^T: accurate for tiny turns and near half a
    turn alike (acos or asin alone lose half the digits at one end).
    """
    T0 = np.asarray(T0, float)
    T1 = np.asarray(T1, float)
    R = np.einsum("...ij,...kj->...ik", T1[..., :3, :3], T0[..., :3, :3])
    sx, sy, sz = R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]
    sin2 = np.sqrt(sx * sx + sy * sy + sz * sz)
    cos2 = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0
    return np.arctan2(sin2, cos2)


def interpolate_pose(T0: np.ndarray, T1: np.ndarray, t: float | np.ndarray) -> np.ndarray:
    """Pose(s) at time t in [0, 1] of the step from T0 to T1 (both (4, 4)); returns (4, 4) or (n, 4, 4)."""
    T0 = np.asarray(T0, float)
    T1 = np.asarray(T1, float)
    return _pose_at(T0, T1, rotation_vector(T0, T1), t)


class PosePath:
    """One tooth's motion over a step, T0 -> T1 (4, 4), asked for its pose at many times.

    `at(t)` is `interpolate_pose(T0, T1, t)`, the same arithmetic, with the rotation vector found
    once, at the first time after 0 asked for, instead of at every call (conservative advancement
    asks for a pose per stride, and often only for t = 0, where the pose is T0 itself: the
    arithmetic multiplies T0 by an identity and adds zeros).
    """

    def __init__(self, T0: np.ndarray, T1: np.ndarray):
        self.T0 = np.asarray(T0, float)
        self.T1 = np.asarray(T1, float)
        self._w: np.ndarray | None = None

    @property
    def w(self) -> np.ndarray:
        """(3,) the step's rotation vector (radians)."""
        if self._w is None:
            self._w = rotation_vector(self.T0, self.T1)
        return self._w

    def at(self, t: float | np.ndarray) -> np.ndarray:
        if np.ndim(t) == 0 and t == 0.0:
            return self.T0.copy()
        return _pose_at(self.T0, self.T1, self.w, t)


def _pose_at(T0: np.ndarray, T1: np.ndarray, w: np.ndarray, t: float | np.ndarray) -> np.ndarray:
    """`interpolate_pose` given the step's rotation vector w (3,) (radians)."""
    ts = np.atleast_1d(np.asarray(t, float))
    R = rotation_matrix(ts[:, None] * w[None, :]) @ T0[:3, :3]
    out = np.tile(np.eye(4), (len(ts), 1, 1))
    out[:, :3, :3] = R
    out[:, :3, 3] = T0[:3, 3] + ts[:, None] * (T1[:3, 3] - T0[:3, 3])
    return out[0] if np.ndim(t) == 0 else out


def chord_deviation_bound(theta: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """mm: largest distance between a point's true path and its chord over the step.

    theta: (...,) radians turned in the step; rho: (...,) mm, the point's distance from the local
    origin. Returns rho * min(theta^2 / 8, 2) (see module docstring).
    """
    theta = np.asarray(theta, float)
    return np.asarray(rho, float) * np.minimum(theta * theta / 8.0, 2.0)


def max_speed(T0: np.ndarray, T1: np.ndarray, rho_max: float, angle: float | None = None) -> float:
    """mm per unit step time: bound on the speed of any point within rho_max of the local origin
    (angle: `rotation_angle(T0, T1)` when the caller has it)."""
    theta = float(rotation_angle(T0, T1)) if angle is None else float(angle)
    return float(np.linalg.norm(np.asarray(T1)[:3, 3] - np.asarray(T0)[:3, 3]) + theta * rho_max)


def relative_speed_bound(T0a: np.ndarray, T1a: np.ndarray, rho_a: float,
                         T0b: np.ndarray, T1b: np.ndarray, rho_b: float,
                         angles: tuple[float, float] | None = None) -> float:
    """mm per unit step time: bound on how fast the distance between two moving bodies can shrink.

    A point of body a moves at v_a + w_a x r (v_a its origin's constant velocity, |w_a| = theta_a,
    |r| <= rho_a), likewise for b, so any two points approach at most at
    |v_a - v_b| + theta_a rho_a + theta_b rho_b. Unlike the sum of the two bodies' own speeds, this
    is near zero for teeth translating together, so conservative advancement takes full strides
    instead of crawling. angles: (theta_a, theta_b), `rotation_angle` of the two motions, when the
    caller has them.
    """
    dv = (np.asarray(T1a)[:3, 3] - np.asarray(T0a)[:3, 3]) - (np.asarray(T1b)[:3, 3] - np.asarray(T0b)[:3, 3])
    theta_a, theta_b = angles if angles is not None else (rotation_angle(T0a, T1a), rotation_angle(T0b, T1b))
    return float(np.linalg.norm(dv) + theta_a * rho_a + theta_b * rho_b)


def interpolate_poses(T0: np.ndarray, T1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(m, 4, 4) poses of m bodies, each at its own time t (m,), stepping from T0 to T1 (m, 4, 4)."""
    T0 = np.asarray(T0, float)
    T1 = np.asarray(T1, float)
    t = np.asarray(t, float)
    w = rotation_vector(T0, T1)
    out = np.tile(np.eye(4), (len(t), 1, 1))
    out[:, :3, :3] = rotation_matrix(t[:, None] * w) @ T0[:, :3, :3]
    out[:, :3, 3] = T0[:, :3, 3] + t[:, None] * (T1[:, :3, 3] - T0[:, :3, 3])
    return out
