"""Initial geometry from the training views (warpgs/points): dense stereo points against the synthetic
scene's ground-truth depth, depth bounds from points (analytic), the fallback chain and its one-line
notes, and what the trainer does with the result (bounds, initial Gaussians, metrics)."""

import json
from pathlib import Path

import numpy as np
import pytest

from warpgs.data.nerfstudio import load_nerfstudio
from warpgs.data.synthetic import SyntheticConfig, generate_capture, write_dl3dv
from warpgs.points import (
    GeometryConfig,
    SfmError,
    StereoInitOptions,
    depth_bounds,
    initial_geometry,
    resolvable_depth_range,
    stereo_points,
)

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """A small synthetic walk-through with ground-truth depth: 4 training views at 128x96."""
    cap = generate_capture(SyntheticConfig(seed=1, width=128, height=96, frames=12, samples_per_side=1, num_points=500),
                           device="cpu")
    path = write_dl3dv(cap, tmp_path_factory.mktemp("room") / "scene")
    return load_nerfstudio(path, views=4, load_depth=True)


def _depth_errors(cameras, xyz):
    """Relative error of each point's z-depth against the ground-truth depth of every view it projects into."""
    rel = []
    for c in cameras:
        uv, z = c.project(xyz)
        j, i = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        ok = (z > 0) & (j >= 0) & (i >= 0) & (j < c.width) & (i < c.height)
        gt = c.depth[i[ok], j[ok]]
        # a point seen by this view may be hidden behind nearer surfaces of it: compare the visible ones only
        vis = z[ok] <= gt * 1.05
        rel.append(np.abs(z[ok][vis] - gt[vis]) / gt[vis])
    return np.concatenate(rel)


def test_stereo_points_match_ground_truth_depth(room):
    pts = stereo_points(room.train, StereoInitOptions(max_width=128))
    assert len(pts.xyz) > 500, pts.stats
    err = _depth_errors(room.train, pts.xyz)
    assert len(err) > 500
    assert np.median(err) < 0.02, np.median(err)
    assert np.mean(err < 0.05) > 0.8
    # the first pass sweeps what the baselines resolve; the second a range around the scene only
    (first, second) = pts.stats["passes"]
    gt = np.concatenate([c.depth[c.depth > 0] for c in room.train])
    assert second["depth_range"][0] <= np.median(gt) <= second["depth_range"][1]
    assert second["depth_range"][1] / second["depth_range"][0] < first["depth_range"][1] / first["depth_range"][0] / 5
    assert np.all((pts.rgb >= 0) & (pts.rgb <= 1))


def test_depth_bounds_are_per_camera_percentiles(room):
    cam = room.train[0]
    # points straight ahead of the first camera at depths 2..10 (a line through the principal point)
    z = np.linspace(2.0, 10.0, 801)
    K_inv = np.linalg.inv(cam.K.astype(np.float64))
    ray = K_inv @ np.array([cam.K[0, 2], cam.K[1, 2], 1.0])
    pc = ray[None] * z[:, None]
    xyz = pc @ cam.c2w[:3, :3].T + cam.c2w[:3, 3]
    near, far = depth_bounds([cam], xyz, 1.0, 99.0, margin=0.2)
    assert near == pytest.approx(np.percentile(z, 1) * 0.8, rel=1e-4)
    assert far == pytest.approx(np.percentile(z, 99) * 1.2, rel=1e-4)
    assert depth_bounds([cam], xyz[:5]) is None  # too few points seen


def test_resolvable_depth_range_is_the_disparity_range():
    f, b, w = 100.0, 0.5, 200
    K = np.array([[f, 0, w / 2], [0, f, 50], [0, 0, 1]])
    V0, V1 = np.eye(4), np.eye(4)
    V1[0, 3] = -b  # second camera 0.5 to the right
    near, far = resolvable_depth_range(np.stack([K, K]), np.stack([V0, V1]), w, min_disparity=0.5, max_disparity=0.25)
    assert near == pytest.approx(f * b / (0.25 * w)) and far == pytest.approx(f * b / 0.5)


def test_fallback_to_stereo_says_so_in_one_line(room, monkeypatch):
    import warpgs.points as points

    def no_matches(*a, **k):
        raise SfmError("no feature matches between the 4 training views")

    monkeypatch.setattr(points, "triangulate", no_matches)
    lines = []
    geo = initial_geometry(room.train, "sfm", GeometryConfig(stereo=StereoInitOptions(max_width=64)), log=lines.append)
    assert geo.method == "stereo" and len(geo.xyz) >= 100
    assert len(lines) == 1 and "using stereo" in lines[0] and "no feature matches" in lines[0]
    near, far = geo.bounds
    gt = np.concatenate([c.depth[c.depth > 0] for c in room.train])
    assert near < np.percentile(gt, 5) and far > np.percentile(gt, 95) and far / near < 50


def test_nothing_found_falls_back_to_random_points(room, monkeypatch):
    """Blank images: SfM finds no match and stereo no texture; the trainer starts from random points."""
    import dataclasses

    import warpgs.points as points
    from warpgs.config import Config
    from warpgs.train import Trainer

    monkeypatch.setattr(points, "triangulate", lambda *a, **k: (_ for _ in ()).throw(SfmError("no feature matches")))
    scene = dataclasses.replace(room, train=[dataclasses.replace(c, image=np.full_like(c.image, 0.5)) for c in room.train],
                                test=room.test[:1])
    lines = []
    geo = initial_geometry(scene.train, "sfm+stereo", GeometryConfig(stereo=StereoInitOptions(max_width=64)),
                           log=lines.append)
    assert geo.method == "none" and len(geo.xyz) == 0 and geo.bounds is None
    assert len(lines) == 2 and "random points" in lines[1]
    cfg = Config()
    cfg.model.init, cfg.model.init_num = "sfm+stereo", 300
    cfg.geometry.stereo.max_width = 64
    cfg.train.device = "cpu"
    t = Trainer(cfg, scene, None, log=lambda m: None)
    assert len(t.model) == 300  # frustum points between the loader's bounds


def test_one_view_is_a_clear_error(room):
    with pytest.raises(SfmError, match="at least 2"):
        initial_geometry(room.train[:1], "sfm")
    with pytest.raises(ValueError, match="at least 2"):
        stereo_points(room.train[:1])


def test_trainer_starts_from_the_points_and_records_them(room, tmp_path, monkeypatch):
    import warpgs.points as points
    from warpgs.config import Config
    from warpgs.train import Trainer

    monkeypatch.setattr(points, "triangulate", lambda *a, **k: (_ for _ in ()).throw(SfmError("no feature matches")))
    loader_bounds = tuple(room.bounds)
    cfg = Config()
    cfg.model.init = "sfm+stereo"
    cfg.geometry.stereo.max_width = 64
    cfg.train.device, cfg.train.iterations, cfg.train.progress = "cpu", 5, False
    cfg.eval.fps_repeats = 1
    cfg.eval.lpips_weights = str(tmp_path / "none.pth")
    cfg.train.hold_geometry = "stereo"  # the captures' default: points from stereo alone hold the geometry
    t = Trainer(cfg, room, tmp_path / "run", log=lambda m: None)
    geo = room.geometry
    assert geo.method == "stereo" and len(t.model) == len(geo.xyz)
    assert t.held["mode"] == "stereo" and t.strategy.refine_stop_iter == 0 and t.cfg.optim.means_lr < cfg.optim.means_lr
    assert room.bounds == geo.bounds and room.metadata["loader_bounds"] == loader_bounds
    t.train()
    m = t.finish()
    assert m["init"]["method"] == "stereo" and m["init"]["points"] == len(geo.xyz)
    assert m["stage_times_s"]["init_stereo_s"] > 0 and m["stage_times_s"]["train_s"] > 0
    saved = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert saved["init"]["notes"] and (tmp_path / "run" / "init_points.ply").is_file()
    assert saved["hold_geometry"]["mode"] == "stereo" and len(t.model) == len(geo.xyz)


@pytest.mark.skipif(not (SHARED / "castle_p30").is_dir(), reason="../shared/data/castle_p30 is not here")
def test_real_capture_bounds_come_from_its_points():
    """castle_p30 (a real walk around a courtyard): the loader's guess spans three decades of depth; the
    bounds measured on the points found between 9 training views span one, and hold the points."""
    from warpgs.data import load_scene

    scene = load_scene(str(SHARED / "castle_p30"), views=9, downscale=8)
    lo, hi = scene.bounds
    geo = initial_geometry(scene.train, "sfm", GeometryConfig(), log=lambda m: None)
    assert geo.method in ("sfm", "stereo") and len(geo.xyz) >= 100
    near, far = geo.bounds
    assert far / near < 100 < hi / lo
    z = np.concatenate([c.project(geo.xyz)[1] for c in scene.train])
    assert np.mean((z > near) & (z < far)) > 0.5


def test_sfm_points_match_the_synthetic_rooms_ground_truth_depth(room):
    """pycolmap triangulation with the poses held fixed, on warpgs's own synthetic walk-through: the
    points sit on the surfaces the ray tracer rendered."""
    pts = initial_geometry(room.train, "sfm", GeometryConfig(min_points=20), log=lambda m: None)
    assert pts.method == "sfm", pts.notes
    assert len(pts.xyz) >= 20
    err = _depth_errors(room.train, pts.xyz)
    assert len(err) >= 40  # each point is seen by at least two views
    # the depth map is sampled at the pixel the point falls in: ~1% on surfaces slanted across a pixel
    assert np.median(err) < 0.02, np.median(err)
    assert np.mean(err < 0.05) > 0.9, np.mean(err < 0.05)


def test_extend_far_reaches_depths_beyond_a_too_near_range(room):
    """A depth range whose far end cuts the scene (as SfM's few points give it: castle_p30 at 3 views): the sweep
    stays inside it, and finds nothing beyond; with extend_far the first pass over the resolvable range runs too, the
    sweep keeps the range's near end and reaches the scene's far surfaces, at their ground-truth depth."""
    gt = np.concatenate([c.depth[c.depth > 0] for c in room.train])
    near, cut = float(np.percentile(gt, 1)) * 0.8, float(np.percentile(gt, 50))
    opts = StereoInitOptions(max_width=128)
    clipped = stereo_points(room.train, opts, (near, cut))
    extended = stereo_points(room.train, opts, (near, cut), extend_far=True)

    def far_share(pts):  # points beyond the cut from every view that sees them (a point's own view is one)
        z = np.full(len(pts.xyz), np.inf)
        for c in room.train:
            uv, d = c.project(pts.xyz)
            ok = (d > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < c.width) & (uv[:, 1] < c.height)
            z = np.where(ok, np.minimum(z, d), z)
        return float(np.mean(z > cut * 1.05))

    assert [p["depth_range"] for p in clipped.stats["passes"]] == [(near, cut)]
    (first, second) = extended.stats["passes"]
    assert first["depth_range"][1] > 10 * np.max(gt)  # the resolvable range
    assert second["depth_range"][0] == near and second["depth_range"][1] >= np.percentile(gt, 95)
    assert far_share(clipped) < 0.02 < 0.2 < far_share(extended), (far_share(clipped), far_share(extended))
    err = _depth_errors(room.train, extended.xyz)
    assert np.median(err) < 0.02 and np.mean(err < 0.05) > 0.8, (np.median(err), np.mean(err < 0.05))


@pytest.mark.parametrize("extend", [False, True])
def test_extend_far_applies_when_sfm_finds_too_few_points(room, monkeypatch, extend):
    """geometry.extend_far reaches stereo_points only when SfM's points, which still give the sweep its range, are
    fewer than min_points."""
    import warpgs.points as points

    calls = []
    monkeypatch.setattr(points, "stereo_points", lambda cameras, options, depth_range, extend_far=False, device=None:
                        calls.append((depth_range, extend_far)) or stereo_points(cameras, options, depth_range,
                                                                                 extend_far=extend_far, device=device))
    cfg = GeometryConfig(min_points=10**6, extend_far=extend, stereo=StereoInitOptions(max_width=64))
    initial_geometry(room.train, "sfm+stereo", cfg, log=lambda m: None)  # stereo's points count as too few as well
    assert len(calls) == 1
    assert calls[0][0] is not None and calls[0][1] is extend


def test_fewer_views_than_sfm_min_views_start_from_stereo_bounded_by_the_sfm_points(room, monkeypatch):
    """With 4 training views and sfm_min_views 5, sfm gives way to stereo although SfM found enough points (one
    line says why), and the sweep's depth range comes from those SfM points; with sfm_min_views 4 the run starts
    from SfM's points."""
    import warpgs.points as points

    ranges = []
    real_stereo = points.stereo_points

    def spy(cameras, options, depth_range, extend_far=False, device=None):
        assert not extend_far  # SfM found min_points
        ranges.append(depth_range)
        return real_stereo(cameras, options, depth_range, device=device)

    monkeypatch.setattr(points, "stereo_points", spy)
    opts = dict(min_points=20, stereo=StereoInitOptions(max_width=64))
    lines = []
    geo = initial_geometry(room.train, "sfm", GeometryConfig(sfm_min_views=5, **opts), log=lines.append)
    assert geo.method == "stereo" and len(geo.xyz) >= 100
    assert len(lines) == 1 and "4 training views, fewer than geometry.sfm_min_views 5; using stereo" in lines[0]
    sfm_xyz = points.triangulate(room.train, points.SfmOptions(), log=lambda *_: None).xyz
    assert ranges == [points.depth_bounds(room.train, sfm_xyz, 1.0, 99.0, 0.2)]
    kept = initial_geometry(room.train, "sfm", GeometryConfig(sfm_min_views=4, **opts), log=lambda m: None)
    assert kept.method == "sfm" and len(kept.xyz) == len(sfm_xyz)
