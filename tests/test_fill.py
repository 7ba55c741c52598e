"""warpgs/points/fill.py: points for the blocks of a training view that no initial point reaches, on an
analytic scene (a fronto-parallel wall at a known depth, half of it covered by points)."""

from __future__ import annotations

import numpy as np
import pytest

from warpgs.data.scene import make_camera
from warpgs.points.fill import fill_points

W, H, F, Z = 64, 32, 50.0, 10.0


def _camera(x=0.0):
    c2w = np.eye(4)
    c2w[0, 3] = x
    K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1]], np.float64)
    rng = np.random.default_rng(0)
    img = rng.random((H, W, 3)).astype(np.float32)
    return make_camera("v", c2w, K, img)


def _left_half_points(cam, stride=8):
    """One point per block of the left half of ``cam``'s image, on the wall z = Z."""
    v, u = np.mgrid[0:H:stride, 0:W // 2:stride] + stride / 2
    rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ np.linalg.inv(cam.K).T
    return rays * Z


def test_fill_covers_the_empty_blocks_on_the_wall_with_their_colours():
    cam = _camera()
    known = _left_half_points(cam)
    xyz, rgb = fill_points([cam], known, stride=8)
    assert len(xyz) == (H // 8) * (W // 2 // 8)  # the right half's blocks, and only those
    np.testing.assert_allclose(xyz[:, 2], Z, rtol=1e-6)  # at the nearest point's depth: the wall's
    uv, z = cam.project(xyz)
    assert (uv[:, 0] > W / 2).all() and (uv[:, 0] < W).all() and (uv[:, 1] > 0).all() and (uv[:, 1] < H).all()
    # each point sits at its block's centre and carries the block's mean colour
    r, c = (uv[:, 1] // 8).astype(int), (uv[:, 0] // 8).astype(int)
    np.testing.assert_allclose(uv % 8, 4.0, atol=1e-4)
    blocks = cam.image.reshape(H // 8, 8, W // 8, 8, 3).mean((1, 3))
    np.testing.assert_allclose(rgb, blocks[r, c], atol=1e-6)


def test_a_second_view_does_not_fill_again_what_the_first_filled():
    a, b = _camera(), _camera()
    xyz, _ = fill_points([a, b], _left_half_points(a), stride=8)
    assert len(xyz) == (H // 8) * (W // 2 // 8)


def test_no_points_at_all_uses_the_default_depth_or_nothing():
    cam = _camera()
    xyz, rgb = fill_points([cam], np.zeros((0, 3)), stride=16)
    assert len(xyz) == 0 and rgb.shape == (0, 3)
    xyz, _ = fill_points([cam], np.zeros((0, 3)), stride=16, default_depth=4.0)
    assert len(xyz) == (H // 16) * (W // 16) and np.allclose(xyz[:, 2], 4.0)
    with pytest.raises(ValueError, match="init_fill"):
        fill_points([cam], np.zeros((0, 3)), stride=0)
