"""The camera path's clearance (warpgs/strategy/clearance.py, clearance.path): segment distances against a dense
sampling of the segments, which Gaussians count as on the path, segments that pass the scene's geometry, and
the trainer removing what lies on the path (and nothing when it is off)."""

import numpy as np
import pytest
import torch

from test_rasterizer import DEVICES
from warpgs.strategy.clearance import PathClearance, segment_distance


def look_at_viewmat(eye, target=(0.0, 0.0, 10.0)):
    from tiny_scene import look_at_c2w

    return np.linalg.inv(look_at_c2w(eye, target)).astype(np.float32)


def test_segment_distance_matches_dense_sampling():
    g = torch.Generator().manual_seed(3)
    a, b = torch.randn(5, 3, generator=g), torch.randn(5, 3, generator=g)
    a[4] = b[4]  # a degenerate segment: a point
    p = torch.randn(200, 3, generator=g) * 2
    t = torch.linspace(0, 1, 20001)
    samples = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 3)
    oracle = torch.cdist(p, samples).min(1).values
    got = segment_distance(p, a, b, chunk=37)  # several chunks
    assert torch.allclose(got, oracle, atol=2e-4)
    assert torch.isinf(segment_distance(p, a[:0], b[:0])).all()


def test_gaussians_on_the_path_are_inside_and_the_scene_is_not():
    # a walk along x at y = 0, every camera looking at a facade 10 m ahead (z = 10)
    V = np.stack([look_at_viewmat((x, 0.0, 0.0), (x, 0.0, 10.0)) for x in (0.0, 2.0, 4.0, 6.0)])
    clear = PathClearance.build(V, radius=0.5, order="capture", samples=8)
    pts = torch.tensor([[1.0, 0.0, 0.0],    # between two cameras, on the path
                        [5.0, 0.3, 0.1],    # 0.32 m off the path
                        [3.0, 0.0, 0.6],    # 0.6 m in front of it: outside 0.5
                        [3.0, 0.0, 10.0],   # the facade
                        [7.0, 0.0, 0.0]])   # past the last camera: 1 m from it
    assert clear.inside(pts).tolist() == [True, True, False, False, False]
    # a point of the scene's geometry right on the path between the 2nd and 3rd cameras: the path there
    # is not free space (an object-centric path crossing the object), so nothing near it is removed
    blocked = PathClearance.build(V, radius=0.5, order="capture", samples=8, geometry=np.array([[3.0, 0.0, 0.0]]))
    assert blocked.dropped > 0
    near_geo = torch.tensor([[3.0, 0.1, 0.0], [1.0, 0.0, 0.0]])
    assert blocked.inside(near_geo).tolist() == [False, True]


@pytest.mark.skipif("cpu" not in DEVICES, reason="trains on the CPU (the GPU machine's packed Warp has no CPU compiler)")
def test_trainer_removes_gaussians_on_the_camera_path(tmp_path):
    from tiny_scene import make_scene, tiny_config
    from warpgs.methods.full import append_gaussians
    from warpgs.train import Trainer

    scene = make_scene()
    near = float(scene.bounds[0])
    planted = None
    kept = {}
    for fraction in (0.0, 0.2):
        cfg = tiny_config(25, str(tmp_path / "none.pth"), path_clearance=fraction)
        tr = Trainer(cfg, scene)
        if planted is None:  # Gaussians on the path: the midpoints of the path's pieces, opaque
            probe = PathClearance.build(np.stack([c.viewmat for c in scene.train]), 0.2 * near, order="nearest")
            assert probe.radius > 0 and len(probe.a) > 0
            planted = ((probe.a + probe.b) / 2)[::3]
        n0 = len(tr.model)
        append_gaussians(tr.context, planted, torch.full((len(planted), 3), 0.5), torch.full((len(planted), 3), 0.05), 0.9)
        assert len(tr.model) == n0 + len(planted)
        tr.train(21)  # refinement steps at 0 and 20 (tiny_config: refine_every 20)
        on_path = PathClearance.build(np.stack([c.viewmat for c in scene.train]), 0.2 * near, order="nearest")
        kept[fraction] = int(on_path.inside(tr.model.means).sum())
        if fraction > 0:
            assert tr.clearance is not None and abs(tr.clearance.radius - 0.2 * near) < 1e-6
        else:
            assert tr.clearance is None
    assert kept[0.0] >= len(planted)  # nothing removes them without the clearance
    assert kept[0.2] == 0


def test_view_clearance_removes_what_is_close_in_front_of_a_pose_of_the_path():
    # cameras at x = 0, 2, 4, 6 looking along +z; fx = fy = 100, a 100x80 image centred at (50, 40)
    V = np.stack([look_at_viewmat((x, 0.0, 0.0), (x, 0.0, 10.0)) for x in (0.0, 2.0, 4.0, 6.0)])
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    clear = PathClearance.build(V, 0.0, order="capture", samples=5, K=K, size=(100, 80), view_depth=3.0)
    assert len(clear.poses) == 4 + 3 * 3  # the inputs and the poses between them
    pts = torch.tensor([[1.0, 0.0, 2.0],    # 2 m in front of the pose at x = 1 (between two inputs)
                        [1.0, 0.0, 4.0],    # 4 m: past the view depth
                        [3.0, 0.0, -1.0],   # behind every pose
                        [3.0, 1.0, 1.5],    # 1.5 m ahead but 1 m down: v = 40 + 100 / 1.5 > 80, outside
                        [20.0, 0.0, 1.0]])  # far to the side of every pose
    assert clear.in_view(pts).tolist() == [True, False, False, False, False]
    assert clear.inside(pts).tolist() == [True, False, False, False, False]  # radius 0: the view clearance only
    # off without a depth, and the tube alone then decides
    assert not PathClearance.build(V, 0.0, order="capture", K=K, size=(100, 80)).inside(pts).any()


def _model(means, scale, opacity=0.9):
    from warpgs.model import GaussianModel

    n = len(means)
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1.0
    logit = float(np.log(opacity / (1 - opacity)))
    return GaussianModel(torch.as_tensor(means, dtype=torch.float32), quats, torch.full((n, 3), float(np.log(scale))),
                         torch.full((n,), logit), torch.zeros(n, 1, 3), torch.zeros(n, 0, 3), max_sh_degree=0)


@pytest.mark.skipif("cpu" not in DEVICES, reason="renders on the CPU")
def test_path_floaters_are_what_a_pose_of_the_path_sees_and_no_input_does():
    """Three inputs at x = 0, 2, 4 look at a wall 10 m ahead; a small Gaussian 0.8 m in front of the path at x = 1
    is 51 degrees off every input's axis (outside their 53-degree field of view, its screen box too) and straight
    ahead of the pose halfway between the first two: it alone is found, the wall (seen by inputs and path alike) is not, and a
    Gaussian the inputs see as much as the path does is not either."""
    from types import SimpleNamespace

    from warpgs.strategy.clearance import PathFloaters

    xs = (0.0, 2.0, 4.0)
    V = np.stack([look_at_viewmat((x, 0.0, 0.0), (x, 0.0, 10.0)) for x in xs])
    K = np.array([[50.0, 0, 25], [0, 50.0, 20], [0, 0, 1]], np.float32)
    wall = [(x, y, 10.0) for x in np.arange(-4.0, 8.5, 1.0) for y in np.arange(-4.0, 4.5, 1.0)]
    floater = (1.0, 0.0, 0.8)
    seen = (1.0, 0.0, 3.0)  # between the first two inputs, 3 m ahead: in all three views
    model = _model(wall + [floater, seen], scale=0.4)
    with torch.no_grad():  # the floater small enough that its screen box (3.33 sigma) stays off the inputs' images
        model.params["scales"][len(wall)] = float(np.log(0.1))
    inputs = [SimpleNamespace(viewmat=torch.as_tensor(v), K=torch.as_tensor(K), width=50, height=40) for v in V]
    finder = PathFloaters.build(V, K, (50, 40), ratio=10.0, per_pair=3, order="capture")
    assert len(finder.poses) == 2 * 3
    found = finder.find(model, inputs)
    assert found.tolist() == [False] * len(wall) + [True, False]
    # the same Gaussian in sight of an input is constrained: nothing is found
    V2 = np.concatenate([V, look_at_viewmat((1.0, 0.0, -0.5), (1.0, 0.0, 10.0))[None]])
    inputs2 = inputs + [SimpleNamespace(viewmat=torch.as_tensor(V2[-1]), K=torch.as_tensor(K), width=50, height=40)]
    assert not finder.find(model, inputs2).any()


def test_path_floaters_on_both_paths_find_what_stands_before_the_line_where_the_spline_bulges():
    """Inputs at (0, 0, -2), (1, 0, 0), (9, 0, 0), (10, 0, -2) look at a wall at z = 10. Across the 8 m gap between
    the middle two, the pseudo views' spline bulges 1.5 m towards the wall, past a small Gaussian 0.8 m in front of
    the straight line's midpoint. The spline's poses (``paths="spline"``) have it behind them; the line's poses
    (``"both"``) see it straight ahead. No input sees it, and the wall is found by neither. A bad value is named."""
    from types import SimpleNamespace

    from warpgs.strategy.clearance import PathFloaters
    from warpgs.geometry import camera_centres
    from warpgs.pseudo.trajectory import path_trajectories

    centres = [(0.0, 0.0, -2.0), (1.0, 0.0, 0.0), (9.0, 0.0, 0.0), (10.0, 0.0, -2.0)]
    V = np.stack([look_at_viewmat(c, (c[0], c[1], c[2] + 10.0)) for c in centres])
    mid_spline = camera_centres(path_trajectories(V, 5, "capture")[1].viewmats)[2]
    mid_line = camera_centres(path_trajectories(V, 5, "capture", centres="line")[1].viewmats)[2]
    assert np.allclose(mid_line, (5.0, 0.0, 0.0), atol=1e-6) and mid_spline[2] > 1.2  # the bulge
    K = np.array([[50.0, 0, 25], [0, 50.0, 20], [0, 0, 1]], np.float32)
    wall = [(x, y, 10.0) for x in np.arange(-4.0, 16.5, 1.0) for y in np.arange(-4.0, 4.5, 1.0)]
    model = _model(wall + [(5.0, 0.0, 0.8)], scale=0.4)
    with torch.no_grad():
        model.params["scales"][len(wall)] = float(np.log(0.1))
    inputs = [SimpleNamespace(viewmat=torch.as_tensor(v), K=torch.as_tensor(K), width=50, height=40) for v in V]
    spline = PathFloaters.build(V, K, (50, 40), ratio=10.0, per_pair=3, order="capture")
    both = PathFloaters.build(V, K, (50, 40), ratio=10.0, per_pair=3, order="capture", paths="both")
    assert len(spline.poses) == 3 * 3 and len(both.poses) == 2 * 3 * 3
    assert spline.find(model, inputs).tolist() == [False] * (len(wall) + 1)
    assert both.find(model, inputs).tolist() == [False] * len(wall) + [True]
    with pytest.raises(ValueError, match="clearance.floaters_paths"):
        PathFloaters.build(V, K, (50, 40), ratio=10.0, paths="curve")


@pytest.mark.skipif("cpu" not in DEVICES, reason="trains on the CPU (the GPU machine's packed Warp has no CPU compiler)")
def test_trainer_removes_the_path_floaters_on_its_schedule(tmp_path):
    from tiny_scene import make_scene, tiny_config
    from warpgs.strategy.clearance import PathFloaters
    from warpgs.methods.full import append_gaussians
    from warpgs.train import Trainer

    scene = make_scene()
    V = np.stack([c.viewmat for c in scene.train])
    counts = {}
    for ratio in (0.0, 10.0):
        cfg = tiny_config(21, str(tmp_path / "none.pth"), path_floaters=ratio, path_floaters_every=20)
        tr = Trainer(cfg, scene)
        assert (tr.floaters is None) == (ratio == 0)
        # opaque Gaussians just in front of the poses between neighbouring inputs, 0.3 x the near depth ahead
        probe = PathFloaters.build(V, scene.train[0].K, (48, 48), 10.0, per_pair=3, order=cfg.pseudo.trajectory.order)
        c2w = torch.linalg.inv(probe.poses)
        planted = c2w[:, :3, 3] + 0.3 * float(scene.bounds[0]) * c2w[:, :3, 2]
        append_gaussians(tr.context, planted, torch.full((len(planted), 3), 0.1), torch.full((len(planted), 3), 0.05), 0.9)
        assert not tr.densify_only_updates_state(20) or ratio == 0
        tr.train(21)  # the floaters' step is 20
        d = torch.cdist(tr.model.means.detach(), planted).min(0).values
        counts[ratio] = int((d < 0.02).sum())  # (Adam moves them a little in 21 steps)
    assert counts[0.0] == len(planted)  # nothing removes them when it is off
    assert counts[10.0] == 0
    # off the schedule (none due in 21 steps), the pass before the final evaluation removes them, unless it is off
    for final in (True, False):
        cfg = tiny_config(21, str(tmp_path / "none.pth"), path_floaters=10.0, path_floaters_every=1000,
                          path_floaters_final=final)
        tr = Trainer(cfg, scene, out_dir=tmp_path / f"final_{final}")
        append_gaussians(tr.context, planted, torch.full((len(planted), 3), 0.1), torch.full((len(planted), 3), 0.05), 0.9)
        tr.train(21)
        assert int((torch.cdist(tr.model.means.detach(), planted).min(0).values < 0.02).sum()) == len(planted)
        stages = tr.finish()["stage_times_s"]
        left = int((torch.cdist(tr.model.means.detach(), planted).min(0).values < 0.02).sum())
        assert left == (0 if final else len(planted))
        # the passes' seconds are one of the run's stage timings: none ran without the final one
        assert stages["path_floaters_s"] == round(tr.path_floaters_time, 2)
        assert (tr.path_floaters_time > 0) == final
    assert "path_floaters_s" not in Trainer(tiny_config(21, str(tmp_path / "none.pth")), scene,
                                            out_dir=tmp_path / "off").finish()["stage_times_s"]
