"""Densification stage 3: open3d statistical outlier removal and voxel downsampling.

References: the synthetic room's ground-truth surface (depth maps unprojected), a brute-force numpy
statistical outlier test written from open3d's definition, and numpy voxel means.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from warpgs.data.synthetic import build_room, render_views, walk_cameras
from warpgs.densify import FilterConfig, filter_cloud, load_densify_config, statistical_outliers, voxel_downsample


def room_surface(width=128, height=96, frames=(0, 2, 4, 5), seed=0):
    """Surface points of the synthetic room: every pixel of four ray-traced depth maps, unprojected."""
    world, (x0, x1, y_of, eye) = build_room(seed)
    vms = walk_cameras(np.random.default_rng([seed, 1]), 6, x0, x1, y_of, eye)[list(frames)]
    f = 0.5 * width / math.tan(math.radians(35.0))
    K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])
    rgb, depth = render_views(world, vms, K, width, height, samples_per_side=1, device="cpu")
    pts, cols = [], []
    for vm, d, c in zip(vms, depth, rgb):
        i, j = np.nonzero(d > 0)
        z = d[i, j].astype(np.float64)
        pc = np.c_[j + 0.5, i + 0.5, np.ones_like(z)] @ np.linalg.inv(K).T * z[:, None]
        c2w = np.linalg.inv(vm)
        pts.append(pc @ c2w[:3, :3].T + c2w[:3, 3])
        cols.append(c[i, j])
    return np.concatenate(pts), np.concatenate(cols)


def far_points(surface, n, rng, box_scale=3.0, min_distance=0.5):
    """``n`` points uniform in a box ``box_scale`` times the surface's bounding box, each at least
    ``min_distance`` from every surface point."""
    import open3d as o3d

    lo, hi = surface.min(0), surface.max(0)
    centre, ext = 0.5 * (lo + hi), hi - lo
    surf = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(surface))
    out = np.zeros((0, 3))
    while len(out) < n:
        q = centre + rng.uniform(-0.5, 0.5, (4 * n, 3)) * ext * box_scale
        d = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(q)).compute_point_cloud_distance(surf))
        out = np.concatenate([out, q[d >= min_distance]])
    return out[:n]


def numpy_sor(points, k, std_ratio):
    """open3d's rule from its definition: score = mean distance to the k nearest points (the point
    itself counted among them), outlier when score > mean + std_ratio * sample std of the scores."""
    d = np.sqrt(((points[:, None] - points[None]) ** 2).sum(-1))
    score = np.sort(d, axis=1)[:, :k].mean(1)
    return score <= score.mean() + std_ratio * score.std(ddof=1)


def test_outlier_removal_acceptance():
    """Issue #6: >= 95% of 1,000 injected far points dropped, >= 95% of true surface points kept."""
    surface, colors = room_surface()
    rng = np.random.default_rng(0)
    far = far_points(surface, 1000, rng)
    pts = np.concatenate([surface, far]).astype(np.float32)
    cols = np.concatenate([colors, rng.uniform(0, 1, (1000, 3))]).astype(np.float32)
    perm = rng.permutation(len(pts))  # no help from the order
    out = filter_cloud(pts[perm], cols[perm])  # the defaults: 20 neighbours, std ratio 2.0
    removed = np.empty(len(pts), bool)
    removed[perm] = out.removed
    dropped_far = removed[len(surface):].mean()
    kept_surface = 1 - removed[:len(surface)].mean()
    print(f"{len(surface)} surface + 1000 far points: {100 * dropped_far:.1f}% of the far points dropped, "
          f"{100 * kept_surface:.2f}% of the surface kept")
    assert dropped_far >= 0.95 and kept_surface >= 0.95
    # the survivors are the kept rows, in order, with their colours
    assert np.array_equal(out.points, pts[perm][out.kept]) and np.array_equal(out.colors, cols[perm][out.kept])
    assert np.array_equal(out.index[out.kept], np.arange(out.kept.sum())) and (out.index[out.removed] == -1).all()


@pytest.mark.parametrize("k,ratio", [(20, 2.0), (8, 1.0), (30, 0.5)])
def test_outlier_rule_matches_brute_force(k, ratio):
    rng = np.random.default_rng(k)
    blob = rng.normal(size=(1200, 3)) * rng.uniform(0.3, 2.0, (1200, 1))  # uneven density
    keep = statistical_outliers(blob, k, ratio)
    ref = numpy_sor(blob, k, ratio)
    assert (keep == ref).mean() > 0.998  # float32 kd-tree vs float64 ties at the threshold
    assert 0 < (~keep).sum() < len(blob)
    cfg = load_densify_config(None, {"filter": {"nb_neighbors": k, "std_ratio": ratio}}).filter
    assert np.array_equal(filter_cloud(blob, config=cfg).kept, keep)


def test_voxel_downsampling_against_numpy():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1, 1, (5000, 3))
    cols = rng.uniform(0, 1, (5000, 3)).astype(np.float32)
    voxel = 0.25
    down, dcols, index = voxel_downsample(pts, cols, voxel)
    assert len(down) == len(np.unique(index)) and (index >= 0).all()
    # every output point is the mean of the inputs mapped to it, and those share one voxel
    lo = pts.min(0) - 0.5 * voxel
    cell = np.floor((pts - lo) / voxel).astype(np.int64)
    for row in rng.choice(len(down), 50, replace=False):
        members = index == row
        assert np.allclose(down[row], pts[members].mean(0), atol=1e-5)
        assert np.allclose(dcols[row], cols[members].mean(0), atol=1e-5)
        assert len(np.unique(cell[members], axis=0)) == 1
    assert len(down) == len(np.unique(cell, axis=0))
    # through filter_cloud: voxels first, then outlier removal; each input shares its voxel's fate
    out = filter_cloud(pts, cols, FilterConfig(voxel=voxel, nb_neighbors=10, std_ratio=1.0))
    keep_v = statistical_outliers(down, 10, 1.0)
    assert np.array_equal(out.kept, keep_v[index])
    assert np.allclose(out.points, down[keep_v]) and len(out.points) == keep_v.sum()
    assert np.allclose(out.points[out.index[out.kept]], down[index[out.kept]])


def test_torch_in_torch_out_and_bad_points():
    rng = np.random.default_rng(5)
    pts = torch.from_numpy(rng.normal(size=(500, 3)).astype(np.float32))
    pts[7] = float("nan")
    pts[9] = torch.tensor([50.0, 50.0, 50.0])
    out = filter_cloud(pts, torch.rand(500, 3))
    assert isinstance(out.points, torch.Tensor) and out.kept.dtype == torch.bool and out.index.dtype == torch.int64
    assert not bool(out.kept[7]) and not bool(out.kept[9])
    assert torch.equal(out.removed, ~out.kept)
    assert torch.isfinite(out.points).all() and out.colors.shape == (int(out.kept.sum()), 3)
    # fewer points than neighbours: nothing to judge, everything kept
    few = filter_cloud(np.zeros((5, 3)))
    assert few.kept.all() and len(few.points) == 5
    empty = filter_cloud(np.zeros((0, 3)), config=FilterConfig(voxel=0.1))
    assert len(empty.points) == 0 and len(empty.kept) == 0
    with pytest.raises(ValueError):
        statistical_outliers(np.zeros((50, 3)), 0, 2.0)
    with pytest.raises(ValueError):
        filter_cloud(np.zeros((10, 3)), np.zeros((9, 3)))


def test_config_file_defaults():
    cfg = load_densify_config()
    assert cfg.filter.nb_neighbors == 20 and cfg.filter.std_ratio == 2.0 and cfg.filter.voxel is None
    with pytest.raises(ValueError, match="valid keys"):
        load_densify_config(None, {"filter": {"neighbours": 3}})
