"""bench/partner_reach.py against an analytic case: two cameras side by side over a plane."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import partner_reach  # noqa: E402
from warpgs.data.scene import Camera  # noqa: E402


def test_ratio_is_the_path_move_over_the_sideways_move_at_the_median_depth():
    # two cameras looking down +z, 2 units apart along x; points on the plane z = 10; fx = 100, 200 px wide.
    # Path partner at reach 0.5: the farthest pose is half way, 1 unit (the path between two inputs is straight).
    # Sideways partner: 0.1 x 200 px of disparity at depth 10 -> 0.1 * 200 * 10 / 100 = 2 units. Ratio 0.5.
    K = np.array([[100.0, 0, 100], [0, 100.0, 50], [0, 0, 1]], np.float32)
    cams = []
    for i, x in enumerate((0.0, 2.0)):
        vm = np.eye(4, dtype=np.float32)
        vm[0, 3] = -x  # world -> camera: x - centre
        cams.append(Camera(name=f"v{i}", viewmat=vm, K=K, width=200, height=100,
                           image=np.zeros((100, 200, 3), np.float32)))
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(-5, 7, 500), rng.uniform(-3, 3, 500), np.full(500, 10.0)])
    r = partner_reach.ratios(cams, xyz, "capture", reach=0.5, shift=0.1)
    np.testing.assert_allclose(r, [0.5, 0.5], atol=2e-3)
    # half the reach, half the move; twice the sideways shift, half the ratio
    np.testing.assert_allclose(partner_reach.ratios(cams, xyz, "capture", reach=0.25, shift=0.1), [0.25, 0.25], atol=2e-3)
    np.testing.assert_allclose(partner_reach.ratios(cams, xyz, "capture", reach=0.5, shift=0.2), [0.25, 0.25], atol=2e-3)
