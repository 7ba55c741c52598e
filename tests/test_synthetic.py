"""The embedded synthetic scene: determinism, ground-truth depth against geometry, and the DL3DV round trip."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from warpgs.data import (
    SceneError,
    SyntheticConfig,
    add_data_args,
    ensure_synthetic,
    generate_capture,
    load_colmap,
    load_nerfstudio,
    load_scene,
    load_scene_from_args,
    write_dl3dv,
)
from warpgs.data.synthetic import APPLIED_TRANSFORM

SMALL = SyntheticConfig(seed=3, width=96, height=72, frames=10, samples_per_side=1, num_points=1500)


@pytest.fixture(scope="module")
def capture():
    return generate_capture(SMALL, device="cpu")


@pytest.fixture(scope="module")
def written(capture, tmp_path_factory):
    return write_dl3dv(capture, tmp_path_factory.mktemp("syn") / "scene")


def _unproject(K, viewmat, uv, z):
    pc = np.c_[uv, np.ones(len(uv))] @ np.linalg.inv(K).T * z[:, None]
    c2w = np.linalg.inv(viewmat)
    return pc @ c2w[:3, :3].T + c2w[:3, 3]


def _project(K, viewmat, X):
    p = X @ viewmat[:3, :3].T + viewmat[:3, 3]
    z = p[:, 2]
    q = p @ K.T
    return q[:, :2] / q[:, 2:3], z


def _bilinear_inverse_depth(depth, uv):
    """Inverse depth interpolated bilinearly at continuous pixel coordinates (exact inside a plane),
    with a flag for samples whose four neighbours are valid and lie on one surface."""
    h, w = depth.shape
    x, y = uv[:, 0] - 0.5, uv[:, 1] - 0.5
    j0, i0 = np.floor(x).astype(int), np.floor(y).astype(int)
    ok = (j0 >= 0) & (i0 >= 0) & (j0 < w - 1) & (i0 < h - 1)
    j0, i0 = np.clip(j0, 0, w - 2), np.clip(i0, 0, h - 2)
    n = np.stack([depth[i0, j0], depth[i0, j0 + 1], depth[i0 + 1, j0], depth[i0 + 1, j0 + 1]], 1)
    ok &= np.all(n > 0, 1)
    inv = 1.0 / np.maximum(n, 1e-6)
    # on one plane, inverse depth is affine in the image: the two diagonals agree
    ok &= np.abs(inv[:, 0] + inv[:, 3] - inv[:, 1] - inv[:, 2]) < 1e-3 * inv.mean(1)
    fx, fy = x - j0, y - i0
    val = inv[:, 0] * (1 - fx) * (1 - fy) + inv[:, 1] * fx * (1 - fy) + inv[:, 2] * (1 - fx) * fy + inv[:, 3] * fx * fy
    return 1.0 / val, ok


@pytest.mark.parametrize("a,b", [(3, 4), (2, 4), (7, 5)])
def test_depth_reprojects_between_views(capture, a, b):
    K, H, W = capture.K, SMALL.height, SMALL.width
    da = capture.depths[a]
    i, j = np.nonzero(da > 0)
    uv_a = np.c_[j + 0.5, i + 0.5]
    X = _unproject(K, capture.viewmats[a], uv_a, da[i, j].astype(np.float64))
    uv_b, z_b = _project(K, capture.viewmats[b], X)
    inside = (z_b > 0) & (uv_b[:, 0] >= 1) & (uv_b[:, 0] < W - 1) & (uv_b[:, 1] >= 1) & (uv_b[:, 1] < H - 1)
    d_b, same_surface = _bilinear_inverse_depth(capture.depths[b], np.where(inside[:, None], uv_b, 1.0))
    visible = inside & same_surface & (np.abs(d_b - z_b) < 0.01 * z_b)  # not occluded in b
    assert visible.mean() > 0.2, visible.mean()
    # back from b with b's own depth
    Xb = _unproject(K, capture.viewmats[b], uv_b[visible], d_b[visible])
    uv_back, _ = _project(K, capture.viewmats[a], Xb)
    err = np.linalg.norm(uv_back - uv_a[visible], axis=1)
    assert np.median(err) <= 0.5 and np.percentile(err, 90) < 1.0, (np.median(err), np.percentile(err, 90))


def test_depth_matches_independent_ray_casting(capture):
    """z-depth of the Warp render vs Moller-Trumbore on every triangle of the world (numpy)."""
    rng = np.random.default_rng(0)
    w = capture.world
    tri = w.vertices[w.faces].astype(np.float64)
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    for k in (0, SMALL.frames - 1):
        c2w = np.linalg.inv(capture.viewmats[k])
        ii, jj = rng.integers(0, SMALL.height, 60), rng.integers(0, SMALL.width, 60)
        for i, j in zip(ii, jj):
            d = c2w[:3, :3] @ (np.linalg.inv(capture.K) @ [j + 0.5, i + 0.5, 1.0])  # z-component 1 in camera
            o = c2w[:3, 3]
            p = np.cross(d, e2)
            det = np.einsum("ij,ij->i", e1, p)
            good = np.abs(det) > 1e-12
            inv = np.where(good, 1.0 / np.where(good, det, 1.0), 0.0)
            s = o - v0
            u = np.einsum("ij,ij->i", s, p) * inv
            q = np.cross(s, e1)
            v = (q @ d) * inv
            t = np.einsum("ij,ij->i", e2, q) * inv
            hit = good & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
            ref = t[hit].min() if hit.any() else 0.0
            assert capture.depths[k, i, j] == pytest.approx(ref, rel=1e-4, abs=1e-4), (k, i, j)


def test_images_are_textured_and_lit(capture):
    img = capture.images
    assert img.dtype == np.float32 and img.shape == (SMALL.frames, SMALL.height, SMALL.width, 3)
    assert 0.0 <= img.min() and img.max() <= 1.0
    assert img.std() > 0.08  # not flat
    # local texture: neighbouring pixels differ somewhere in most 8x8 blocks
    g = img.mean(-1)
    grad = np.abs(np.diff(g, axis=2))[:, :, :]
    blocks = grad[:, : SMALL.height // 8 * 8, : (SMALL.width - 1) // 8 * 8].reshape(SMALL.frames, SMALL.height // 8, 8, -1, 8).max(axis=(2, 4))
    assert (blocks > 0.01).mean() > 0.8
    assert np.all(capture.depths > 0)  # a closed room: every pixel sees a surface
    # the camera walks forward (mostly along its viewing direction), not around an orbit
    centres = np.array([np.linalg.inv(v)[:3, 3] for v in capture.viewmats])
    steps = np.diff(centres, axis=0)
    fwd = np.array([v[2, :3] for v in capture.viewmats[:-1]])
    cosines = np.einsum("ij,ij->i", steps, fwd) / np.linalg.norm(steps, axis=1)
    assert np.all(cosines > 0.7)
    assert np.linalg.norm(centres[-1] - centres[0]) > 0.8 * np.linalg.norm(steps, axis=1).sum()


def test_deterministic_by_seed():
    cfg = SyntheticConfig(seed=5, width=32, height=24, frames=3, samples_per_side=1)
    a, b = generate_capture(cfg, "cpu"), generate_capture(cfg, "cpu")
    assert np.array_equal(a.images, b.images) and np.array_equal(a.depths, b.depths) and np.array_equal(a.viewmats, b.viewmats)
    c = generate_capture(SyntheticConfig(seed=6, width=32, height=24, frames=3, samples_per_side=1), "cpu")
    assert not np.array_equal(a.images, c.images)


def test_written_scene_loads_back_identically(capture, written):
    A = APPLIED_TRANSFORM
    s = load_nerfstudio(written, views=None, load_points=True)
    assert s.metadata["format"] == "nerfstudio"
    assert np.allclose(s.world_transform, A)
    by_name = {c.name: c for c in s.cameras}
    assert sorted(by_name) == capture.names
    assert [c.name for c in s.test] == [capture.names[k] for k in range(0, SMALL.frames, 8)]
    for k, name in enumerate(capture.names):
        c = by_name[name]
        # poses are stored in nerfstudio's frame A @ world: world-to-camera is viewmat @ A^-1
        assert np.allclose(c.viewmat, capture.viewmats[k] @ np.linalg.inv(A), atol=1e-5)
        assert np.allclose(c.K, capture.K, atol=1e-5) and (c.width, c.height) == (SMALL.width, SMALL.height)
        assert np.array_equal(c.image, np.round(capture.images[k] * 255).astype(np.float32) / 255)
        assert np.array_equal(c.depth, capture.depths[k])
    # the same scene through its COLMAP model, which lives in the generator's world
    sc = load_colmap(written, views=None)
    assert np.allclose(sc.world_transform, np.eye(4))
    for c in sc.cameras:
        k = capture.names.index(c.name)
        assert np.allclose(c.viewmat, capture.viewmats[k], atol=1e-5)
    # COLMAP points moved by applied_transform lie on the surfaces the loaded cameras see
    for c in s.train[:3]:
        uv, z = c.project(s.points3d)
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < c.width) & (uv[:, 1] >= 0) & (uv[:, 1] < c.height)
        d = c.depth[np.floor(uv[inside, 1]).astype(int), np.floor(uv[inside, 0]).astype(int)]
        on_surface = np.abs(z[inside] - d) < 0.02 * d
        in_front = z[inside] < 0.95 * d  # a surface point cannot be in front of the visible surface
        assert on_surface.mean() > 0.3 and in_front.mean() < 0.05, (on_surface.mean(), in_front.mean())
    # downscaled folder: images_2 with K halved
    s2 = load_nerfstudio(written, views=3, downscale=2)
    assert (s2.train[0].width, s2.train[0].height) == (SMALL.width // 2, SMALL.height // 2)
    assert np.allclose(s2.train[0].K[:2], capture.K[:2] / 2, atol=1e-5)
    assert s2.train[0].depth.shape == (SMALL.height // 2, SMALL.width // 2)


def test_cache_reuse_and_refusal(tmp_path):
    cfg = SyntheticConfig(seed=1, width=32, height=24, frames=4, samples_per_side=1)
    p = ensure_synthetic(cfg, tmp_path / "a", device="cpu")
    stamp = (p / "transforms.json").stat().st_mtime_ns
    assert ensure_synthetic(cfg, tmp_path / "a", device="cpu") == p and (p / "transforms.json").stat().st_mtime_ns == stamp
    other = tmp_path / "user_data"
    other.mkdir()
    (other / "precious.txt").write_text("x")
    with pytest.raises(SceneError, match="refusing"):
        ensure_synthetic(cfg, other, device="cpu")
    assert sorted(q.name for q in other.iterdir()) == ["precious.txt"]


def test_a_parallel_runs_copy_is_kept_and_an_outdated_one_replaced(capture, tmp_path):
    """Runs started together on a fresh machine each generate the default scene: whichever writes second must not
    remove the copy the first put in place, which others may be reading (a suite of 8 runs on a GPU lost a depth
    file that way); a cached scene of another version is replaced, and no temporary folder is left behind."""
    out = write_dl3dv(capture, tmp_path / "scene")
    depth = next((out / "depths").iterdir())
    before = (depth.stat().st_ino, depth.stat().st_mtime_ns)
    for overwrite in (False, True):  # as ensure_synthetic asks when the cache was empty / outdated at its check
        assert write_dl3dv(capture, out, overwrite=overwrite) == out
        assert (depth.stat().st_ino, depth.stat().st_mtime_ns) == before
    stamp = json.loads((out / "synthetic.json").read_text())
    (out / "synthetic.json").write_text(json.dumps({**stamp, "format_version": -1}))
    with pytest.raises(SceneError, match="refusing"):
        write_dl3dv(capture, out)
    write_dl3dv(capture, out, overwrite=True)
    assert json.loads((out / "synthetic.json").read_text()) == stamp
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene"]


def test_street_has_sky(tmp_path):
    cap = generate_capture(SyntheticConfig(kind="street", seed=2, width=48, height=36, frames=3, samples_per_side=1), "cpu")
    sky = cap.depths == 0
    assert 0.05 < sky.mean() < 0.7
    assert np.all(cap.images[sky][:, 2] > cap.images[sky][:, 0])  # bluish where nothing is hit


def test_default_data_is_synthetic_and_fast(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPGS_CACHE", str(tmp_path / "cache"))
    args = add_data_args(argparse.ArgumentParser()).parse_args([])
    assert args.data == "synthetic"
    s = load_scene_from_args(args, device="cpu")
    assert s.metadata["format"] == "nerfstudio" and s.metadata["synthetic"]["width"] == 256
    assert (s.train[0].width, s.train[0].height) == (256, 192) and len(s.train) == 9
    # test views: every frame not trained on (configs/data/synthetic.yaml: test_rest)
    names = sorted(c.name for c in s.train + s.test)
    assert len(s.test) == 15 and len(set(names)) == 24 and names == [f"frame_{i:05d}" for i in range(1, 25)]
    assert all(c.depth is not None for c in s.cameras)
    assert (tmp_path / "cache" / "synthetic").is_dir()
    # a second run reuses the written scene: no file of it is written again
    written = {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").rglob("*") if p.is_file()}
    load_scene("synthetic", views=3)
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").rglob("*") if p.is_file()} == written


@pytest.mark.cuda
def test_full_hd_on_gpu():
    wp = pytest.importorskip("warp")
    wp.init()
    if not wp.is_cuda_available():
        pytest.skip("no CUDA device")
    cfg = SyntheticConfig(width=1920, height=1080, frames=24)
    cap = generate_capture(cfg, device="cuda:0")
    assert cap.images.shape == (24, 1080, 1920, 3) and np.all(cap.depths > 0)
