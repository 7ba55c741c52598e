"""bench/diagnostics/depth_prior_trace.py: the check of a depth map against 3D points, on an analytic case."""

import sys
from pathlib import Path
from types import SimpleNamespace

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.diagnostics.depth_prior_trace import check_against_points  # noqa: E402


def test_points_on_confident_pixels_against_a_depth_map():
    """A camera at the origin looking down +z (fx = fy = 10, 20x10 px): points at z = 4 on the left half's
    pixels, the depth map 4 there except 5 on one column; the right half is not confident, and a point behind
    the camera and one outside the image are left out."""
    cam = SimpleNamespace(viewmat=torch.eye(4), K=torch.tensor([[10.0, 0, 10], [0, 10.0, 5], [0, 0, 1]]),
                          width=20, height=10)
    depth = torch.full((10, 20), 4.0)
    depth[:, 3] = 5.0
    mask = torch.zeros(10, 20, dtype=torch.bool)
    mask[:, :10] = True
    u = torch.arange(20).float() + 0.5  # pixel centres of row 5
    z = torch.full((20,), 4.0)
    xyz = torch.stack([(u - 10) / 10 * z, torch.full((20,), 0.05) * z, z], 1)
    xyz = torch.cat([xyz, torch.tensor([[0.0, 0.0, -4.0], [100.0, 0.0, 4.0]])])
    r = check_against_points(depth, mask, cam, xyz)
    assert r["points_on_confident"] == 10
    assert r["median_rel_err"] == 0.0 and abs(r["share_over_10pct"] - 0.1) < 1e-6  # column 3: |5 - 4| / 4
    assert check_against_points(depth, torch.zeros_like(mask), cam, xyz) == {}
