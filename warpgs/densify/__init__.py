"""Densification from pseudo views: pick views, dense stereo, clean the cloud, add Gaussians where none are.

    from warpgs.densify import DensifyConfig, densify_gaussians, load_densify_config
    cfg = load_densify_config()                                   # the defaults (or Config.densify)
    out = densify_gaussians(model.means, images, Ks, viewmats, depth_range=scene.bounds, config=cfg)
    out.insertion.means, out.insertion.colors, out.insertion.scales   # the new Gaussians (scales: std devs)

Stages, each usable on its own (plain tensors in and out):

1. ``select.select_views``: a subset of the pseudo views with low covisibility (farthest-point sampling
   on a pose distance mixing translation and rotation);
2. ``stereo.stereo_point_cloud``: Warp plane-sweep stereo (NCC, winner-take-all with sub-plane
   refinement, cross-view geometric consistency, a confidence per pixel) of the selected views against
   their nearest frames, fused into a coloured cloud; or a learned network from local weights;
3. ``filter.filter_cloud``: open3d statistical outlier removal (20 neighbours, std ratio 2.0) and
   optional voxel downsampling;
4. ``insert.insert_points``: Warp HashGrid radius query; a new Gaussian only where no existing centre
   lies within the radius, coloured from the cloud, scaled by the local point spacing.

``python -m warpgs.viz cloud.ply`` shows the result (``save_origin_ply`` writes kept / added / removed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from warpgs.configio import ConfigError, apply_values, read_yaml
from warpgs.viz import ORIGIN_ADDED, ORIGIN_KEPT, ORIGIN_NAMES, ORIGIN_REMOVED, save_origin_ply

from .filter import FilterConfig, FilterResult, filter_cloud, statistical_outliers, voxel_downsample
from .insert import InsertConfig, Insertion, insert_points, local_spacing, thin_points, within_radius
from .select import camera_centres, farthest_point_sampling, neighbour_views, pose_distance, select_views
from .stereo import (
    MVSNetLite,
    PointCloud,
    StereoConfig,
    StereoNetwork,
    StereoResult,
    StereoWeightsError,
    check_consistency,
    cost_volume,
    estimate_depths,
    load_stereo_network,
    plane_sweep_depth,
    save_stereo_network,
    stereo_point_cloud,
    winner_take_all,
)


@dataclass
class SelectConfig:
    views: int = 4  # pseudo views used as stereo references
    translation_scale: float = 1.0  # pose distance: 1 - exp(-|dt| / translation_scale) exp(-rotation_weight angle)
    rotation_weight: float = 1.0


@dataclass
class DensifyConfig:
    select: SelectConfig = field(default_factory=SelectConfig)
    stereo: StereoConfig = field(default_factory=StereoConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    insert: InsertConfig = field(default_factory=InsertConfig)
    auto_radius: float = 0.005  # insert.radius null: this fraction of the cloud's bounding-box diagonal


DensifyConfigError = ConfigError  # the one config error type (warpgs.config)


def load_densify_config(path: str | Path | None = None, overrides: dict | None = None) -> DensifyConfig:
    """Defaults, then a YAML file of ``DensifyConfig`` fields (None: defaults only), then ``overrides``
    (a nested dict, e.g. ``{"filter": {"std_ratio": 3.0}}``). Unknown keys are errors."""
    cfg = DensifyConfig()
    if path is not None:
        data = read_yaml(path)
        apply_values(cfg, data.get("densify", data), str(path))
    if overrides:
        apply_values(cfg, overrides, "overrides")
    return cfg


class Densification(NamedTuple):
    references: list[int]  # views used as stereo references
    stereo: StereoResult
    filter: FilterResult
    insertion: Insertion
    radius: float  # the insertion radius used

    def origin_cloud(self, existing_means: torch.Tensor, existing_colors: torch.Tensor | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points [N, 3], colors [N, 3], origin [N] uint8) of kept Gaussians, added ones and the stereo
        points removed as outliers, for ``warpgs.viz.save_origin_ply``."""
        ex = existing_means.detach().float().cpu().numpy()
        exc = (np.full((len(ex), 3), 0.5, np.float32) if existing_colors is None
               else existing_colors.detach().float().cpu().numpy().reshape(len(ex), -1)[:, :3])
        add = self.insertion.means.detach().cpu().numpy()
        addc = self.insertion.colors.detach().cpu().numpy()
        if addc.shape[1] < 3:
            addc = np.full((len(add), 3), 0.5, np.float32)
        removed = _np(self.filter.removed)
        cloud = self.stereo.cloud
        rem = cloud.points.detach().cpu().numpy()[removed]
        remc = cloud.colors.detach().cpu().numpy()[removed]
        points = np.concatenate([ex, add, rem]).astype(np.float32)
        colors = np.concatenate([exc, addc[:, :3], remc]).astype(np.float32)
        origin = np.concatenate([np.full(len(ex), ORIGIN_KEPT), np.full(len(add), ORIGIN_ADDED),
                                 np.full(len(rem), ORIGIN_REMOVED)]).astype(np.uint8)
        return points, colors, origin


def _np(a) -> np.ndarray:
    return a.detach().cpu().numpy() if hasattr(a, "detach") else np.asarray(a)


def densify_gaussians(existing_means: torch.Tensor, images: torch.Tensor, Ks: torch.Tensor, viewmats: torch.Tensor,
                      depth_range: tuple[float, float], config: DensifyConfig | None = None, references=None,
                      fixed=(), network: StereoNetwork | None = None, neighbours=None) -> Densification:
    """The four stages on pseudo views ``images`` [V, H, W, 3] with ``Ks`` [V, 3, 3] and ``viewmats``
    [V, 4, 4]: ``references`` (default: ``config.select.views`` chosen by farthest-point sampling,
    continuing from ``fixed``) are matched against their nearest views (or ``neighbours`` [V, m]: the
    source views of every view), the cloud is cleaned, and new Gaussians are proposed around
    ``existing_means`` [N, 3]."""
    cfg = config or DensifyConfig()
    if references is None:
        references = select_views(viewmats, cfg.select.views, fixed=fixed,
                                  translation_scale=cfg.select.translation_scale, rotation_weight=cfg.select.rotation_weight)
    references = [int(r) for r in references]
    st = stereo_point_cloud(images, Ks, viewmats, depth_range, cfg.stereo, references=references, network=network,
                            neighbours=neighbours)
    flt = filter_cloud(st.cloud.points, st.cloud.colors, cfg.filter)
    radius = cfg.insert.radius
    if radius is None:
        pts = flt.points if len(flt.points) else existing_means
        ext = (pts.max(0).values - pts.min(0).values).norm().item() if len(pts) else 1.0
        radius = max(cfg.auto_radius * ext, 1e-6)
    ins = insert_points(existing_means.to(flt.points.device), flt.points, flt.colors, radius=radius, config=cfg.insert)
    return Densification(references, st, flt, ins, float(radius))


__all__ = [
    "Densification", "DensifyConfig", "DensifyConfigError", "FilterConfig", "FilterResult",
    "InsertConfig", "Insertion", "MVSNetLite", "ORIGIN_ADDED", "ORIGIN_KEPT", "ORIGIN_NAMES", "ORIGIN_REMOVED",
    "PointCloud", "SelectConfig", "StereoConfig", "StereoNetwork", "StereoResult", "StereoWeightsError",
    "camera_centres", "check_consistency", "cost_volume", "densify_gaussians", "estimate_depths",
    "farthest_point_sampling", "filter_cloud", "insert_points", "load_densify_config", "load_stereo_network",
    "local_spacing", "neighbour_views", "plane_sweep_depth", "pose_distance", "save_stereo_network",
    "save_origin_ply", "select_views", "statistical_outliers", "stereo_point_cloud", "thin_points", "voxel_downsample",
    "winner_take_all", "within_radius",
]
