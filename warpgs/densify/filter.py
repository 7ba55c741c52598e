"""Clean a fused stereo cloud with open3d: optional voxel downsampling, then statistical outlier removal.

    out = filter_cloud(points, colors)                       # nb_neighbors 20, std_ratio 2.0, no voxels
    out = filter_cloud(points, colors, FilterConfig(voxel=0.02))
    out.points, out.colors        survivors (voxel means when downsampled)
    out.kept, out.removed         [N] bool over the input points (a point shares its voxel's fate)
    out.index                     [N] int64 row of out.points that holds each input point, -1 if removed

Statistical outlier removal (open3d ``remove_statistical_outlier``): a point is an outlier when its
mean distance to its ``nb_neighbors`` nearest neighbours exceeds the cloud's mean of that quantity by
more than ``std_ratio`` standard deviations. Voxel downsampling (``voxel_down_sample_and_trace``)
averages the points and colours of each cubic cell ``voxel`` wide, which evens out the density before
the statistics (SYN3R downsamples first, too). Torch inputs give torch outputs on their device;
numpy gives numpy. open3d is imported only when a filter runs.

``filter_cloud`` runs open3d in a child process (``warpgs.densify.native``) on the finite points only: a child
that dies (open3d aborts on inputs its C++ did not expect), hangs past ``FILTER_TIMEOUT_S`` or leaves no result
costs one warning line, and the cloud is kept unfiltered (every finite point kept); ``out.failure`` holds the line
(None when the filter ran).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import numpy as np

from .native import NativeStepFailed, run_native

FILTER_TIMEOUT_S = 600.0  # the child process of a filter is stopped after this long


@dataclass
class FilterConfig:
    nb_neighbors: int = 20  # neighbours whose mean distance is scored
    std_ratio: float = 2.0  # outlier: score > mean + std_ratio * std
    voxel: float | None = None  # voxel size for downsampling first; None or 0: off

    LIMITS = {"nb_neighbors": ">= 1", "std_ratio": "> 0", "voxel": ">= 0"}


class FilterResult(NamedTuple):
    points: Any  # [M, 3]
    colors: Any  # [M, C] or None
    kept: Any  # [N] bool over the input
    removed: Any  # [N] bool over the input (= ~kept)
    index: Any  # [N] int64 output row of each input point, -1 where removed
    failure: str | None = None  # the line of a filter whose child process failed (the cloud is then unfiltered)


def _to_numpy(a):
    if a is None:
        return None
    if hasattr(a, "detach"):
        return a.detach().cpu().numpy()
    return np.asarray(a)


def statistical_outliers(points, nb_neighbors: int = 20, std_ratio: float = 2.0) -> np.ndarray:
    """[N] bool numpy mask of the points open3d's statistical outlier removal keeps."""
    import open3d as o3d

    p = np.ascontiguousarray(_to_numpy(points), dtype=np.float64).reshape(-1, 3)
    if nb_neighbors < 1 or std_ratio <= 0:
        raise ValueError(f"nb_neighbors must be >= 1 and std_ratio > 0, got {nb_neighbors} and {std_ratio}")
    keep = np.ones(len(p), dtype=bool)
    if len(p) <= nb_neighbors:  # too few points for the statistic: keep them all
        return keep
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    _, ind = pcd.remove_statistical_outlier(nb_neighbors=int(nb_neighbors), std_ratio=float(std_ratio))
    keep[:] = False
    keep[np.asarray(ind, dtype=np.int64)] = True
    return keep


def voxel_downsample(points, colors=None, voxel: float = 0.01) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """(points [M, 3], colors [M, C] or None, index [N]): open3d's voxel means and, for every input
    point, the row of its voxel."""
    import open3d as o3d

    if not voxel > 0:
        raise ValueError(f"voxel size must be positive, got {voxel}")
    p = np.ascontiguousarray(_to_numpy(points), dtype=np.float64).reshape(-1, 3)
    c = _to_numpy(colors)
    index = np.full(len(p), -1, dtype=np.int64)
    if len(p) == 0:
        return p.astype(np.float32), (None if c is None else c[:0]), index
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    lo, hi = p.min(0) - 0.5 * voxel, p.max(0) + 0.5 * voxel
    down, _, trace = pcd.voxel_down_sample_and_trace(float(voxel), lo, hi, False)
    for row, members in enumerate(trace):
        index[np.asarray(members, dtype=np.int64)] = row
    if (index < 0).any():  # pragma: no cover - open3d traces every point
        raise RuntimeError("open3d's voxel trace missed points")
    out_c = None
    if c is not None:  # mean colour per voxel (any channel count, so not through open3d)
        c = c.reshape(len(p), -1).astype(np.float64)
        sums = np.zeros((len(trace), c.shape[1]))
        np.add.at(sums, index, c)
        out_c = (sums / np.bincount(index, minlength=len(trace))[:, None]).astype(np.float32)
    return np.asarray(down.points, dtype=np.float32), out_c, index


def _downsample_and_filter(p: np.ndarray, c, voxel: float | None, nb_neighbors: int, std_ratio: float):
    """(voxel points, their colours, each point's voxel row, [M] bool kept): the open3d part of ``filter_cloud``."""
    if voxel:
        vp, vc, vindex = voxel_downsample(p, c, float(voxel))
    else:
        vp, vc, vindex = p, c, np.arange(len(p))
    return vp, vc, vindex, statistical_outliers(vp, nb_neighbors, std_ratio)


def _warn(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def filter_cloud(points, colors=None, config: FilterConfig | None = None, *, isolate: bool = True,
                 timeout_s: float = FILTER_TIMEOUT_S, log: Callable[[str], Any] = _warn) -> FilterResult:
    """Voxel downsampling (if ``config.voxel``), then statistical outlier removal; see the module doc.
    ``isolate``: open3d in a child process (False: in this one); ``log`` gets the one line of a failed child."""
    cfg = config or FilterConfig()
    if not (int(cfg.nb_neighbors) >= 1 and float(cfg.std_ratio) > 0 and (cfg.voxel is None or cfg.voxel >= 0)):
        raise ValueError(f"filter: nb_neighbors must be >= 1, std_ratio > 0 and voxel >= 0, got {cfg.nb_neighbors}, "
                         f"{cfg.std_ratio}, {cfg.voxel}")
    torch_in = hasattr(points, "detach")
    device = points.device if torch_in else None
    p = np.ascontiguousarray(_to_numpy(points), dtype=np.float32).reshape(-1, 3)
    c = _to_numpy(colors)
    if c is not None and len(c) != len(p):
        raise ValueError(f"colors has {len(c)} rows, points {len(p)}")
    finite = np.isfinite(p).all(1)
    src = np.nonzero(finite)[0]
    args = (p[src], None if c is None else c[src], cfg.voxel, int(cfg.nb_neighbors), float(cfg.std_ratio))
    failure = None
    if not isolate or len(src) == 0:
        vp, vc, vindex, keep_v = _downsample_and_filter(*args)
    else:
        try:
            vp, vc, vindex, keep_v = run_native("open3d", _downsample_and_filter, *args, timeout_s=timeout_s)
        except NativeStepFailed as e:  # the documented fallback: the cloud unfiltered
            failure = f"outlier filter: {e}; the cloud is kept unfiltered"
            log(f"warpgs: {failure}")
            vp, vc, vindex, keep_v = args[0], args[1], np.arange(len(src)), np.ones(len(src), dtype=bool)
    new_row = np.cumsum(keep_v) - 1
    index = np.full(len(p), -1, dtype=np.int64)
    index[src] = np.where(keep_v[vindex], new_row[vindex], -1)
    kept = index >= 0
    out_p = vp[keep_v].astype(np.float32)
    out_c = None if vc is None else vc[keep_v]
    if torch_in:
        import torch

        t = lambda a, dt=None: None if a is None else torch.as_tensor(np.ascontiguousarray(a), device=device, dtype=dt)  # noqa: E731
        return FilterResult(t(out_p), t(out_c, torch.float32), t(kept), t(~kept), t(index), failure)
    return FilterResult(out_p, out_c, kept, ~kept, index, failure)
