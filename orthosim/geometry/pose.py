"""Rigid poses as 4x4 homogeneous matrices (local -> arch frame, millimetres) and small helpers."""

from __future__ import annotations

import numpy as np


def frame_pose(origin: np.ndarray, x_axis: np.ndarray, y_axis: np.ndarray) -> np.ndarray:
    """Pose whose local x and y axes point along the given directions (orthonormalised), z = x cross y."""
    y = np.asarray(y_axis, float)
    y = y / np.linalg.norm(y)
    x = np.asarray(x_axis, float)
    x = x - y * (x @ y)
    x = x / np.linalg.norm(x)
    z = np.cross(x, y)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, origin
    return T


def rotation_about_axis(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """3x3 rotation by `angle_rad` about the unit vector `axis` (Rodrigues)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * K + (1 - np.cos(angle_rad)) * (K @ K)


def translation(offset: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = offset
    return T


def is_rigid(T: np.ndarray, tol: float = 1e-6) -> bool:
    R = T[:3, :3]
    return bool(np.allclose(R.T @ R, np.eye(3), atol=tol) and abs(np.linalg.det(R) - 1) < tol)
