"""Which pseudo views to densify from: few, and seeing different things.

Views that overlap a lot add the same points twice, so the densification keeps a subset with low
inter-frame covisibility, chosen by farthest-point sampling on a pose distance that mixes translation
and rotation (SYN3R's key-frame choice):

    D(a, b) = 1 - exp(-|c_a - c_b| / translation_scale) * exp(-rotation_weight * angle(R_a, R_b))

with c the camera centres and the angle in radians. D is 0 for equal poses and tends to 1 as the
cameras move apart or turn away; ``translation_scale`` is the distance (world units) at which
translation alone gives 1 - 1/e (SYN3R: 1).

    keep = select_views(viewmats, 4)                      # indices of 4 mutually distant poses
    keep = select_views(viewmats, 4, fixed=[0, 12])       # continue from poses already chosen
    nbrs = neighbour_views(viewmats, 3)                   # [V, 3] closest poses: stereo partners

Poses are world-to-camera 4x4 matrices (numpy or torch, [V, 4, 4]).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from warpgs.geometry import as_viewmats as _as_numpy
from warpgs.geometry import camera_centres


def rotation_angles(viewmats_a, viewmats_b=None) -> np.ndarray:
    """[A, B] angle (radians) of the relative rotation between every pair of poses."""
    a = _as_numpy(viewmats_a)[:, :3, :3]
    b = a if viewmats_b is None else _as_numpy(viewmats_b)[:, :3, :3]
    tr = np.einsum("aij,bij->ab", a, b)  # trace(R_a R_b^T)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def pose_distance(viewmats_a, viewmats_b=None, translation_scale: float = 1.0, rotation_weight: float = 1.0) -> np.ndarray:
    """[A, B] pose distance D (see the module docstring) between the poses of a and b (b = a if None)."""
    if translation_scale <= 0:
        raise ValueError(f"translation_scale must be positive, got {translation_scale}")
    ca = camera_centres(viewmats_a)
    cb = ca if viewmats_b is None else camera_centres(viewmats_b)
    dt = np.linalg.norm(ca[:, None] - cb[None], axis=-1)
    ang = rotation_angles(viewmats_a, viewmats_b)
    return 1.0 - np.exp(-dt / translation_scale) * np.exp(-rotation_weight * ang)


def farthest_point_sampling(dist: np.ndarray, k: int, fixed: Sequence[int] = (), first: int = 0) -> list[int]:
    """Greedy max-min selection of ``k`` new indices on a symmetric distance matrix: each pick is the
    item farthest from everything chosen so far (``fixed`` counts as chosen, and is not returned).
    Without ``fixed`` the first pick is ``first``. Ties go to the lowest index."""
    d = np.asarray(dist, dtype=np.float64)
    n = d.shape[0]
    if d.shape != (n, n):
        raise ValueError(f"distance matrix must be square, got {d.shape}")
    fixed = [int(f) for f in fixed]
    if any(not 0 <= f < n for f in fixed):
        raise ValueError(f"fixed indices {fixed} out of range for {n} items")
    k = min(int(k), n - len(set(fixed)))
    if k <= 0:
        return []
    chosen: list[int] = []
    if fixed:
        mind = d[fixed].min(axis=0)
    else:
        chosen.append(int(first))
        mind = d[first].copy()
    mind[fixed] = -np.inf
    if chosen:
        mind[chosen] = -np.inf
    while len(chosen) < k:
        nxt = int(np.argmax(mind))
        chosen.append(nxt)
        mind = np.minimum(mind, d[nxt])
        mind[nxt] = -np.inf
    return chosen


def select_views(viewmats, k: int, fixed: Sequence[int] = (), translation_scale: float = 1.0,
                 rotation_weight: float = 1.0, first: int = 0) -> list[int]:
    """Indices of ``k`` poses with low covisibility: farthest-point sampling on ``pose_distance``."""
    d = pose_distance(viewmats, translation_scale=translation_scale, rotation_weight=rotation_weight)
    return farthest_point_sampling(d, k, fixed, first)


def neighbour_views(viewmats, m: int, translation_scale: float = 1.0, rotation_weight: float = 1.0,
                    candidates: Sequence[int] | None = None) -> np.ndarray:
    """[V, m] for every pose, the ``m`` closest other poses (among ``candidates``, default all) by
    ``pose_distance``, closest first: the source views a reference is matched against."""
    v = _as_numpy(viewmats)
    d = pose_distance(v, translation_scale=translation_scale, rotation_weight=rotation_weight)
    pool = np.arange(len(v)) if candidates is None else np.asarray(candidates, dtype=np.int64)
    out = np.zeros((len(v), m), dtype=np.int64)
    for i in range(len(v)):
        others = pool[pool != i]
        if len(others) < m:
            raise ValueError(f"view {i} has {len(others)} candidate neighbours, {m} asked for")
        order = np.argsort(d[i, others], kind="stable")[:m]
        out[i] = others[order]
    return out
