"""Scene loaders: the shared real scenes against independent facts, format readers, and bad input.

The shared scenes live in ../shared/data (or $WARPGS_SHARED_DATA); tests that need them are skipped
when that folder is absent. Everything else writes its own small scenes into tmp_path.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from warpgs.data import (
    DatasetNotFoundError,
    SceneError,
    detect_format,
    load_blender,
    load_colmap,
    load_dtu,
    load_llff,
    load_nerfstudio,
    load_scene,
)
from warpgs.data import colmap as colmap_io
from warpgs.data.dtu import decompose_projection
from warpgs.data.splits import DTU_EXCLUDED_TEST_IDS, dtu_split, every_nth_split

SHARED = Path(os.environ.get("WARPGS_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=f"shared data not found at {SHARED}")


def _listing(root: Path) -> list[tuple[str, int, int]]:
    out = []
    for dirpath, _, files in os.walk(root):
        for f in files:
            st = os.stat(os.path.join(dirpath, f))
            out.append((os.path.join(dirpath, f), st.st_size, st.st_mtime_ns))
    return sorted(out)


# ----------------------------------------------------------------------------------------------
# shared real scenes (each loaded once)


@pytest.fixture(scope="module")
def shared_listing():
    return _listing(SHARED) if SHARED.is_dir() else None


@pytest.fixture(scope="module")
def fern(shared_listing):
    return load_llff(SHARED / "llff_fern", views=3)


@pytest.fixture(scope="module")
def lego(shared_listing):
    return load_blender(SHARED / "blender_lego")


@pytest.fixture(scope="module")
def dtu(shared_listing):
    return load_dtu(SHARED / "dtu_scan65", views=3)


@needs_shared
def test_fern_split(fern):
    # rule: sorted names, test = index % 8 == 0, train = round(linspace(0, 16, 3)) over the 17 others
    assert [c.name for c in fern.test] == ["image000", "image008", "image016"]
    assert [c.name for c in fern.train] == ["image001", "image010", "image019"]
    for c in fern.cameras:
        assert (c.width, c.height) == (504, 378) and c.image.shape == (378, 504, 3)
        assert c.image.dtype == np.float32 and 0.0 <= c.image.min() and c.image.max() <= 1.0
    # NeRF's bd_factor normalisation: the nearest bound becomes 1 / 0.75
    assert fern.bounds[0] == pytest.approx(1 / 0.75, rel=1e-6)


@needs_shared
def test_fern_cameras_match_colmap(fern):
    # focal length: COLMAP's own cameras.bin (full 4032 px) scaled to 504 px
    cams = colmap_io.read_cameras_binary(SHARED / "llff_fern" / "sparse" / "0" / "cameras.bin")
    (cam,) = cams.values()
    assert (cam.width, cam.height) == (4032, 3024)
    f = cam.pinhole()[0] * 504 / 4032
    for c in fern.cameras:
        assert c.K[0, 0] == pytest.approx(f, rel=1e-5) and c.K[1, 1] == pytest.approx(f, rel=1e-5)
    # COLMAP's points (same world as the poses), moved by the loader's own normalisation, are seen by every camera
    pts = colmap_io.read_points3d(SHARED / "llff_fern" / "sparse" / "0").xyz
    assert len(pts) > 1000
    W = fern.world_transform
    assert np.allclose(W[3], [0, 0, 0, 1])
    P = pts @ W[:3, :3].T + W[:3, 3]
    for c in fern.cameras:
        uv, z = c.project(P)
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < c.width) & (uv[:, 1] >= 0) & (uv[:, 1] < c.height)
        assert inside.mean() >= 0.95, (c.name, inside.mean())
    # and a mirrored (wrongly converted) camera would not see them
    c = fern.train[0]
    bad = c.viewmat.copy()
    bad[:3, :3] = np.diag([1, 1, -1]) @ bad[:3, :3]
    bad[2, 3] *= -1
    z_bad = P @ bad[2, :3] + bad[2, 3]
    assert (z_bad > 0).mean() < 0.05


@needs_shared
def test_lego_protocol_and_cameras(lego):
    assert [c.name for c in lego.train] == ["r_26", "r_86", "r_2", "r_55", "r_75", "r_93", "r_16", "r_73"]
    assert len(lego.test) == 25 and all(int(c.name[2:]) % 8 == 0 for c in lego.test)
    assert all((c.width, c.height) == (400, 400) for c in lego.test)
    assert lego.white_background
    for c in lego.cameras:
        centre = c.center
        assert np.linalg.norm(centre) == pytest.approx(4.031, abs=1e-3)
        assert c.forward @ (-centre / np.linalg.norm(centre)) > 0.9999  # looks at the origin
        uv, z = c.project(np.zeros((1, 3)))
        assert z[0] > 0 and np.allclose(uv[0], [c.width / 2, c.height / 2], atol=0.5)
    # composited on white: the corners (background) are white, the alpha is kept as the mask
    img = lego.train[0].image
    assert np.all(img[:4, :4] > 0.99) and lego.train[0].mask is not None and 0.05 < lego.train[0].mask.mean() < 0.9


@needs_shared
def test_dtu_split_and_masks(dtu):
    assert [c.name for c in dtu.train] == ["025", "022", "028"]
    test_ids = [int(c.name) for c in dtu.test]
    assert not set(test_ids) & set(DTU_EXCLUDED_TEST_IDS) and not set(test_ids) & {25, 22, 28, 40, 44, 48, 0, 8, 13}
    assert len(test_ids) == 49 - 9 - 15
    assert dtu.eval_masked
    for c in dtu.cameras:
        assert c.mask is not None and c.mask.dtype == bool and c.mask.shape == (300, 400)
        assert 0.02 < c.mask.mean() < 0.98


@needs_shared
def test_dtu_projection_matches_world_mat(dtu):
    cams = np.load(SHARED / "dtu_scan65" / "cameras.npz")
    scale_mat = cams["scale_mat_0"]
    rng = np.random.default_rng(0)
    # points around the object, in DTU's original world: the unit sphere of the normalised world
    xn = rng.normal(size=(500, 3))
    xn = xn / np.linalg.norm(xn, axis=1, keepdims=True) * rng.uniform(0, 1, (500, 1))
    X = (np.c_[xn, np.ones(500)] @ scale_mat.T)[:, :3]
    Xl = X @ dtu.world_transform[:3, :3].T + dtu.world_transform[:3, 3]
    for c in dtu.cameras:
        i = int(c.name)
        wm = cams[f"world_mat_{i}"].astype(np.float64)
        # original projection, pixel coordinates of the 1600x1200 images scaled to 400x300
        p = np.c_[X, np.ones(500)] @ wm[:3].T
        uv_ref = p[:, :2] / p[:, 2:3] * 0.25
        uv, z = c.project(Xl)
        assert np.all(z > 0)
        assert np.abs(uv - uv_ref).max() <= 1e-3, c.name
        # the decomposition itself is exact in float64
        K, R, t = decompose_projection(wm @ scale_mat)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0 and K[0, 0] > 0 and K[1, 1] > 0
        P2 = K @ np.c_[R, t]
        ref = (wm @ scale_mat)[:3]
        assert np.allclose(P2 / P2[2, 3], ref / ref[2, 3], rtol=1e-9, atol=1e-9)


@needs_shared
def test_loading_writes_nothing_into_the_dataset(fern, lego, dtu, shared_listing):
    load_scene(str(SHARED / "llff_fern"))
    assert _listing(SHARED) == shared_listing


@needs_shared
def test_registry_names_roots_and_env(monkeypatch, tmp_path):
    s = load_scene("llff", root=SHARED)
    assert s.name == "llff_fern" and len(s.train) == 3 and len(s.test) == 3
    monkeypatch.setenv("WARPGS_DATA_ROOT", str(SHARED))
    assert load_scene("dtu").name == "dtu_scan65"
    # a root without the data: the message says where it looked and how to get it
    with pytest.raises(DatasetNotFoundError) as e:
        load_scene("llff", root=tmp_path)
    assert str(tmp_path / "llff_fern") in str(e.value) and "nerf_llff_data" in str(e.value)
    monkeypatch.delenv("WARPGS_DATA_ROOT")
    with pytest.raises(DatasetNotFoundError) as e:
        load_scene("dl3dv", root=tmp_path)
    assert str(tmp_path) in str(e.value) and "github.com/DL3DV-10K/Dataset" in str(e.value) and "images_4" in str(e.value)
    # paths are detected
    assert detect_format(SHARED / "llff_fern")[0] == "llff"
    assert detect_format(SHARED / "blender_lego")[0] == "blender"
    assert detect_format(SHARED / "dtu_scan65")[0] == "dtu"


# ----------------------------------------------------------------------------------------------
# splits


def test_split_rules():
    train, test = every_nth_split(20, 3)
    assert test == [0, 8, 16] and train == [1, 10, 19]
    train, test = every_nth_split(30, 9)
    rest = [i for i in range(30) if i % 8]
    assert test == [0, 8, 16, 24] and train == [rest[int(round(x))] for x in np.linspace(0, len(rest) - 1, 9)]
    assert every_nth_split(10, None)[0] == [1, 2, 3, 4, 5, 6, 7, 9]
    # test_rest: the same training views, every other frame a test view
    assert every_nth_split(20, 3, test_rest=True) == ([1, 10, 19], [i for i in range(20) if i not in (1, 10, 19)])
    with pytest.raises(SceneError):
        every_nth_split(10, 9)
    assert dtu_split(49, 6)[0] == [25, 22, 28, 40, 44, 48]


# ----------------------------------------------------------------------------------------------
# COLMAP readers


def _random_model(rng, n_img=5):
    cams = {
        1: colmap_io.ColmapCamera(1, "PINHOLE", 64, 48, np.array([50.0, 51.0, 32.0, 24.0])),
        2: colmap_io.ColmapCamera(2, "OPENCV", 64, 48, np.array([50.0, 50.0, 31.5, 24.5, 0.01, -0.002, 0.001, 0.0005])),
    }
    imgs = {}
    for k in range(1, n_img + 1):
        q = rng.normal(size=4)
        q = q / np.linalg.norm(q) * np.sign(q[0])
        im = colmap_io.ColmapImage(k, q, rng.normal(size=3), 1 + k % 2, f"img_{k:03d}.png")
        im.xys = rng.uniform(0, 48, (3, 2))
        im.point3d_ids = np.array([1, -1, 2])
        imgs[k] = im
    pts = colmap_io.ColmapPoints(np.arange(1, 8), rng.normal(size=(7, 3)), rng.integers(0, 256, (7, 3)).astype(np.uint8), rng.uniform(0, 2, 7), np.zeros(7, np.int64))
    return cams, imgs, pts


@pytest.mark.parametrize("binary", [True, False])
def test_colmap_roundtrip(tmp_path, binary):
    cams, imgs, pts = _random_model(np.random.default_rng(1))
    colmap_io.write_model(tmp_path, cams, imgs, pts, binary=binary)
    c2, i2, p2 = colmap_io.read_model(tmp_path, with_points2d=True)
    assert c2.keys() == cams.keys()
    for k in cams:
        assert c2[k].model == cams[k].model and (c2[k].width, c2[k].height) == (64, 48)
        assert np.array_equal(c2[k].params, cams[k].params)
    for k in imgs:
        assert i2[k].name == imgs[k].name and i2[k].camera_id == imgs[k].camera_id
        assert np.array_equal(i2[k].qvec, imgs[k].qvec) and np.array_equal(i2[k].tvec, imgs[k].tvec)
        assert np.array_equal(i2[k].xys, imgs[k].xys) and np.array_equal(i2[k].point3d_ids, imgs[k].point3d_ids)
    assert np.array_equal(p2.xyz, pts.xyz) and np.array_equal(p2.rgb, pts.rgb) and np.array_equal(p2.ids, pts.ids)
    # quaternion convention: (w, x, y, z) of the world-to-camera rotation, round trip through matrices
    R = imgs[1].viewmat()[:3, :3]
    assert np.allclose(colmap_io.qvec_to_rotmat(colmap_io.rotmat_to_qvec(R)), R, atol=1e-12)
    assert np.allclose(colmap_io.qvec_to_rotmat([np.cos(0.3), 0, 0, np.sin(0.3)])[:2, :2], [[np.cos(0.6), -np.sin(0.6)], [np.sin(0.6), np.cos(0.6)]])


def test_colmap_truncated_file(tmp_path):
    cams, imgs, pts = _random_model(np.random.default_rng(2))
    colmap_io.write_model(tmp_path, cams, imgs, pts, binary=True)
    data = (tmp_path / "images.bin").read_bytes()
    (tmp_path / "images.bin").write_bytes(data[: len(data) // 2])
    with pytest.raises(SceneError, match="images.bin.*ends early"):
        colmap_io.read_model(tmp_path)


# ----------------------------------------------------------------------------------------------
# small nerfstudio / COLMAP captures written into tmp_path


def _look(c2w_gl_pos, yaw):
    c2w = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    c2w[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    c2w[:3, 3] = c2w_gl_pos
    return c2w


def write_capture(root: Path, n=10, w=16, h=12, extra=None, image_fn=None, frame_edit=None, colmap=False) -> Path:
    """A tiny nerfstudio capture (and optionally its COLMAP twin) with random images."""
    rng = np.random.default_rng(0)
    (root / "images").mkdir(parents=True)
    frames, c2ws = [], []
    for k in range(n):
        img = image_fn(k) if image_fn else (rng.random((h, w, 3)) * 255).astype(np.uint8)
        Image.fromarray(img).save(root / "images" / f"frame_{k + 1:05d}.png")
        c2w = _look([0.1 * k, 0.02 * k, 0.0], 0.05 * k)
        c2ws.append(c2w)
        fr = {"file_path": f"images/frame_{k + 1:05d}.png", "transform_matrix": c2w.tolist()}
        if frame_edit:
            frame_edit(k, fr)
        frames.append(fr)
    meta = {"w": w, "h": h, "fl_x": 20.0, "fl_y": 21.0, "cx": w / 2, "cy": h / 2, "camera_model": "OPENCV", "frames": frames}
    meta.update(extra or {})
    (root / "transforms.json").write_text(json.dumps(meta))
    if colmap:
        cams = {1: colmap_io.ColmapCamera(1, "PINHOLE", w, h, np.array([20.0, 21.0, w / 2, h / 2]))}
        imgs = {}
        for k, c2w in enumerate(c2ws):
            cv = c2w.copy()
            cv[:3, 1:3] *= -1
            vm = np.linalg.inv(cv)
            imgs[k + 1] = colmap_io.ColmapImage(k + 1, colmap_io.rotmat_to_qvec(vm[:3, :3]), vm[:3, 3], 1, f"frame_{k + 1:05d}.png")
        colmap_io.write_model(root / "sparse" / "0", cams, imgs, None, binary=False)
    return root


def test_nerfstudio_and_colmap_agree(tmp_path):
    root = write_capture(tmp_path / "cap", colmap=True)
    before = _listing(root)
    a = load_nerfstudio(root, views=3)
    assert detect_format(root)[0] == "nerfstudio"
    (root / "transforms.json").rename(tmp_path / "moved.json")  # now only the COLMAP model describes it
    assert detect_format(root)[0] == "colmap"
    b = load_colmap(root, views=3)
    (tmp_path / "moved.json").rename(root / "transforms.json")
    assert _listing(root) == before
    assert [c.name for c in a.train] == [c.name for c in b.train] == ["frame_00002", "frame_00006", "frame_00010"]
    assert [c.name for c in a.test] == ["frame_00001", "frame_00009"]
    for ca, cb in zip(a.cameras, b.cameras):
        assert np.allclose(ca.viewmat, cb.viewmat, atol=1e-6) and np.allclose(ca.K, cb.K)
        assert np.array_equal(ca.image, cb.image)
    # OpenGL -> OpenCV: the camera looks down -z of its OpenGL frame
    c = a.train[0]
    assert np.allclose(c.forward, -np.asarray(_look([0, 0, 0], 0.05)[:3, 2]), atol=1e-6)
    t = c.to_torch("cpu")
    assert tuple(t.image.shape) == (12, 16, 3) and t.viewmat.dtype.is_floating_point and t.viewmat.shape == (4, 4)


def test_capture_bounds_without_depth_or_points_are_left_to_the_geometry(tmp_path):
    """A capture with poses only has no depth to bound: the loader's camera-extent guess (1% to 10x) is
    flagged, and the summary says the bounds come from the initial geometry rather than print the guess."""
    bare = load_nerfstudio(write_capture(tmp_path / "bare"), views=3)
    assert bare.bounds_guessed and "measured on the initial geometry" in bare.summary()
    near, far = bare.bounds
    assert far / near == pytest.approx(1000.0)  # the guess spans three decades (only the last-resort frustum init uses it)
    measured = dataclasses.replace(bare, bounds=(2.0, 9.5), bounds_guessed=False)
    assert "bounds 2..9.5" in measured.summary()


def test_downscale_folders_and_in_memory(tmp_path):
    root = write_capture(tmp_path / "cap", w=32, h=24)
    (root / "images_2").mkdir()
    for p in sorted((root / "images").iterdir()):
        Image.open(p).resize((16, 12), Image.BOX).save(root / "images_2" / p.name)
    s1, s2 = load_nerfstudio(root, views=3, downscale=1), load_nerfstudio(root, views=3, downscale=2)
    assert Path(s2.train[0].image_path).parent.name == "images_2"
    assert np.allclose(s2.train[0].K[:2], s1.train[0].K[:2] / 2)
    s4 = load_nerfstudio(root, views=3, downscale=4)  # no images_4: box-filtered in memory, nothing written
    assert (s4.train[0].width, s4.train[0].height) == (8, 6) and np.allclose(s4.train[0].K[:2], s1.train[0].K[:2] / 4)
    assert not (root / "images_4").exists()
    assert np.allclose(s4.train[0].image, s1.train[0].image.reshape(6, 4, 8, 4, 3).mean(axis=(1, 3)), atol=1e-6)


def _distort(x, y, k1, k2, p1, p2):
    r2 = x * x + y * y
    rad = 1 + k1 * r2 + k2 * r2 * r2
    return x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y


def test_distortion_is_removed_or_refused(tmp_path):
    w, h, f = 48, 36, 40.0
    dist = {"k1": -0.25, "k2": 0.05, "p1": 0.004, "p2": -0.003}

    def pattern(x, y):  # a smooth function of the pinhole (undistorted) normalised coordinates
        return 0.5 + 0.4 * np.sin(12 * x) * np.cos(9 * y)

    def distorted_image(_k):
        # each distorted pixel shows the scene point whose undistorted coordinates map onto it: invert the
        # distortion by fixed-point iteration (independent of the loader's forward mapping)
        u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        xd, yd = (u - w / 2) / f, (v - h / 2) / f
        x, y = xd.copy(), yd.copy()
        for _ in range(50):
            ex, ey = _distort(x, y, **dist)
            x, y = x - (ex - xd), y - (ey - yd)
        g = pattern(x, y)
        return (np.repeat(g[..., None], 3, axis=2) * 255).round().astype(np.uint8)

    def stamped(k):  # each frame its own file (a corner pixel outside the compared region differs)
        img = distorted_image(k)
        img[0, 0] = k
        return img

    root = write_capture(tmp_path / "cap", n=4, w=w, h=h, image_fn=stamped, extra={"fl_x": f, "fl_y": f, **dist})
    with pytest.raises(SceneError, match="distortion"):
        load_nerfstudio(root, views=1, undistort=False)
    s = load_nerfstudio(root, views=1, undistort=True)
    img = s.train[0].image[..., 0]
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    ref = pattern((u - w / 2) / f, (v - h / 2) / f)
    inner = (slice(4, h - 4), slice(4, w - 4))
    err = np.abs(img[inner] - ref[inner]).max()
    assert err < 0.03, err
    # ignoring the distortion would be visibly wrong
    assert np.abs(distorted_image(0)[..., 0][inner] / 255.0 - ref[inner]).max() > 0.15


def _numpy_undistort_coords(K, dist, width, height):
    """The loader's own undistortion before it used OpenCV (kept here as the oracle): for each pixel centre of
    the pinhole image, where it lies in the distorted one (library convention, centres at +0.5)."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    g = {k: float(dist.get(k, 0.0)) for k in ("k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2")}
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    x, y = (u - cx) / fx, (v - cy) / fy
    r2 = x * x + y * y
    radial = (1 + r2 * (g["k1"] + r2 * (g["k2"] + r2 * g["k3"]))) / (1 + r2 * (g["k4"] + r2 * (g["k5"] + r2 * g["k6"])))
    xd = x * radial + 2 * g["p1"] * x * y + g["p2"] * (r2 + 2 * x * x)
    yd = y * radial + g["p1"] * (r2 + 2 * y * y) + 2 * g["p2"] * x * y
    return fx * xd + cx, fy * yd + cy


def _numpy_remap(a, u, v, nearest=False):
    """The loader's old sampler (the oracle): bilinear at continuous pixel coordinates, edges clamped."""
    h, w = a.shape[:2]
    if nearest:
        return a[np.clip(np.floor(v).astype(int), 0, h - 1), np.clip(np.floor(u).astype(int), 0, w - 1)]
    x, y = np.clip(u - 0.5, 0, w - 1), np.clip(v - 0.5, 0, h - 1)
    j0, i0 = np.minimum(np.floor(x).astype(int), w - 2), np.minimum(np.floor(y).astype(int), h - 2)
    fx, fy = x - j0, y - i0
    if a.ndim == 3:
        fx, fy = fx[..., None], fy[..., None]
    return (a[i0, j0] * (1 - fx) * (1 - fy) + a[i0, j0 + 1] * fx * (1 - fy)
            + a[i0 + 1, j0] * (1 - fx) * fy + a[i0 + 1, j0 + 1] * fx * fy).astype(a.dtype)


# fox-like captures (nerfstudio / instant-ngp OPENCV with k1, k2, p1, p2), the case above, COLMAP's
# SIMPLE_RADIAL and a FULL_OPENCV rational model
DISTORTION_CASES = {
    "fox_like": (1080 // 8, 1920 // 8, 1375.5 / 8, {"k1": 0.0335, "k2": -0.0245, "p1": 0.0011, "p2": -0.0008}),
    "strong": (36, 48, 40.0, {"k1": -0.25, "k2": 0.05, "p1": 0.004, "p2": -0.003}),
    "simple_radial": (60, 80, 70.0, {"k1": 0.08}),
    "full_opencv": (48, 64, 50.0, {"k1": -0.1, "k2": 0.02, "k3": -0.003, "k4": 0.05, "k5": -0.01, "k6": 0.002,
                                   "p1": 0.002, "p2": 0.001}),
}


@pytest.mark.parametrize("case", sorted(DISTORTION_CASES))
def test_opencv_undistortion_matches_the_former_numpy_one(case):
    """OpenCV's map + remap give what the loader's own numpy code gave: sample positions to 1e-3 px (the
    maps are float32; OpenCV 5 is exact for 1, 3 and 4 channels, older versions interpolate at 1/32-pixel steps,
    which the bounds allow), bilinear values to 1/32 of the largest step between neighbouring pixels,
    nearest-neighbour values exactly except at exact ties. Without the half-pixel shift between the library's
    pixel centres and OpenCV's, every bound here fails."""
    from warpgs.data.nerfstudio import undistort_image

    h, w, f, dist = DISTORTION_CASES[case]
    K = np.array([[f, 0, w / 2 + 0.3], [0, f * 1.01, h / 2 - 0.2], [0, 0, 1.0]])
    rng = np.random.default_rng(7)
    # a smooth image plus noise: both sharp steps and gradients
    yy, xx = np.mgrid[0:h, 0:w]
    rgb = (0.5 + 0.3 * np.sin(xx[..., None] * [0.3, 0.17, 0.05] + yy[..., None] * [0.11, 0.23, 0.4])
           + 0.15 * rng.random((h, w, 3))).astype(np.float32)
    u, v = _numpy_undistort_coords(K, dist, w, h)
    want = _numpy_remap(rgb, u, v)
    got = undistort_image(rgb, K, dist)
    assert got.shape == rgb.shape and got.dtype == np.float32
    step = max(np.abs(np.diff(rgb, axis=0)).max(), np.abs(np.diff(rgb, axis=1)).max())
    err = np.abs(got - want).max()
    assert err <= step / 32 + 1e-6, (err, step)
    # the positions themselves, through a coordinate image (bilinear interpolation of a linear ramp is exact)
    ramp = np.stack([*np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), np.zeros((h, w))], -1).astype(np.float32)
    inside = (u > 0.5) & (u < w - 0.5) & (v > 0.5) & (v < h - 0.5)
    pos = undistort_image(ramp, K, dist)
    assert inside.mean() > 0.5
    assert np.abs(pos[..., 0] - u)[inside].max() < 1 / 32 + 1e-3 and np.abs(pos[..., 1] - v)[inside].max() < 1 / 32 + 1e-3
    # masks and depth: nearest neighbour
    mask = rng.random((h, w)) > 0.5
    depth = rng.uniform(1, 5, (h, w)).astype(np.float32)
    for a in (mask, depth):
        got_n = undistort_image(a, K, dist, nearest=True)
        assert got_n.dtype == a.dtype and got_n.shape == a.shape
        assert (got_n == _numpy_remap(a, u, v, nearest=True)).mean() > 0.995
    # the distortion does move pixels, so the comparison is not trivially between identities
    assert np.abs(np.hypot(u - ramp[..., 0], v - ramp[..., 1])).max() > 0.3


# ----------------------------------------------------------------------------------------------
# bad input


def _err(fn, *match):
    with pytest.raises(SceneError) as e:
        fn()
    for m in match:
        assert m in str(e.value), str(e.value)
    return str(e.value)


def test_bad_nerfstudio_inputs(tmp_path):
    r = write_capture(tmp_path / "missing")
    (r / "images" / "frame_00003.png").unlink()
    before = _listing(r)
    _err(lambda: load_nerfstudio(r, views=None), "frame_00003.png", "missing")
    assert _listing(r) == before

    r = write_capture(tmp_path / "nopose", frame_edit=lambda k, fr: fr.pop("transform_matrix") if k == 4 else None)
    _err(lambda: load_nerfstudio(r), "transforms.json", "frame_00005.png", "no pose")

    def nan(k, fr):
        if k == 2:
            fr["transform_matrix"][0][3] = float("nan")

    r = write_capture(tmp_path / "nan", frame_edit=nan)
    _err(lambda: load_nerfstudio(r, views=None), "frame_00003.png", "non-finite")

    def scaled(k, fr):
        if k == 1:
            m = np.array(fr["transform_matrix"])
            m[:3, :3] *= 2.0
            fr["transform_matrix"] = m.tolist()

    r = write_capture(tmp_path / "scaled", frame_edit=scaled)
    _err(lambda: load_nerfstudio(r, views=None), "frame_00002.png", "not rigid")

    r = write_capture(tmp_path / "mixed")
    Image.fromarray(np.zeros((10, 20, 3), np.uint8)).save(r / "images" / "frame_00004.png")
    _err(lambda: load_nerfstudio(r, views=None), "frame_00004.png", "20x10")
    Image.fromarray(np.zeros((6, 8, 3), np.uint8)).save(r / "images" / "frame_00004.png")  # a valid /2 size, but mixed
    _err(lambda: load_nerfstudio(r, views=None), "frame_00004.png", "8x6", "mixed image sizes")

    r = write_capture(tmp_path / "fisheye", extra={"camera_model": "OPENCV_FISHEYE"})
    _err(lambda: load_nerfstudio(r, views=None), "OPENCV_FISHEYE")

    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("hello")
    _err(lambda: load_scene(str(tmp_path / "junk")), "junk", "unknown scene layout")
    _err(lambda: load_scene(str(tmp_path / "nowhere")), "nowhere")
    (tmp_path / "badjson").mkdir()
    (tmp_path / "badjson" / "transforms.json").write_text("{not json")
    _err(lambda: load_scene(str(tmp_path / "badjson")), "transforms.json", "JSON")


def test_bad_llff_dtu_blender_inputs(tmp_path):
    # LLFF: one more image than poses
    r = tmp_path / "llff"
    (r / "images_8").mkdir(parents=True)
    rows = []
    for k in range(5):
        Image.fromarray(np.full((6, 8, 3), k, np.uint8)).save(r / "images_8" / f"img{k}.png")  # distinct frames
        R = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])  # [down, right, back] of a camera looking along +z
        rows.append(np.r_[np.c_[R, [0.1 * k, 0, 0], [48, 64, 50]].ravel(), 1.0, 10.0])
    np.save(r / "poses_bounds.npy", np.array(rows[:4]))
    _err(lambda: load_llff(r, views=2), "poses_bounds.npy", "4 poses", "5 images")
    np.save(r / "poses_bounds.npy", np.array(rows))
    s = load_llff(r, views=2)
    assert np.allclose(s.train[0].K[0, 0], 50 * 8 / 64)
    rows[3][3] = np.inf
    np.save(r / "poses_bounds.npy", np.array(rows))
    _err(lambda: load_llff(r, views=2), "poses_bounds.npy", "non-finite")

    # DTU: an image without a world_mat
    r = tmp_path / "dtu"
    (r / "image").mkdir(parents=True)
    for k in range(3):
        Image.fromarray(np.zeros((3, 4, 3), np.uint8)).save(r / "image" / f"{k:06d}.png")
    np.savez(r / "cameras.npz", world_mat_0=np.eye(4), world_mat_1=np.eye(4))
    _err(lambda: load_dtu(r), "cameras.npz", "world_mat_2", "000002.png")

    # Blender: a listed frame whose image is missing
    r = tmp_path / "blender"
    r.mkdir()
    frames = [{"file_path": f"./train/r_{i}", "transform_matrix": np.eye(4).tolist()} for i in (26, 86, 2, 55, 75, 93, 16, 73)]
    for name in ("train", "test"):
        (r / f"transforms_{name}.json").write_text(json.dumps({"camera_angle_x": 0.69, "frames": frames}))
    _err(lambda: load_blender(r), "r_26.png", "missing")


# ----------------------------------------------------------------------------------------------
# plausibility (warpgs/data/plausible.py)


def test_impossible_cameras_are_refused_naming_frame_and_field_unless_allowed(tmp_path):
    from warpgs.data import load_scene

    r = write_capture(tmp_path / "far_cx", extra={"cx": 1e6})  # the principal point 60,000 images to the right
    _err(lambda: load_scene(str(r), views=3), "frame_0000", "cx = 1e+06", "allow_implausible_camera")
    s = load_scene(str(r), views=3, allow_implausible_camera=True)  # a user who means it
    assert s.train[0].K[0, 2] == pytest.approx(1e6)
    r = write_capture(tmp_path / "tele", extra={"fl_x": 1e30, "fl_y": 1e30})
    _err(lambda: load_scene(str(r), views=3), "fx = 1e+30", "implausible intrinsics")
    r = write_capture(tmp_path / "k1", extra={"k1": 40.0})  # the corner's radius x 1+ 40 r^2: no lens
    _err(lambda: load_scene(str(r), views=3), "k1 = 40", "lens distortion")
    # the edges of what real cameras do load: a wide lens, a long one, an off-centre crop, a barrel distortion
    for k, extra in enumerate(({"fl_x": 1.0, "fl_y": 1.0}, {"fl_x": 1500.0, "fl_y": 1500.0}, {"cx": -10.0, "cy": 20.0},
                               {"k1": -0.2, "k2": 0.03})):
        assert len(load_scene(str(write_capture(tmp_path / f"ok{k}", extra=extra)), views=3).train) == 3


@pytest.mark.parametrize("how", ["spelling", "symlink", "copy"])
def test_one_frame_twice_is_refused_naming_both_unless_allowed(tmp_path, how):
    from warpgs.data import load_scene

    def edit(k, fr):
        if k == 4:
            fr["file_path"] = {"spelling": "images/./frame_00002.png", "symlink": "images/alias.png",
                               "copy": "images/copy.png"}[how]

    r = write_capture(tmp_path / "cap", frame_edit=edit)
    if how == "symlink":
        (r / "images" / "alias.png").symlink_to("frame_00002.png")
    elif how == "copy":
        (r / "images" / "copy.png").write_bytes((r / "images" / "frame_00002.png").read_bytes())
    _err(lambda: load_scene(str(r), views=3), "frame_00002.png", "allow_duplicate_frames",
         "listed twice" if how != "copy" else "byte-identical")
    assert len(load_scene(str(r), views=3, allow_duplicate_frames=True).train) == 3
