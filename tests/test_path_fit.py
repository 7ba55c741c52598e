"""bench/path_fit.py's interpolations of a camera path: every kind passes through the inputs' centres, collinear
centres give the straight line, and the natural spline is the one the pseudo views' trajectories use."""

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from warpgs.clearance import segment_distance
from warpgs.geometry import camera_centres
from warpgs.pseudo.trajectory import path_trajectories

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from path_fit import KINDS, dense_path  # noqa: E402


@pytest.mark.parametrize("kind", KINDS)
def test_each_path_passes_through_the_centres_and_is_straight_on_a_line(kind):
    rng = np.random.default_rng(0)
    C = np.cumsum(rng.uniform(0.5, 3.0, (6, 3)), axis=0)  # uneven spacing, not collinear
    D = dense_path(C, kind, n=50)
    for c in C:
        assert np.linalg.norm(D - c, axis=1).min() < 1e-9
    L = np.outer(np.cumsum([0.0, 1.0, 4.0, 0.5, 2.0]), [1.0, 2.0, -1.0])  # collinear, uneven
    D = dense_path(L, kind, n=50)
    d = segment_distance(torch.as_tensor(D), torch.as_tensor(L[:1]), torch.as_tensor(L[-1:]))
    assert float(d.max()) < 1e-9


def test_the_natural_spline_is_the_trajectories_path():
    rng = np.random.default_rng(1)
    C = np.cumsum(rng.uniform(0.5, 3.0, (5, 3)), axis=0)
    V = np.tile(np.eye(4), (5, 1, 1))
    V[:, :3, 3] = -C  # identity rotations: the centres are C
    D = dense_path(C, "natural", n=400)
    for traj in path_trajectories(V, 7, "capture"):
        for c in camera_centres(traj.viewmats):
            assert np.linalg.norm(D - c, axis=1).min() < 0.02
