"""Points for what the initial geometry leaves empty in a training view (``model.init_fill``).

With 3 views of a walk-around capture, a wall that only one input sees gets no SfM or stereo point: nothing
matches it. Such pixels then render as the far field (or the background) from every novel pose, however close
to that input. ``fill_points`` places one point per empty ``stride`` x ``stride`` block of each view, on the
block's ray at the depth of the nearest block that does hold a point (a nearest-neighbour guess: right for
the rest of a facade, too near for sky behind a roof edge), coloured by the block's mean. The points come from
the training views alone.
"""

from __future__ import annotations

import numpy as np
import torch


def _block_depths(cam, xyz: np.ndarray, stride: int) -> np.ndarray:
    """(rows, cols) nearest depth of the points in each stride x stride block of ``cam``'s image (inf: none)."""
    rows, cols = cam.height // stride, cam.width // stride
    depth = np.full((rows, cols), np.inf, np.float64)
    if len(xyz):
        uv, z = cam.project(xyz)
        ok = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < cols * stride) & (uv[:, 1] < rows * stride)
        r, c = (uv[ok, 1] // stride).astype(int), (uv[ok, 0] // stride).astype(int)
        np.minimum.at(depth, (r, c), z[ok])
    return depth


def fill_points(cameras, xyz: np.ndarray, stride: int = 8, default_depth: float | None = None):
    """(xyz (M, 3), rgb (M, 3)) float32: one point per block of each camera that no point of ``xyz`` (nor a
    point filled from an earlier camera) projects into, at the depth of the nearest block that has one
    (``default_depth`` where the view holds none; no points for that view when it is None)."""
    if stride < 1:
        raise ValueError(f"model.init_fill must be >= 1 pixel (0 = off), got {stride}")
    out_xyz, out_rgb = [], []
    known = np.asarray(xyz, np.float64).reshape(-1, 3)
    for cam in cameras:
        depth = _block_depths(cam, known, stride)
        empty = ~np.isfinite(depth)
        if not empty.any():
            continue
        full = np.argwhere(~empty)  # row-major, the order of depth[~empty]
        holes = np.argwhere(empty)
        if len(full):
            d = torch.cdist(torch.from_numpy(holes.astype(np.float32)), torch.from_numpy(full.astype(np.float32)))
            z = depth[~empty][d.argmin(1).numpy()]
        elif default_depth is not None:
            z = np.full(len(holes), float(default_depth))
        else:
            continue
        u = (holes[:, 1] + 0.5) * stride
        v = (holes[:, 0] + 0.5) * stride
        rays = np.stack([u, v, np.ones_like(u)], 1) @ np.linalg.inv(np.asarray(cam.K, np.float64)).T
        c2w = np.asarray(cam.c2w, np.float64)
        pts = (rays * z[:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
        img = np.asarray(cam.image, np.float32)[: depth.shape[0] * stride, : depth.shape[1] * stride, :3]
        means = img.reshape(depth.shape[0], stride, depth.shape[1], stride, 3).mean((1, 3))
        out_xyz.append(pts)
        out_rgb.append(means[holes[:, 0], holes[:, 1]])
        known = np.concatenate([known, pts])
    if not out_xyz:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
    return np.concatenate(out_xyz).astype(np.float32), np.concatenate(out_rgb).astype(np.float32)
