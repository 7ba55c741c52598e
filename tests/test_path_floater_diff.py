"""bench/path_floater_diff.py's edge test: analytic cases of a pinhole camera."""

from types import SimpleNamespace

import torch

from bench.path_floater_diff import edge_shares


def _cam():
    # looks down +z from the origin, 100x100 pixels, focal 100, centre (50, 50)
    return SimpleNamespace(viewmat=torch.eye(4), K=torch.tensor([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]]),
                           width=100, height=100)


def test_edge_shares_of_points_inside_at_the_edge_and_outside():
    # centre pixel; 2 px from the left edge (inside 5%); outside the image (x = -10 px); behind the camera
    pts = torch.tensor([[0.0, 0.0, 1.0], [-0.48, 0.0, 1.0], [-0.6, 0.0, 1.0], [0.0, 0.0, -1.0]])
    outside, edge = edge_shares(pts, [_cam()])
    assert outside == 0.5 and edge == 0.25
    # a second camera, shifted so that the edge point is central there: it is no longer "near the edge of every
    # input that sees it"
    shifted = _cam()
    shifted.viewmat = torch.eye(4)
    shifted.viewmat[0, 3] = 0.48
    outside, edge = edge_shares(pts, [_cam(), shifted])
    assert edge == 0.0
    assert edge_shares(pts[:0], [_cam()]) == (0.0, 0.0)
