"""Pose helpers shared by every part (numpy, float64): camera centres, quaternions (w, x, y, z), slerp,
axis-angle rotations, poses from a rotation and a centre; and the inverse of small torch matrices (``small_inv``).
Poses are world-to-camera 4x4 matrices in OpenCV axes (``warpgs/__init__.py``)."""

from __future__ import annotations

import numpy as np


def as_viewmats(viewmats) -> np.ndarray:
    """[V, 4, 4] float64 numpy from numpy or torch world-to-camera matrices."""
    if hasattr(viewmats, "detach"):
        viewmats = viewmats.detach().cpu().numpy()
    v = np.asarray(viewmats, dtype=np.float64)
    if v.ndim != 3 or v.shape[1:] != (4, 4):
        raise ValueError(f"viewmats must be [V, 4, 4], got {v.shape}")
    return v


def camera_centres(viewmats) -> np.ndarray:
    """Camera centres -R^T t of world-to-camera matrices (..., 4, 4) -> (..., 3); numpy or torch."""
    if hasattr(viewmats, "detach"):
        viewmats = viewmats.detach().cpu().numpy()
    V = np.asarray(viewmats, np.float64)
    R, t = V[..., :3, :3], V[..., :3, 3]
    return -np.einsum("...ji,...j->...i", R, t)


def rotmat_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) -> unit quaternion (w, x, y, z) with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions along the shorter arc, s in [0, 1]."""
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    d = float(np.dot(q0, q1))
    if d < 0.0:  # q and -q are one rotation: take the shorter way round
        q1, d = -q1, -d
    if d > 1.0 - 1e-10:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    return (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / np.sin(theta)


def axis_angle_to_rotmat(v: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vector (axis * angle in radians) -> (3, 3)."""
    v = np.asarray(v, np.float64)
    a = np.linalg.norm(v)
    if a < 1e-12:
        return np.eye(3)
    k = v / a
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * Kx + (1 - np.cos(a)) * Kx @ Kx


def pose(R_c2w: np.ndarray, center: np.ndarray) -> np.ndarray:
    """World-to-camera 4x4 from a camera-to-world rotation and a camera centre."""
    V = np.eye(4)
    V[:3, :3] = R_c2w.T
    V[:3, 3] = -R_c2w.T @ np.asarray(center, np.float64)
    return V


def small_inv(m):
    """``torch.linalg.inv`` of small matrices (cameras' 3x3 / 4x4, batched or not) computed on the CPU and returned
    on ``m``'s device in ``m``'s dtype: on CUDA it needs a cuSOLVER handle, whose creation failed in a GPU shared
    by 12 runs (CUSOLVER_STATUS_INTERNAL_ERROR), and a 4x4 gains nothing from the GPU."""
    import torch

    return torch.linalg.inv(m.cpu()).to(m.device)


__all__ = ["as_viewmats", "axis_angle_to_rotmat", "camera_centres", "pose", "quat_to_rotmat", "rotmat_to_quat", "slerp", "small_inv"]

