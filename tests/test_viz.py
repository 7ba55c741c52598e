"""``python -m warpgs.viz``: PLY reading, the headless PNG of a densified cloud, and the splat renderer."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from test_stereo import room_rig
from warpgs.densify import DensifyConfig, densify_gaussians
from warpgs.densify.stereo import unproject
from warpgs.viz import (
    ORIGIN_COLORS,
    default_camera,
    main,
    open3d_render,
    read_cloud,
    render_png,
    save_origin_ply,
    splat_render,
)

REPO = Path(__file__).resolve().parents[1]
ARTIFACTS = REPO / "outputs" / "test_artifacts"


def _open3d_offscreen_works() -> bool:
    try:
        img = open3d_render(np.zeros((1, 3)), np.zeros((1, 3)), *default_camera(np.zeros((1, 3)), 32, 24), 32, 24, 4.0)
        return img.shape == (24, 32, 3)
    except Exception:
        return False


@pytest.fixture(scope="module")
def densified(tmp_path_factory):
    """The full densification on five views of the synthetic room: existing Gaussians are a sparse
    sample of the surface (like SfM points) on the left of the centre view; the stereo cloud of two
    selected views fills in around them."""
    images, Ks, vms, gt = room_rig(64, 48, yaw=-1.0, baseline=0.3)
    left = gt[0] > 0
    left[:, 32:] = False
    existing, _ = unproject(gt[0], Ks[0], vms[0], left)
    existing = existing[::6].contiguous()
    cfg = DensifyConfig()
    cfg.select.views = 2
    out = densify_gaussians(existing, images, Ks, vms, (1.2, 9.0), cfg)
    path = save_origin_ply(tmp_path_factory.mktemp("viz") / "densified.ply", *out.origin_cloud(existing))
    return out, existing, path


def test_densified_cloud_png(densified, tmp_path):
    """The test suite's picture of a densified cloud (kept / added / removed), through the CLI."""
    out, existing, ply = densified
    assert len(out.references) == 2 and len(out.insertion.means) > 100
    cloud = read_cloud(ply)
    counts = [int((cloud["origin"] == k).sum()) for k in range(3)]
    assert counts == [len(existing), len(out.insertion.means), int(out.filter.removed.sum())]
    png = ARTIFACTS / "densified_cloud.png"
    png.parent.mkdir(parents=True, exist_ok=True)  # viz writes into an existing folder only
    r = subprocess.run([sys.executable, "-m", "warpgs.viz", str(ply), "--png", str(png), "--size", "480x360",
                        "--point-size", "3"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    used = r.stdout.strip().split("renderer: ")[-1].rstrip(")")
    print(f"wrote {png} with {used}; kept/added/removed = {counts}")
    assert used in ("open3d-egl", "numpy-splat")
    img = np.asarray(Image.open(png).convert("RGB")).astype(np.float32) / 255
    assert img.shape == (360, 480, 3)
    body = img[60:]  # below the legend
    drawn = np.abs(body - 1.0).max(-1) > 0.05
    assert drawn.mean() > 0.03  # a real picture, not a blank frame
    for k, n in enumerate(counts):  # each origin that exists shows up in its colour
        seen = (np.abs(body - ORIGIN_COLORS[k]).max(-1) < 0.03).sum()
        assert (seen > 0) == (n > 0) or n < 5, (k, n, seen)
    # the same view with the file's own colours, and the numpy renderer at the same camera
    assert main([str(ply), "--png", str(tmp_path / "rgb.png"), "--color", "rgb", "--size", "160x120"]) == 0
    assert render_png(cloud, tmp_path / "np.png", 160, 120, 3, renderer="numpy") == "numpy-splat"


def test_splat_renderer_projects_and_occludes():
    K = np.array([[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]])
    vm = np.eye(4)
    # a point at depth 2 that projects to the centre of pixel (i=10, j=40): u = 40.5, v = 10.5
    z = 2.0
    p = np.array([[(40.5 - 32) * z / 50, (10.5 - 24) * z / 50, z]])
    img = splat_render(p, [[1.0, 0, 0]], K, vm, 64, 48, point_size=1, background=(0, 0, 0))
    assert np.argwhere(img.sum(-1) > 0).tolist() == [[10, 40]]
    # a 3-pixel splat covers the 3x3 block around it
    img = splat_render(p, [[1.0, 0, 0]], K, vm, 64, 48, point_size=3, background=(0, 0, 0))
    assert sorted(map(tuple, np.argwhere(img.sum(-1) > 0).tolist())) == [(i, j) for i in (9, 10, 11) for j in (39, 40, 41)]
    # the nearer of two points on one ray wins, whatever the order; points behind the camera vanish
    near, far = p * 0.5, p * 2.0
    for pts, cols in (([near[0], far[0]], [[0, 1.0, 0], [0, 0, 1.0]]), ([far[0], near[0]], [[0, 0, 1.0], [0, 1.0, 0]])):
        img = splat_render(np.array(pts), np.array(cols), K, vm, 64, 48, 1, (0, 0, 0))
        assert img[10, 40].tolist() == [0, 1.0, 0]
    assert splat_render(-p, [[1.0, 1, 1]], K, vm, 64, 48, 1, (0, 0, 0)).sum() == 0


def test_default_camera_frames_the_cloud():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(3000, 3)) * [4.0, 1.0, 0.2] + [10, -3, 2]  # a flat slab, off the origin
    K, vm = default_camera(pts, 320, 240)
    x = pts @ vm[:3, :3].T + vm[:3, 3]
    assert (x[:, 2] > 0).all()
    uv = x @ K.T
    uv = uv[:, :2] / uv[:, 2:3]
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < 320) & (uv[:, 1] >= 0) & (uv[:, 1] < 240)
    assert inside.mean() > 0.97
    # the view looks mostly across the slab's thin axis, so the picture is not a sliver
    assert np.ptp(uv[inside, 1]) > 60 and np.ptp(uv[inside, 0]) > 150
    assert np.allclose(vm[:3, :3] @ vm[:3, :3].T, np.eye(3), atol=1e-9)


@pytest.mark.skipif(not _open3d_offscreen_works(), reason="open3d has no offscreen context here")
def test_open3d_and_splat_renderers_agree():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1, 1, (4000, 3)) * [1, 1, 0.05]
    cols = rng.uniform(0, 1, (4000, 3))
    K, vm = default_camera(pts, 200, 150)
    a = open3d_render(pts, cols, K, vm, 200, 150, 2.0)
    b = splat_render(pts, cols, K, vm, 200, 150, 2.0)
    ma, mb = a.min(-1) < 0.99, b.min(-1) < 0.99
    iou = (ma & mb).sum() / (ma | mb).sum()
    assert iou > 0.8, iou


def test_read_gaussian_ply_and_cli_errors(tmp_path, capsys):
    from warpgs.model import GaussianModel

    m = GaussianModel.from_points(np.random.default_rng(2).uniform(-1, 1, (50, 3)).astype(np.float32),
                                  np.tile([[0.9, 0.2, 0.1]], (50, 1)).astype(np.float32), sh_degree=1)
    path = m.save_ply(tmp_path / "g.ply")
    cloud = read_cloud(path)
    assert cloud["kind"] == "gaussians" and cloud["origin"] is None
    assert np.allclose(cloud["points"], m.means.detach().numpy(), atol=1e-6)
    assert np.allclose(cloud["colors"], [0.9, 0.2, 0.1], atol=1e-5)
    assert main([str(path), "--png", str(tmp_path / "g.png"), "--renderer", "numpy", "--size", "64x48"]) == 0
    assert Image.open(tmp_path / "g.png").size == (64, 48)
    capsys.readouterr()
    assert main([str(tmp_path / "missing.ply"), "--png", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and err.startswith("error: ") and err.count("\n") == 1
    assert main([str(path), "--png", str(tmp_path / "x.png"), "--color", "origin"]) == 2
    # a round trip of an origin cloud keeps points, 8-bit colours and origins
    pts = np.random.default_rng(3).normal(size=(20, 3)).astype(np.float32)
    origin = np.arange(20) % 3
    c = read_cloud(save_origin_ply(tmp_path / "o.ply", pts, np.full((20, 3), 0.5), origin))
    assert np.array_equal(c["points"], pts) and np.array_equal(c["origin"], origin)
    assert np.allclose(c["colors"], 128 / 255)
    with pytest.raises(ValueError):
        save_origin_ply(tmp_path / "bad.ply", pts, None, np.full(20, 3))


def test_window_without_display_says_use_png(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    path = save_origin_ply(tmp_path / "p.ply", np.zeros((3, 3)))
    if sys.platform.startswith("linux"):
        assert main([str(path)]) == 2
        assert "--png" in capsys.readouterr().err


def _one_error(capsys, *words):
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for w in words:
        assert w in err, err


def test_png_into_a_missing_folder_is_refused_and_creates_nothing(tmp_path, capsys):
    path = save_origin_ply(tmp_path / "p.ply", np.random.default_rng(0).normal(size=(10, 3)))
    target = tmp_path / "no" / "such" / "dir" / "x.png"
    assert main([str(path), "--png", str(target), "--renderer", "numpy"]) == 2
    _one_error(capsys, "does not exist")
    assert not (tmp_path / "no").exists()


def test_a_header_claiming_more_vertices_than_the_file_holds_is_refused_before_reading(tmp_path, capsys):
    path = save_origin_ply(tmp_path / "p.ply", np.random.default_rng(0).normal(size=(10, 3)))
    data = path.read_bytes()
    lying = tmp_path / "lying.ply"
    lying.write_bytes(data.replace(b"element vertex 10", b"element vertex 99999999999999"))
    assert main([str(lying), "--png", str(tmp_path / "x.png"), "--renderer", "numpy"]) == 2
    _one_error(capsys, "99999999999999", "bytes after the header")


def test_a_gaussian_ply_without_opacity_scales_or_rotations_is_refused(tmp_path, capsys):
    from warpgs.model import GaussianModel
    from warpgs.ply import read_vertices, write_vertices

    m = GaussianModel.from_points(np.random.default_rng(2).uniform(-1, 1, (20, 3)).astype(np.float32),
                                  np.full((20, 3), 0.5, np.float32), sh_degree=0)
    v = read_vertices(m.save_ply(tmp_path / "g.ply"))
    for drop in (["opacity"], ["scale_0", "scale_1", "scale_2"], ["rot_3"]):
        keep = [k for k in v if k not in drop]
        rec = np.zeros(20, dtype=[(k, "<f4") for k in keep])
        for k in keep:
            rec[k] = v[k]
        write_vertices(tmp_path / "part.ply", rec)
        assert main([str(tmp_path / "part.ply"), "--png", str(tmp_path / "x.png"), "--renderer", "numpy"]) == 2
        _one_error(capsys, *drop)
        assert not (tmp_path / "x.png").exists()
