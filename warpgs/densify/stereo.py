"""Dense multi-view stereo on posed views, fused into a coloured point cloud.

    res = stereo_point_cloud(images, Ks, viewmats, depth_range=(near, far))
    res.cloud.points [N, 3], res.cloud.colors [N, 3], res.cloud.confidence [N]
    res.depth [V, H, W] (fused, 0 where not confident), res.confidence [V, H, W], res.mask [V, H, W]

``images`` [V, H, W, 3] in [0, 1], ``Ks`` [V, 3, 3], ``viewmats`` [V, 4, 4] world-to-camera (the
library's convention, see ``warpgs/__init__.py``); all views share one size. Each reference view
(``references``, default all) is matched against its ``neighbours`` closest poses among all the
views (``warpgs.densify.select.neighbour_views``); those neighbours get depth maps too, for the
consistency check, but only references contribute points.

Plane sweep (default backend, Warp kernels in ``warpgs.kernels.stereo``):

1. ``planes`` fronto-parallel planes uniform in inverse depth over ``depth_range``;
2. cost = 1 - NCC of a (2 ``patch_radius`` + 1)^2 grey patch against its plane-induced warp into each
   source, the ``top_k`` best sources averaged (occlusion-robust);
3. winner-take-all, refined by a parabola through the best plane and its two neighbours; the NCC at
   the refined minimum is the pixel's photometric score. With ``sgm_paths`` the plane is picked on the
   volume aggregated by semi-global matching along image lines (smooth surfaces win over repeated
   patterns: facade windows), and the score is the raw NCC at that plane;
4. geometric consistency: the pixel goes to each neighbour at its depth, picks up the neighbour's
   depth there, comes back, and must land within ``consistency_px`` pixels with a depth within
   ``consistency_depth`` (relative); the agreeing depths are averaged (the fused depth). With
   ``min_angle`` > 0 a neighbour whose ray meets the reference's at the point under a smaller angle is
   not checked: two views a few centimetres apart agree on any depth;
5. a pixel is confident when its score >= ``min_score`` and at least ``min_consistent`` neighbours
   agree; its confidence is clamp(score, 0, 1) x agreeing / checked neighbours.

Learned backend (``backend="learned"``): a network loaded from local weights (``weights``) replaces
steps 1-3 and returns depth and a confidence per reference; steps 4-5 are the same. See
``load_stereo_network``: a ``torch.export`` (.pt2) or TorchScript archive with the ``StereoNetwork``
call signature, or a checkpoint of the built-in ``MVSNetLite`` (``save_stereo_network``). Nothing is
downloaded.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, Protocol

import numpy as np
import torch
import torch.nn.functional as F
import warp as wp
from torch import nn

from warpgs._warp import arg, device_of, launch, stream_of
from warpgs.densify.select import neighbour_views
from warpgs.geometry import small_inv
from warpgs.kernels import stereo as ks

WEIGHTS_ENV = "WARPGS_STEREO_WEIGHTS"


@dataclass
class StereoConfig:
    backend: str = "planesweep"  # planesweep | learned
    weights: str | None = None  # learned: .pt2 / TorchScript archive or MVSNetLite checkpoint; None: $WARPGS_STEREO_WEIGHTS
    planes: int = 64  # depth hypotheses, uniform in inverse depth
    patch_radius: int = 2  # NCC patch is (2r+1)^2 taps
    patch_step: int = 1  # pixels between taps (dilated patch)
    neighbours: int = 4  # source views per reference (closest poses)
    top_k: int = 2  # best source costs averaged per plane
    min_texture: float = 0.01  # grey std of a patch below which a pixel gets no estimate
    min_score: float = 0.5  # photometric score (NCC, or the network's confidence) of a confident pixel
    consistency_px: float = 1.0  # forward-backward reprojection error bound (pixels)
    consistency_depth: float = 0.01  # relative depth difference bound
    min_consistent: int = 1  # neighbours that must agree
    min_angle: float = 0.0  # degrees: a neighbour whose ray meets the reference's at a smaller angle at the point
    #   (too short a baseline to place it in depth) does not count towards min_consistent (COLMAP's patch-match filter
    #   uses 3); 0: every neighbour counts
    translation_scale: float = 1.0  # pose distance used to pick neighbours (see select.pose_distance)
    sgm_paths: int = 0  # semi-global matching: the cost volume aggregated along this many image directions (0: off,
    #   winner-take-all per pixel; 4: left, right, up, down) before the best plane is picked
    sgm_p1: float = 0.05  # its penalty for a step to the neighbouring plane (costs are 1 - NCC, in [0, 2])
    sgm_p2: float = 0.4  # ... and for a larger jump

    LIMITS = {"min_angle": "[0, 90)", "sgm_paths": "[0, 4]", "sgm_p1": ">= 0", "sgm_p2": ">= 0"}


class PointCloud(NamedTuple):
    points: torch.Tensor  # [N, 3] world
    colors: torch.Tensor  # [N, 3] in [0, 1]
    confidence: torch.Tensor  # [N] in [0, 1]
    view: torch.Tensor  # [N] int64 reference view of each point
    pixel: torch.Tensor  # [N, 2] int64 (row i, column j) in that view


class StereoResult(NamedTuple):
    cloud: PointCloud
    depth: torch.Tensor  # [V, H, W] fused z-depth of confident pixels, 0 elsewhere
    raw_depth: torch.Tensor  # [V, H, W] per-view estimate before the consistency check (0 = none)
    score: torch.Tensor  # [V, H, W] photometric score (NCC, or the network's confidence)
    consistent: torch.Tensor  # [V, H, W] int32 neighbours that agree
    confidence: torch.Tensor  # [V, H, W] in [0, 1]
    mask: torch.Tensor  # [V, H, W] bool confident
    neighbours: torch.Tensor  # [V, M] source views of each reference


# ----------------------------------------------------------------------------------------------
# plane sweep


def to_gray(images: torch.Tensor) -> torch.Tensor:
    """[..., H, W, 3] in [0, 1] -> [..., H, W] luma (Rec. 601)."""
    w = torch.tensor([0.299, 0.587, 0.114], device=images.device, dtype=torch.float32)
    return (images.float() * w).sum(-1)


def inverse_depth_planes(depth_range: tuple[float, float], planes: int, device=None) -> torch.Tensor:
    """[P] inverse depths, uniform from 1/near down to 1/far."""
    near, far = float(depth_range[0]), float(depth_range[1])
    if not (0.0 < near < far and math.isfinite(far)):
        raise ValueError(f"depth_range must be 0 < near < far < inf, got {depth_range}")
    if planes < 3:
        raise ValueError(f"the plane sweep needs at least 3 planes, got {planes}")
    return torch.linspace(1.0 / near, 1.0 / far, planes, dtype=torch.float32, device=device)


def relative_homography_terms(K_ref, viewmat_ref, K_src, viewmat_src) -> tuple[torch.Tensor, torch.Tensor]:
    """(A [M, 3, 3], b [M, 3]) with reference pixel q on the plane of inverse depth d landing at
    pi(A q + d b) in each source: A = K_s R_sr K_r^-1, b = K_s t_sr (computed in float64)."""
    Kr = K_ref.double()
    Vr = viewmat_ref.double()
    Ks_ = K_src.double().reshape(-1, 3, 3)
    Vs = viewmat_src.double().reshape(-1, 4, 4)
    T = Vs @ small_inv(Vr)  # reference camera -> source camera
    A = Ks_ @ T[:, :3, :3] @ small_inv(Kr)
    b = (Ks_ @ T[:, :3, 3:4]).squeeze(-1)
    return A.float().contiguous(), b.float().contiguous()


def _index_tensor(a) -> torch.Tensor:
    """A CPU int64 tensor of view indices from a tensor, array or nested list."""
    if isinstance(a, torch.Tensor):
        return a.detach().to("cpu", torch.int64)
    return torch.as_tensor(np.asarray(a), dtype=torch.int64)


def _check_views(images, Ks, viewmats):
    if images.dim() != 4 or images.shape[-1] != 3:
        raise ValueError(f"images must be [V, H, W, 3], got {tuple(images.shape)}")
    v = images.shape[0]
    if Ks.shape != (v, 3, 3) or viewmats.shape != (v, 4, 4):
        raise ValueError(f"Ks must be [{v}, 3, 3] and viewmats [{v}, 4, 4], got {tuple(Ks.shape)} and {tuple(viewmats.shape)}")
    if v < 2:
        raise ValueError("stereo needs at least two views")


def cost_volume(gray: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor, ref: int, sources,
                depth_range: tuple[float, float], cfg: StereoConfig | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(cost [P, H, W], inverse depths [P]) of reference ``ref`` against ``sources`` (indices into
    ``gray`` [V, H, W]); cost = mean of the ``top_k`` smallest 1 - NCC, 2 where there is no evidence."""
    cfg = cfg or StereoConfig()
    src = torch.as_tensor(list(sources), dtype=torch.int32, device=gray.device)
    if not 1 <= src.numel() <= ks.MAX_SOURCES:
        raise ValueError(f"the plane sweep takes 1..{ks.MAX_SOURCES} source views, got {src.numel()}")
    if (src == ref).any():
        raise ValueError("a view cannot be its own source")
    gray = gray.float().contiguous()
    dev = device_of(gray)
    stream = stream_of(dev)
    _, h, w = gray.shape
    inv = inverse_depth_planes(depth_range, cfg.planes, gray.device)
    A, b = relative_homography_terms(Ks[ref], viewmats[ref], Ks[src.long()], viewmats[src.long()])
    A, b = A.to(gray.device), b.to(gray.device)
    mean = torch.empty(h, w, device=gray.device)
    std = torch.empty(h, w, device=gray.device)
    launch(ks.patch_stats, (h, w), [arg(gray), int(ref), int(cfg.patch_radius), int(cfg.patch_step), arg(mean), arg(std)], dev, stream)
    cost = torch.empty(cfg.planes, h, w, device=gray.device)
    launch(ks.plane_sweep_ncc, (cfg.planes, h, w),
           [arg(gray), int(ref), arg(src), arg(A, wp.mat33), arg(b, wp.vec3), arg(inv), arg(mean), arg(std),
            int(cfg.patch_radius), int(cfg.patch_step), int(cfg.top_k), float(cfg.min_texture), arg(cost)],
           dev, stream)
    return cost, inv


def winner_take_all(cost: torch.Tensor, inv_depths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(depth [H, W], score [H, W]) from a cost volume: best plane, parabola-refined; depth 0 and
    score -1 where the minimum is on the first or last plane or there is no evidence."""
    dev = device_of(cost)
    _, h, w = cost.shape
    depth = torch.empty(h, w, device=cost.device)
    score = torch.empty(h, w, device=cost.device)
    launch(ks.winner_take_all, (h, w), [arg(cost.contiguous()), arg(inv_depths.contiguous()), arg(depth), arg(score)], dev, stream_of(dev))
    return depth, score


SGM_DIRECTIONS = ((1, 0), (-1, 0), (0, 1), (0, -1))
SGM_NEUTRAL = 1.0  # what a plane without evidence (cost BAD_COST: no texture, no source sees it) costs on a path


def aggregate_costs(cost: torch.Tensor, paths: int = 4, p1: float = 0.05, p2: float = 0.4) -> torch.Tensor:
    """[P, H, W] semi-global matching of a plane-sweep cost volume: the mean over ``paths`` image directions of
    the path costs (``warpgs.kernels.stereo.sgm_path``). A plane without evidence counts as ``SGM_NEUTRAL`` there, so
    the paths carry the neighbours' planes across untextured pixels."""
    if paths not in (1, 2, 3, 4):
        raise ValueError(f"stereo: sgm_paths must be 0 (off) or 1..4 directions, got {paths}")
    if not (0 <= p1 <= p2):
        raise ValueError(f"stereo: semi-global matching needs 0 <= sgm_p1 <= sgm_p2, got {p1} and {p2}")
    cost = cost.float().contiguous()
    dev = device_of(cost)
    stream = stream_of(dev)
    _, h, w = cost.shape
    total = torch.zeros_like(cost)
    scratch = torch.empty_like(cost)
    for dx, dy in SGM_DIRECTIONS[:paths]:
        launch(ks.sgm_path, h if dy == 0 else w,
               [arg(cost), dx, dy, float(p1), float(p2), SGM_NEUTRAL, arg(scratch), arg(total)], dev, stream)
    return total / paths


def select_planes(cost: torch.Tensor, inv_depths: torch.Tensor, cfg: StereoConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """(depth [H, W], score [H, W]) of a cost volume: ``winner_take_all`` of the volume itself, or with
    ``cfg.sgm_paths`` of its semi-global aggregate; then the score is the NCC of the raw volume at the chosen plane
    (the photometric evidence of that pixel alone), and pixels with no evidence on any plane get no depth."""
    if not cfg.sgm_paths:
        return winner_take_all(cost, inv_depths)
    depth, _ = winner_take_all(aggregate_costs(cost, cfg.sgm_paths, cfg.sgm_p1, cfg.sgm_p2), inv_depths)
    n = inv_depths.numel()
    step = (inv_depths[-1] - inv_depths[0]) / (n - 1)
    found = depth > 0
    plane = ((1.0 / depth.clamp_min(1e-12) - inv_depths[0]) / step).round().long().clamp(0, n - 1)
    raw = cost.gather(0, torch.where(found, plane, torch.zeros_like(plane))[None])[0]
    found &= (cost < float(ks.BAD_COST)).any(0)
    return (torch.where(found, depth, torch.zeros_like(depth)),
            torch.where(found, 1.0 - raw, torch.full_like(depth, -1.0)))


def plane_sweep_depth(images: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor, ref: int, sources,
                      depth_range: tuple[float, float], cfg: StereoConfig | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(depth [H, W], NCC score [H, W]) of view ``ref`` from the plane sweep against ``sources``."""
    cfg = cfg or StereoConfig()
    cost, inv = cost_volume(to_gray(images), Ks, viewmats, ref, sources, depth_range, cfg)
    return select_planes(cost, inv, cfg)


def check_consistency(depths: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor, neighbours,
                      cfg: StereoConfig | None = None, views=None) -> tuple[torch.Tensor, torch.Tensor]:
    """(count [V, H, W] int32 of agreeing neighbours, fused depth [V, H, W]: the mean of the view's
    own depth and the agreeing neighbours' depths, 0 where the view has none), for the ``views``
    (default all; others get count 0 and their own depth)."""
    cfg = cfg or StereoConfig()
    d = depths.float().contiguous()
    dev = device_of(d)
    stream = stream_of(dev)
    v, h, w = d.shape
    w2c = viewmats.double()
    c2w = small_inv(w2c)
    Kd = Ks.double()
    to = dict(device=d.device, dtype=torch.float32)
    w2c, c2w, K, K_inv = (x.to(**to).contiguous() for x in (w2c, c2w, Kd, small_inv(Kd)))
    nb = _index_tensor(neighbours).int()
    count = torch.zeros(v, h, w, dtype=torch.int32, device=d.device)
    dsum = d.clone()
    max_cos = math.cos(math.radians(cfg.min_angle)) if cfg.min_angle > 0 else 1.0
    for r in (range(v) if views is None else [int(x) for x in views]):
        nr = nb[r].to(d.device).contiguous()
        launch(ks.geometric_consistency, (h, w),
               [arg(d), arg(w2c, wp.mat44), arg(c2w, wp.mat44), arg(K, wp.mat33), arg(K_inv, wp.mat33), r, arg(nr),
                float(cfg.consistency_px), float(cfg.consistency_depth), max_cos, arg(count[r]), arg(dsum[r])],
               dev, stream)
    fused = dsum / (count.float() + 1.0)
    return count, fused


def estimate_depths(images: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor, depth_range: tuple[float, float],
                    cfg: StereoConfig | None = None, neighbours=None, network: "StereoNetwork | None" = None,
                    views=None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(depth [V, H, W], score [V, H, W], neighbours [V, M]): the depth of each view in ``views``
    (default all) as a reference against its neighbours, with the configured backend (a given
    ``network`` is used as the learned backend); other views get depth 0 and score -1."""
    cfg = cfg or StereoConfig()
    _check_views(images, Ks, viewmats)
    v, h, w, _ = images.shape
    if neighbours is None:
        m = min(cfg.neighbours, v - 1)
        neighbours = neighbour_views(viewmats, m, translation_scale=cfg.translation_scale)
    nb = _index_tensor(neighbours)
    if nb.shape[0] != v:
        raise ValueError(f"neighbours must have one row per view ({v}), got {tuple(nb.shape)}")
    views = range(v) if views is None else [int(r) for r in views]
    depth = torch.zeros(v, h, w, device=images.device)
    score = torch.full((v, h, w), -1.0, device=images.device)
    learned = cfg.backend == "learned" or network is not None
    if not learned and cfg.backend != "planesweep":
        raise ValueError(f"unknown stereo backend {cfg.backend!r} (planesweep | learned)")
    if learned:
        net = network if network is not None else load_stereo_network(cfg.weights, images.device)
        inv = inverse_depth_planes(depth_range, cfg.planes, images.device)
        with torch.no_grad():
            for r in views:
                idx = torch.cat([torch.tensor([r]), nb[r]]).to(images.device)
                d, c = net(images[idx].permute(0, 3, 1, 2).float().contiguous(), Ks[idx].float(), viewmats[idx].float(), inv)
                depth[r] = torch.nan_to_num(d.float(), nan=0.0, posinf=0.0, neginf=0.0).clamp_min(0)
                score[r] = c.float()
        return depth, score, nb
    gray = to_gray(images).contiguous()
    for r in views:
        cost, inv = cost_volume(gray, Ks, viewmats, r, nb[r].tolist(), depth_range, cfg)
        depth[r], score[r] = select_planes(cost, inv, cfg)
    return depth, score, nb


def unproject(depth: torch.Tensor, K: torch.Tensor, viewmat: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """World points [N, 3] of the pixels in ``mask`` [H, W] at z-depth ``depth`` [H, W], and their (i, j)."""
    ij = mask.nonzero()
    z = depth[ij[:, 0], ij[:, 1]].double()
    uv1 = torch.stack([ij[:, 1].double() + 0.5, ij[:, 0].double() + 0.5, torch.ones_like(z)], 1)
    pc = uv1 @ small_inv(K.double()).T * z[:, None]
    c2w = small_inv(viewmat.double())
    return (pc @ c2w[:3, :3].T + c2w[:3, 3]).float(), ij


def stereo_point_cloud(images: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor, depth_range: tuple[float, float],
                       cfg: StereoConfig | None = None, neighbours=None, network: "StereoNetwork | None" = None,
                       references=None) -> StereoResult:
    """Depth maps, the consistency check, and the confident pixels of the ``references`` (default:
    every view) fused into a coloured cloud. Each reference is checked against its neighbours, so
    those get depth maps too (against their own neighbours); only references contribute points."""
    cfg = cfg or StereoConfig()
    _check_views(images, Ks, viewmats)
    v = images.shape[0]
    if neighbours is None:
        neighbours = neighbour_views(viewmats, min(cfg.neighbours, v - 1), translation_scale=cfg.translation_scale)
    nb = _index_tensor(neighbours)
    refs = list(range(v)) if references is None else sorted({int(r) for r in references})
    need = sorted(set(refs) | set(nb[refs].reshape(-1).tolist()))
    raw, score, nb = estimate_depths(images, Ks, viewmats, depth_range, cfg, nb, network, views=need)
    raw = torch.where(score >= cfg.min_score, raw, torch.zeros_like(raw))  # only plausible depths vote
    count, fused = check_consistency(raw, Ks, viewmats, nb, cfg, views=refs)
    is_ref = torch.zeros(v, 1, 1, dtype=torch.bool, device=raw.device)
    is_ref[refs] = True
    mask = (raw > 0) & (count >= cfg.min_consistent) & is_ref
    confidence = score.clamp(0, 1) * count.float() / max(1, nb.shape[1])
    confidence = torch.where(mask, confidence, torch.zeros_like(confidence))
    depth = torch.where(mask, fused, torch.zeros_like(fused))
    pts, cols, conf, view, pix = [], [], [], [], []
    for r in refs:
        p, ij = unproject(depth[r], Ks[r], viewmats[r], mask[r])
        pts.append(p.to(images.device))
        cols.append(images[r, ij[:, 0], ij[:, 1]].float())
        conf.append(confidence[r, ij[:, 0], ij[:, 1]])
        view.append(torch.full((len(ij),), r, dtype=torch.int64, device=images.device))
        pix.append(ij)
    cloud = PointCloud(torch.cat(pts), torch.cat(cols), torch.cat(conf), torch.cat(view), torch.cat(pix))
    return StereoResult(cloud, depth, raw, score, count, confidence, mask, nb)


# ----------------------------------------------------------------------------------------------
# learned stereo from local weights


class StereoNetwork(Protocol):
    """What the learned backend calls, once per reference view (exported archives follow it too):

    ``net(images [S, 3, H, W] in [0, 1] (the reference first, then its sources), Ks [S, 3, 3],
    viewmats [S, 4, 4], inv_depths [P]) -> (depth [H, W] z-depth, confidence [H, W] in [0, 1])``
    """

    def __call__(self, images: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor,
                 inv_depths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]: ...


class StereoWeightsError(FileNotFoundError):
    """The learned stereo backend has no usable weights; the message says where it looked and what to do."""


def plane_sweep_grid(K_ref, viewmat_ref, K_src, viewmat_src, inv_depths, height: int, width: int) -> torch.Tensor:
    """[M, P, H, W, 2] ``grid_sample`` coordinates (align_corners=False) of every reference pixel on
    every plane in every source view."""
    A, b = relative_homography_terms(K_ref, viewmat_ref, K_src, viewmat_src)
    A, b = A.to(inv_depths.device), b.to(inv_depths.device)
    ys, xs = torch.meshgrid(torch.arange(height, device=inv_depths.device) + 0.5,
                            torch.arange(width, device=inv_depths.device) + 0.5, indexing="ij")
    q = torch.stack([xs, ys, torch.ones_like(xs)], -1).reshape(-1, 3)  # [HW, 3]
    x = torch.einsum("mij,nj->mni", A, q)[:, None] + inv_depths[None, :, None, None] * b[:, None, None, :]  # [M, P, HW, 3]
    z = x[..., 2:3].clamp_min(1e-6)
    uv = x[..., :2] / z
    grid = torch.stack([uv[..., 0] / width * 2 - 1, uv[..., 1] / height * 2 - 1], -1)
    grid = torch.where(x[..., 2:3] > 1e-6, grid, torch.full_like(grid, -2.0))  # behind the camera: outside
    return grid.reshape(A.shape[0], inv_depths.shape[0], height, width, 2)


class MVSNetLite(nn.Module):
    """A small MVSNet-style network (Yao et al. 2018): shared 2D features, differentiable plane-sweep
    warping, variance cost volume, 3D convolutional regularisation, soft-argmin over inverse depth,
    and MVSNet's probability-mass confidence. Full resolution; for users who train their own weights."""

    def __init__(self, channels: int = 8, reg_channels: int = 8):
        super().__init__()
        self.config = {"channels": int(channels), "reg_channels": int(reg_channels)}
        c, r = channels, reg_channels
        self.features = nn.Sequential(
            nn.Conv2d(3, c, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv2d(c, c, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv2d(c, c, 3, padding=1),
        )
        self.regularise = nn.Sequential(
            nn.Conv3d(c, r, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv3d(r, r, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv3d(r, 1, 3, padding=1),
        )

    def forward(self, images, Ks, viewmats, inv_depths):
        s, _, h, w = images.shape
        p = inv_depths.shape[0]
        f = self.features(images)  # [S, C, H, W]
        total = f[0][:, None].expand(-1, p, -1, -1)  # [C, P, H, W]
        total_sq = total * total
        if s > 1:
            grid = plane_sweep_grid(Ks[0], viewmats[0], Ks[1:], viewmats[1:], inv_depths, h, w)  # [M, P, H, W, 2]
            for m in range(s - 1):
                warped = F.grid_sample(f[m + 1][None].expand(p, -1, -1, -1), grid[m], mode="bilinear",
                                       padding_mode="zeros", align_corners=False)  # [P, C, H, W]
                warped = warped.permute(1, 0, 2, 3)
                total = total + warped
                total_sq = total_sq + warped * warped
        variance = total_sq / s - (total / s) ** 2
        logits = self.regularise(variance[None])[0, 0]  # [P, H, W]
        prob = torch.softmax(logits, dim=0)
        inv = (prob * inv_depths[:, None, None]).sum(0)
        depth = 1.0 / inv.clamp_min(1e-8)
        index = (prob * torch.arange(p, device=prob.device, dtype=prob.dtype)[:, None, None]).sum(0)
        mass4 = F.avg_pool3d(F.pad(prob[None, None], (0, 0, 0, 0, 1, 2)), (4, 1, 1), stride=1)[0, 0] * 4  # planes k-1..k+2
        k = index.floor().long().clamp(0, p - 1)
        confidence = mass4.gather(0, k[None])[0].clamp(0, 1)
        return depth, confidence


def save_stereo_network(net: MVSNetLite, path: str | Path) -> Path:
    """Writes a checkpoint that ``load_stereo_network`` reads: {'arch', 'config', 'state_dict'}."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"arch": "mvsnet_lite", "config": dict(net.config), "state_dict": net.state_dict()}, path)
    return path


def load_stereo_network(weights: str | Path | None, device="cpu") -> nn.Module:
    """The learned stereo network from a local file: a ``torch.export`` archive (``.pt2``) or a
    TorchScript archive whose forward follows ``StereoNetwork``, or a checkpoint {'arch':
    'mvsnet_lite', 'config': {...}, 'state_dict': {...}} (``save_stereo_network``). ``weights`` None
    reads $WARPGS_STEREO_WEIGHTS. Raises ``StereoWeightsError`` saying what to do."""
    source = "the stereo config's 'weights'"
    if weights is None and os.environ.get(WEIGHTS_ENV):
        weights, source = os.environ[WEIGHTS_ENV], f"${WEIGHTS_ENV}"
    hint = ("Set densify.stereo.weights (or $%s) to a local file: a torch.export (.pt2) or TorchScript archive whose "
            "forward takes (images [S,3,H,W], Ks [S,3,3], viewmats [S,4,4], inv_depths [P]) and returns "
            "(depth [H,W], confidence [H,W]), or a checkpoint written by warpgs.densify.stereo.save_stereo_network. "
            "warpgs downloads nothing. Or use backend 'planesweep', which needs no weights." % WEIGHTS_ENV)
    if weights is None:
        raise StereoWeightsError(f"the learned stereo backend needs local weights and none were given. {hint}")
    path = Path(weights).expanduser()
    if not path.is_file():
        raise StereoWeightsError(f"{path} (from {source}): no such file. {hint}")
    if path.suffix == ".pt2":
        try:
            module = torch.export.load(str(path)).module()
        except Exception as e:
            raise StereoWeightsError(f"{path}: cannot load it as a torch.export archive ({e}). {hint}") from e
        try:
            module = module.to(device)
        except Exception:  # pragma: no cover - some exported graphs are pinned to their device
            pass
        return module
    try:
        with warnings.catch_warnings():  # TorchScript is deprecated in recent torch, still supported here
            warnings.simplefilter("ignore", DeprecationWarning)
            return torch.jit.load(str(path), map_location=device).eval()
    except Exception:
        pass  # not TorchScript: a checkpoint
    try:
        ck = torch.load(path, map_location=device, weights_only=True)
    except Exception as e:
        raise StereoWeightsError(f"{path}: neither a TorchScript archive nor a readable checkpoint ({e}). {hint}") from e
    if not isinstance(ck, dict) or ck.get("arch") != "mvsnet_lite" or "state_dict" not in ck:
        keys = sorted(ck) if isinstance(ck, dict) else type(ck).__name__
        raise StereoWeightsError(f"{path}: checkpoint is not an 'mvsnet_lite' stereo network (found {keys}). {hint}")
    net = MVSNetLite(**ck.get("config", {}))
    try:
        net.load_state_dict(ck["state_dict"])
    except RuntimeError as e:
        raise StereoWeightsError(f"{path}: weights do not fit MVSNetLite{net.config}: {e}") from e
    return net.to(device).eval()
