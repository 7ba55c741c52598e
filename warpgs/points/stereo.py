"""Dense initial points from the training views alone: Warp plane-sweep stereo between neighbouring
inputs, fused into one cloud and cleaned with open3d's statistical outlier removal.

    pts = stereo_points(cameras, StereoInitOptions(), depth_range=(near, far))   # or depth_range=None

The views are downsampled to at most ``max_width`` pixels wide first (the sweep costs planes x pixels
x sources x patch taps; Warp's CPU backend runs it on one thread). Every training view is a reference,
matched against its ``neighbours`` closest training views (``warpgs.densify.select.neighbour_views``),
and a pixel survives only when its depth agrees with a neighbour's (forward-backward reprojection).

Without a depth range (no SfM points), the first pass sweeps the range the cameras can resolve at
all: for each view and its nearest neighbour with baseline b and focal length f, disparities from
``max_disparity`` x width down to ``min_disparity`` pixels, i.e. depths f b / (max_disparity W) ..
f b / min_disparity. A second pass sweeps again between percentiles of the first pass's confident
depths, with the same number of planes over that much narrower range.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

# warpgs.densify is imported where used: warpgs.config builds on these option classes, and warpgs.densify
# reads its own config through warpgs.config


@dataclass
class StereoInitOptions:
    max_width: int = 256  # views are downsampled (box filter) to at most this width for the sweep on the CPU ...
    max_width_cuda: int = 512  # ... and on a GPU, where the sweep takes milliseconds
    coarse_factor: int = 2  # the first pass (no depth range given) runs this much smaller again
    planes: int = 64  # depth hypotheses per pass, uniform in inverse depth
    neighbours: int = 2  # training views each reference is matched against (closest poses)
    top_k: int = 1  # best source costs averaged per plane (1: the best; occlusion-robust with few views)
    patch_radius: int = 2  # NCC patch of (2 r + 1)^2 taps
    min_score: float = 0.6  # NCC of a confident pixel
    min_texture: float = 0.02  # grey std below which a patch gets no estimate
    consistency_px: float = 1.5  # forward-backward reprojection bound, pixels (at the downsampled size)
    consistency_depth: float = 0.02  # relative depth bound of that check
    min_consistent: int = 1  # neighbours whose depth must agree
    min_angle: float = 0.0  # degrees: neighbours that see a point under a smaller triangulation angle do not count
    min_disparity: float = 0.5  # first pass without a depth range: the farthest depth resolved (pixels)
    max_disparity: float = 1.0  # ... and the nearest (fraction of the image width)
    refine_low: float = 1.0  # second pass: the range between these depth percentiles of the first pass ...
    refine_high: float = 99.0
    refine_margin: float = 0.25  # ... widened by this fraction on each side (near x (1 - m), far x (1 + m))
    sgm_paths: int = 0  # semi-global matching of the cost volume along this many directions (0: off; densify.stereo)
    sgm_p1: float = 0.05
    sgm_p2: float = 0.4
    filter_neighbors: int = 20  # open3d statistical outlier removal of the fused cloud
    filter_std_ratio: float = 2.0

    LIMITS = {"min_angle": "[0, 90)", "sgm_paths": "[0, 4]", "sgm_p1": ">= 0", "sgm_p2": ">= 0"}


@dataclass
class StereoPoints:
    xyz: np.ndarray  # (N, 3) float32 world
    rgb: np.ndarray  # (N, 3) float32 in [0, 1]
    depth_range: tuple[float, float]  # the range of the last sweep
    stats: dict


def _downsampled(cameras, max_width: int, device):
    """images [V, h, w, 3], Ks [V, 3, 3], viewmats [V, 4, 4] at the sweep's size (one size for all)."""
    w0, h0 = cameras[0].width, cameras[0].height
    f = max(1, int(np.ceil(w0 / max_width)))
    w, h = w0 // f, h0 // f
    imgs, Ks = [], []
    for c in cameras:
        img = torch.as_tensor(np.asarray(c.image), dtype=torch.float32)
        if (c.width, c.height) != (w0, h0):
            raise ValueError(f"stereo init: view {c.name} is {c.width}x{c.height}, the first view {w0}x{h0}; "
                             "the training views must share one size")
        if f > 1:
            img = F.avg_pool2d(img[: h * f, : w * f].permute(2, 0, 1)[None], f)[0].permute(1, 2, 0)
        imgs.append(img)
        K = np.asarray(c.K, np.float64).copy()
        K[:2] /= f  # pixel centres: (j + 0.5) f = original (j' + 0.5) for j' = j f + (f - 1) / 2
        Ks.append(K)
    images = torch.stack(imgs).contiguous().to(device)
    Ks_t = torch.as_tensor(np.stack(Ks), dtype=torch.float32, device=device)
    V = torch.as_tensor(np.stack([np.asarray(c.viewmat, np.float32) for c in cameras]), device=device)
    return images, Ks_t, V


def resolvable_depth_range(Ks: np.ndarray, viewmats: np.ndarray, width: int, min_disparity: float,
                           max_disparity: float) -> tuple[float, float]:
    """Depths that the cameras' baselines can resolve: for each view and its nearest other view,
    f b / (max_disparity W) .. f b / min_disparity; the union over the views."""
    c = np.stack([-(V[:3, :3].T @ V[:3, 3]) for V in np.asarray(viewmats, np.float64)])
    d = np.linalg.norm(c[:, None] - c[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    b = d.min(1)
    f = np.asarray(Ks, np.float64)[:, 0, 0]
    near = float(np.min(f * b / (max_disparity * width)))
    far = float(np.max(f * b / min_disparity))
    if not (np.isfinite(near) and np.isfinite(far) and 0 < near < far):
        raise ValueError("stereo init: the training cameras have no baseline (all centres coincide)")
    return near, far


def _sweep(images, Ks, V, depth_range, opts: StereoInitOptions, nb):
    from warpgs.densify.stereo import StereoConfig, stereo_point_cloud

    cfg = StereoConfig(planes=opts.planes, patch_radius=opts.patch_radius, neighbours=nb.shape[1],
                       top_k=min(opts.top_k, nb.shape[1]), min_texture=opts.min_texture, min_score=opts.min_score,
                       consistency_px=opts.consistency_px, consistency_depth=opts.consistency_depth,
                       min_consistent=opts.min_consistent, min_angle=opts.min_angle, sgm_paths=opts.sgm_paths,
                       sgm_p1=opts.sgm_p1, sgm_p2=opts.sgm_p2)
    return stereo_point_cloud(images, Ks, V, depth_range, cfg, neighbours=nb)


def stereo_points(cameras, options: StereoInitOptions | None = None, depth_range: tuple[float, float] | None = None,
                  *, extend_far: bool = False, device=None, log=None) -> StereoPoints:
    """The fused, cleaned cloud of plane-sweep stereo between the ``cameras`` (warpgs ``Camera``s);
    ``depth_range`` None: two passes, the first over the resolvable range (module docstring).
    ``extend_far``: ``depth_range`` was measured on too few points to trust its far end (SfM's
    triangulation-angle test drops distant points first): the first pass runs as well, and the sweep
    goes from ``depth_range``'s near to the farther of the two far ends."""
    from warpgs.densify.select import neighbour_views

    opts = options or StereoInitOptions()
    if len(cameras) < 2:
        raise ValueError(f"stereo init needs at least 2 training views, got {len(cameras)}")
    t0 = time.perf_counter()
    device = torch.device(device or "cpu")
    width = opts.max_width_cuda if device.type == "cuda" else opts.max_width
    images, Ks, V = _downsampled(cameras, width, device)
    nb = neighbour_views(V.cpu(), min(opts.neighbours, len(cameras) - 1))
    passes = []
    if depth_range is None or extend_far:
        c_images, c_Ks, _ = _downsampled(cameras, max(32, width // max(1, opts.coarse_factor)), device)
        rng = resolvable_depth_range(c_Ks.cpu().numpy(), V.cpu().numpy(), c_images.shape[2], opts.min_disparity,
                                     opts.max_disparity)
        res = _sweep(c_images, c_Ks, V, rng, opts, nb)
        z = res.depth[res.mask]
        passes.append({"depth_range": rng, "points": int(z.numel())})
        if z.numel() >= 100 and depth_range is None:
            lo, hi = np.percentile(z.cpu().numpy(), [opts.refine_low, opts.refine_high])
            depth_range = (float(lo) * (1 - opts.refine_margin), float(hi) * (1 + opts.refine_margin))
        elif z.numel() >= 100:  # extend_far: keep the given near end
            far = float(np.percentile(z.cpu().numpy(), opts.refine_high)) * (1 + opts.refine_margin)
            depth_range = (depth_range[0], max(depth_range[1], far))
        elif depth_range is None:
            return _finish(res, rng, passes, opts, t0)
    res = _sweep(images, Ks, V, depth_range, opts, nb)
    passes.append({"depth_range": tuple(map(float, depth_range)), "points": int(res.mask.sum())})
    return _finish(res, depth_range, passes, opts, t0)


def _finish(res, depth_range, passes, opts: StereoInitOptions, t0: float) -> StereoPoints:
    from warpgs.densify.filter import FilterConfig, filter_cloud

    pts, cols = res.cloud.points, res.cloud.colors
    flt = filter_cloud(pts.cpu(), cols.cpu(), FilterConfig(opts.filter_neighbors, opts.filter_std_ratio)) if len(pts) else None
    xyz = np.zeros((0, 3), np.float32) if flt is None else np.asarray(flt.points, np.float32)
    rgb = np.zeros((0, 3), np.float32) if flt is None else np.asarray(flt.colors, np.float32)
    stats = {"passes": passes, "matched": int(len(pts)), "after_filter": int(len(xyz)),
             "size": [int(res.depth.shape[2]), int(res.depth.shape[1])], "seconds": round(time.perf_counter() - t0, 2)}
    if flt is not None and flt.failure:
        stats["filter_failure"] = flt.failure
    return StereoPoints(xyz, rgb.clip(0, 1), tuple(map(float, depth_range)), stats)
