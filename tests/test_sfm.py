"""SfM initialisation (warpgs/points/sfm.py): triangulated points against ground-truth depth, poses held
fixed (points follow a similarity of the world), determinism, and the one-line errors."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

# pycolmap is a dependency: without it these tests fail (SfmInputError names the pip command), they do not skip
from warpgs.data.scene import Camera, make_camera  # noqa: E402
from warpgs.points.sfm import SfmError, SfmOptions, triangulate  # noqa: E402

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "herz_jesus_p25"


def look_at(eye, target, up=(0.0, -1.0, 0.0)) -> np.ndarray:
    """OpenCV camera-to-world at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
    c2w[:3, 3] = eye
    return c2w


class TexturedRoom:
    """A room corner ray-cast in numpy: floor (y = 1.5, y down), back wall (z = 7), left wall (x = -3.5)
    and a box in front of them, all painted with a smooth random 3D colour field (sums of sinusoids),
    so SIFT finds blobs everywhere. Depth is exact: the ray parameter of the first hit."""

    planes = ((np.array([0.0, 1.0, 0.0]), 1.5), (np.array([0.0, 0.0, 1.0]), 7.0), (np.array([1.0, 0.0, 0.0]), -3.5))
    box = (np.array([-0.8, 0.3, 3.8]), np.array([0.6, 1.5, 4.8]))

    def __init__(self, seed: int = 0, waves: int = 16):
        rng = np.random.default_rng(seed)
        self.freq = rng.normal(size=(3, waves, 3)) * rng.uniform(2.0, 14.0, size=(3, waves, 1))
        self.phase = rng.uniform(0.0, 2 * np.pi, size=(3, waves))

    def colour(self, p: np.ndarray) -> np.ndarray:
        out = np.stack([np.sin(p @ self.freq[c].T + self.phase[c]).sum(-1) for c in range(3)], -1)
        return 0.5 + 0.35 * np.tanh(2.0 * out / np.sqrt(self.freq.shape[1]))

    def render(self, c2w: np.ndarray, K: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
        j, i = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        d = np.stack([(j - K[0, 2]) / K[0, 0], (i - K[1, 2]) / K[1, 1], np.ones_like(j)], -1) @ c2w[:3, :3].T
        o = c2w[:3, 3]
        t = np.full((h, w), np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for n, off in self.planes:
                tp = (off - o @ n) / (d @ n)
                t = np.minimum(t, np.where(tp > 1e-6, tp, np.inf))
            t1, t2 = (self.box[0] - o) / d, (self.box[1] - o) / d
        near, far = np.minimum(t1, t2).max(-1), np.maximum(t1, t2).min(-1)
        t = np.where((near <= far) & (near > 1e-6) & (near < t), near, t)
        # camera-space direction has z = 1, so the ray parameter is the z-depth
        return self.colour(o + d * t[..., None]).astype(np.float32), t.astype(np.float32)


W, H = 256, 192
KMAT = np.array([[0.9 * W, 0, W / 2], [0, 0.9 * W, H / 2], [0, 0, 1.0]])


@pytest.fixture(scope="module")
def room():
    return TexturedRoom(0)


@pytest.fixture(scope="module")
def room_cams(room):
    cams = []
    for k, x in enumerate(np.linspace(-0.6, 0.6, 4)):  # a sideways walk, 0.4 m steps, 3-7 m from the walls
        c2w = look_at((x, 0.0, 0.0), (0.2 * x, 0.4, 5.0))
        img, depth = room.render(c2w, KMAT, W, H)
        cams.append(make_camera(f"v{k}", c2w, KMAT, img, depth=depth))
    return cams


@pytest.fixture(scope="module")
def room_points(room_cams):
    return triangulate(room_cams, log=lambda *_: None)


def _gt_relative_depth_error(cams, xyz) -> np.ndarray:
    """Per point: |z - GT depth| / GT depth at its pixel, in the view where it agrees best (a point is
    triangulated from views that see it; the others may have it occluded)."""
    rel = np.full((len(cams), len(xyz)), np.inf)
    for k, c in enumerate(cams):
        uv, z = c.project(xyz)
        j, i = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        ok = (z > 0) & (j >= 0) & (i >= 0) & (j < c.width) & (i < c.height)
        gt = c.depth[i[ok], j[ok]]
        rel[k, ok] = np.abs(z[ok] - gt) / gt
    return rel.min(0)


def test_points_match_ground_truth_depth(room, room_cams, room_points):
    pts = room_points
    assert len(pts.xyz) > 300, pts.stats
    assert pts.xyz.dtype == np.float32 and pts.rgb.dtype == np.float32 and pts.xyz.shape == pts.rgb.shape
    assert len(pts.track_length) == len(pts.error) == len(pts.xyz)
    assert pts.track_length.min() >= 2 and pts.stats["views"] == 4
    rel = _gt_relative_depth_error(room_cams, pts.xyz.astype(np.float64))
    # bounds: median depth error under 1%, 90% of the points within 5% (the rest: depth edges of the box)
    assert np.median(rel) < 0.01, np.median(rel)
    assert np.percentile(rel, 90) < 0.05, np.percentile(rel, 90)
    assert np.median(pts.error) < 0.5 and pts.error.max() <= SfmOptions().max_reproj_error + 1e-3
    # observations: every point projects onto its keypoints in the views that see it
    obs = pts.observations
    assert len(obs) == pts.track_length.sum() and np.all(np.diff(obs[:, 0]) >= 0)
    for k, c in enumerate(room_cams):
        sel = obs[:, 1] == k
        uv, z = c.project(pts.xyz[obs[sel, 0].astype(int)])
        assert np.all(z > 0) and np.all(np.linalg.norm(uv - obs[sel, 2:4], axis=1) < SfmOptions().max_reproj_error)
    # colours: the mean of the images at the keypoints, close to the surface colour at the point
    assert np.abs(room.colour(pts.xyz.astype(np.float64)) - pts.rgb).mean() < 0.08
    assert {"extract", "match", "triangulate", "total"} <= set(pts.stats["seconds"])


def test_points_follow_a_similarity_of_the_world(room_cams, room_points):
    """Poses are held fixed: the same images under a scaled, rotated, shifted world give the same points
    mapped by that similarity."""
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))
    s, t = 2.5, np.array([10.0, -3.0, 7.0])
    moved = []
    for c in room_cams:
        V = c.viewmat.astype(np.float64)
        V2 = np.eye(4)
        V2[:3, :3] = V[:3, :3] @ R.T  # x' = s R x + t  ->  camera = V R^T (x' - t) / s, scaled by s
        V2[:3, 3] = s * V[:3, 3] - V2[:3, :3] @ t
        moved.append(Camera(c.name, V2.astype(np.float32), c.K, c.width, c.height, c.image))
    pts2 = triangulate(moved, log=lambda *_: None)
    expect = s * room_points.xyz.astype(np.float64) @ R.T + t
    assert abs(len(pts2.xyz) - len(expect)) <= 0.02 * len(expect)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(expect).query(pts2.xyz.astype(np.float64))
    assert np.median(d) < 1e-3 * s, np.median(d)  # metres * s; the scene is ~5 m deep
    assert np.mean(d < 1e-2 * s) > 0.98


def test_deterministic_and_workdir(room_cams, room_points, tmp_path):
    again = triangulate(room_cams, workdir=tmp_path, log=lambda *_: None)
    np.testing.assert_array_equal(again.xyz, room_points.xyz)
    np.testing.assert_array_equal(again.rgb, room_points.rgb)
    assert (tmp_path / "database.db").is_file() and (tmp_path / "images" / "0000.png").is_file()


def test_one_line_summary(room_cams):
    lines = []
    triangulate(room_cams[:2], log=lines.append)
    assert len(lines) == 1 and lines[0].startswith("sfm: ") and "from 2 views" in lines[0]


def test_one_view_is_an_error(room_cams):
    with pytest.raises(SfmError, match="at least 2 training views, got 1"):
        triangulate(room_cams[:1], log=lambda *_: None)


def test_blank_images_say_no_matches(room_cams):
    grey = [Camera(c.name, c.viewmat, c.K, c.width, c.height, np.full_like(c.image, 0.5)) for c in room_cams[:3]]
    with pytest.raises(SfmError, match=r"no feature matches between the 3 training views.*textureless") as e:
        triangulate(grey, log=lambda *_: None)
    assert "\n" not in str(e.value)


def test_pycolmap_missing_names_the_pip_command(room_cams, monkeypatch):
    monkeypatch.setitem(sys.modules, "pycolmap", None)  # `import pycolmap` raises ImportError (in this process)
    with pytest.raises(SfmError, match=r"pycolmap is not installed: pip install pycolmap"):
        triangulate(room_cams, log=lambda *_: None, isolate=False)


def test_bad_options_and_shapes(room_cams):
    with pytest.raises(SfmError, match="verification"):
        triangulate(room_cams, SfmOptions(verification="magic"), log=lambda *_: None)
    bad = Camera("x", room_cams[0].viewmat, room_cams[0].K, W + 1, H, room_cams[0].image)
    with pytest.raises(SfmError, match="does not match"):
        triangulate([bad, room_cams[1]], log=lambda *_: None)


@pytest.mark.skipif(not REAL.is_dir(), reason=f"{REAL} not present")
def test_real_scene_three_views_small():
    from warpgs.data.registry import load_scene

    scene = load_scene(str(REAL), views=3, downscale=8)
    pts = triangulate(scene.train, log=lambda *_: None)
    assert len(pts.xyz) > 40, pts.stats
    assert np.median(pts.error) < 0.5
    depths = np.stack([c.project(pts.xyz)[1] for c in scene.train])
    assert np.all(depths.max(0) > 0)  # every point is in front of some view (it is in front of those that see it)
