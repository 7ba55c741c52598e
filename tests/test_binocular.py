"""Binocular consistency (warpgs/binocular.py, warpgs/kernels/warping.py ``shift_warp``).

References are independent: torch's ``grid_sample`` (bilinear, zero padding) as the oracle of the warp and
autograd's gradients through it, a fronto-parallel plane rendered by the rasterizer from the input and from
the moved camera (the warp of the moved render with the true depth gives the input back), and the trainer's
run with the term on against the same run with it off.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from warpgs.regularizers.binocular import moved_viewmat, shift_warp

from devices import DEVICES  # noqa: E402 (tests/devices.py: WARPGS_TEST_DEVICES restricts them)


def oracle(moved: torch.Tensor, depth: torch.Tensor, ft: float) -> tuple[torch.Tensor, torch.Tensor]:
    """torch's grid_sample of ``moved`` at (x - ft / z, y), zero padding, align_corners False; its weight as the
    warp of an all-ones image; 0 where the depth is <= 0."""
    H, W = depth.shape
    ys, xs = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64),
                            indexing="ij")
    z = depth.double()
    ok = z > 1e-6
    x = xs + 0.5 - ft / torch.where(ok, z, torch.ones_like(z))
    y = ys + 0.5
    grid = torch.stack([2 * x / W - 1, 2 * y / H - 1], -1)[None]
    img = moved.double().permute(2, 0, 1)[None]
    # along the row only: sampling at the row's centre makes grid_sample's vertical weights (1, 0)
    out = torch.nn.functional.grid_sample(img, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    wgt = torch.nn.functional.grid_sample(torch.ones_like(img[:, :1]), grid, mode="bilinear", padding_mode="zeros",
                                          align_corners=False)
    return out[0].permute(1, 2, 0) * ok[..., None], wgt[0, 0] * ok


@pytest.mark.parametrize("device", DEVICES)
def test_shift_warp_matches_grid_sample_and_its_gradients(device):
    g = torch.Generator().manual_seed(0)
    H, W = 7, 11
    moved = torch.rand(H, W, 3, generator=g)
    depth = 1.0 + 3.0 * torch.rand(H, W, generator=g)
    depth[2, 3] = 0.0  # no depth: nothing warped, no gradient
    ft = 6.3  # disparities 1.6 .. 6.3 px: taps inside, across and outside the border
    warped, weight = shift_warp(moved.to(device), depth.to(device), ft)
    ref, ref_w = oracle(moved, depth, ft)
    assert torch.allclose(warped.cpu().double(), ref, atol=1e-5)
    assert torch.allclose(weight.cpu().double(), ref_w, atol=1e-5)
    assert weight[2, 3] == 0 and (warped[2, 3] == 0).all()

    v = torch.rand(H, W, 3, generator=g)
    m1 = moved.clone().to(device).requires_grad_(True)
    d1 = depth.clone().to(device).requires_grad_(True)
    (shift_warp(m1, d1, ft)[0] * v.to(device)).sum().backward()
    m2 = moved.clone().double().requires_grad_(True)
    d2 = depth.clone().double().requires_grad_(True)
    (oracle(m2, d2, ft)[0] * v.double()).sum().backward()
    assert torch.allclose(m1.grad.cpu().double(), m2.grad, atol=1e-5)
    assert torch.allclose(d1.grad.cpu().double(), d2.grad, atol=1e-4)
    assert d1.grad[2, 3] == 0


def test_shift_warp_depth_gradient_against_finite_differences():
    g = torch.Generator().manual_seed(1)
    H, W = 5, 16
    moved = torch.rand(H, W, 3, generator=g, dtype=torch.float32)
    depth = 2.0 + torch.rand(H, W, generator=g)
    v = torch.rand(H, W, 3, generator=g)
    ft = 9.0
    d = depth.clone().requires_grad_(True)
    (shift_warp(moved, d, ft)[0] * v).sum().backward()
    for (i, j) in [(0, 8), (2, 12), (4, 15)]:
        h = 1e-3
        dp, dm = depth.clone(), depth.clone()
        dp[i, j] += h
        dm[i, j] -= h
        fd = ((shift_warp(moved, dp, ft)[0] - shift_warp(moved, dm, ft)[0]) * v).sum() / (2 * h)
        assert abs(float(fd) - float(d.grad[i, j])) < 2e-2 * max(1.0, abs(float(fd))), (i, j, float(fd),
                                                                                          float(d.grad[i, j]))


def test_moved_render_warped_with_true_depth_gives_the_input_back():
    """A textured fronto-parallel plane at z = 4: rendered from the input and from the camera moved by t, the
    moved render warped back with the input's rendered depth matches the input render inside the image."""
    from warpgs.render import rasterize

    g = np.random.default_rng(0)
    n = 60 * 40
    gx, gy = np.meshgrid(np.linspace(-2.4, 2.4, 60), np.linspace(-1.6, 1.6, 40))
    means = torch.tensor(np.stack([gx.ravel(), gy.ravel(), np.full(n, 4.0)], 1), dtype=torch.float32)
    scales = torch.full((n, 3), 0.05)
    scales[:, 2] = 0.002
    quats = torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1)
    opac = torch.full((n,), 0.99)
    colours = torch.tensor(g.random((n, 1, 3)), dtype=torch.float32)
    W, H = 48, 32
    K = torch.tensor([[40.0, 0, W / 2], [0, 40.0, H / 2], [0, 0, 1]])
    vm = torch.eye(4)
    t = torch.tensor([0.2])
    bg = torch.zeros(3)
    inp = rasterize(means, quats, scales, opac, colours, vm, K, W, H, sh_degree=0, background=bg)
    mov = rasterize(means, quats, scales, opac, colours, moved_viewmat(vm, t), K, W, H, sh_degree=0, background=bg)
    assert torch.allclose(moved_viewmat(vm, t)[0, 3], torch.tensor(-0.2))
    assert inp.depth[H // 2, W // 2].item() == pytest.approx(4.0, abs=0.01)
    warped, weight = shift_warp(mov.image, inp.depth, 40.0 * 0.2)  # 2 px of disparity
    inside = weight > 0.999
    assert inside.float().mean() > 0.8
    err = (warped - inp.image).abs()[inside].mean()
    err_unwarped = (mov.image - inp.image).abs()[inside].mean()
    assert err < 0.3 * err_unwarped, (float(err), float(err_unwarped))


def test_bad_shapes_are_named():
    with pytest.raises(ValueError, match="shift_warp"):
        shift_warp(torch.zeros(4, 5, 3), torch.zeros(4, 6), 1.0)


# ----------------------------------------------------------------------------------------------
# the trainer's switches: train.opacity_decay, train.binocular


def test_opacity_decay_multiplies_every_opacity_each_step_from_refine_start():
    """With the opacities' learning rate ~0 and no densification, the decay alone changes them: after the
    steps from refine_start_iter on, each opacity is its start value x (1 - rate)^steps (analytic); the
    same run with the decay off keeps them."""
    from tests.tiny_scene import make_scene, tiny_config
    from warpgs.train import Trainer

    def run(decay):
        cfg = tiny_config(12)
        cfg.optim.opacities_lr = 1e-12
        cfg.strategy.refine_stop_iter = 0
        cfg.strategy.refine_start_iter = 4
        cfg.train.opacity_decay = decay
        t = Trainer(cfg, make_scene(), None, log=lambda m: None)
        start = t.model.opacities.detach().clone()
        t.train()
        return start, t.model.opacities.detach()

    start, kept = run(0.0)
    assert torch.allclose(kept, start, atol=1e-6)
    start, decayed = run(0.1)
    assert torch.allclose(decayed, start * 0.9 ** 8, rtol=1e-4, atol=1e-7)  # steps 4..11


def test_binocular_term_trains_and_checkpoints_its_draws(tmp_path):
    """The term appears in the step's parts from binocular_start on, changes the training, and a run
    stopped half-way and resumed from its checkpoint ends bit for bit as the run without the stop."""
    from tests.tiny_scene import make_scene, param_copy, same_params, tiny_config
    from warpgs.train import Trainer

    def cfg_of(on):
        cfg = tiny_config(40)
        cfg.train.binocular = 1.0 if on else 0.0
        cfg.train.binocular_start = 0.25
        cfg.train.checkpoint_every = 20
        return cfg

    on = Trainer(cfg_of(True), make_scene(), None, log=lambda m: None)
    assert on.regularizers.get("binocular").start == 10
    calls = []
    term = on.regularizers.get("binocular").loss
    on.regularizers.get("binocular").loss = lambda *a: (calls.append(on.step), term(*a))[1]
    on.train()
    assert calls == list(range(10, 40))  # every step from the start on, none before
    off = Trainer(cfg_of(False), make_scene(), None, log=lambda m: None)
    off.train()
    assert not same_params(param_copy(on), param_copy(off))

    whole = Trainer(cfg_of(True), make_scene(), tmp_path / "whole", log=lambda m: None)
    whole.train()
    half = Trainer(cfg_of(True), make_scene(), tmp_path / "half", log=lambda m: None)
    half.train(20)
    half.save_checkpoint()
    resumed = Trainer(cfg_of(True), make_scene(), tmp_path / "half", log=lambda m: None)
    resumed.load_checkpoint()
    resumed.train()
    assert same_params(param_copy(resumed), param_copy(whole))


def _plane_view(gx, gy, colours):
    """A plane of Gaussians at z = 4 (centres ``gx``, ``gy``, RGB ``colours`` [n, 3]) rendered by a 48x32 camera at
    the origin looking along +z -> (model, the render, the camera with that render as its photo, background)."""
    from types import SimpleNamespace

    from warpgs.model import GaussianModel

    means = torch.tensor(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 4.0)], 1), dtype=torch.float32)
    model = GaussianModel.from_points(means, torch.as_tensor(colours, dtype=torch.float32), sh_degree=0,
                                      init_opacity=0.99, init_scale=1.0)
    W, H = 48, 32
    K = torch.tensor([[40.0, 0, W / 2], [0, 40.0, H / 2], [0, 0, 1]])
    vm = torch.eye(4)
    bg = torch.zeros(3)
    with torch.no_grad():
        inp = model.render(vm, K, W, H, background=bg)
    return model, inp, SimpleNamespace(viewmat=vm, K=K, width=W, height=H, image=inp.image), bg


def test_binocular_loss_is_lower_with_the_true_depth():
    """On the textured plane, the term computed with the input's rendered depth is below the term with that
    depth 30% too far or too near (the warp then misaligns the moved render)."""
    from warpgs.regularizers.binocular import Binocular

    gx, gy = np.meshgrid(np.linspace(-2.4, 2.4, 60), np.linspace(-1.6, 1.6, 40))
    model, inp, cam, bg = _plane_view(gx, gy, np.random.default_rng(0).random((gx.size, 3)))

    def term(scale):
        b = Binocular(1.0, 1.0, 0, 0.0, "cpu", 0)  # the same draw of t each time (same seed): 6 px at 4 m
        with torch.no_grad():
            return float(b.loss(model, inp._replace(depth=inp.depth * scale), cam, bg, {}))

    right = term(1.0)
    assert right < 0.5 * term(1.3) and right < 0.5 * term(0.7)


def test_a_moved_render_cut_short_by_a_fixed_capacity_sits_the_term_out_and_is_counted():
    """In a step recorded as a CUDA graph the moved render gets fixed buffers (its pose is drawn on the device, so
    its count cannot be read first). With room enough the term is the counted render's, bit for bit, gradient
    included; with too little the term is 0 for that step and ``overflows`` counts it (the next recording makes
    more room)."""
    from warpgs.regularizers.binocular import Binocular

    gx, gy = np.meshgrid(np.linspace(-2.4, 2.4, 60), np.linspace(-1.6, 1.6, 40))
    model, inp, cam, bg = _plane_view(gx, gy, np.random.default_rng(0).random((gx.size, 3)))
    results = []
    for capacity in (None, 10 ** 6, 50):
        b = Binocular(1.0, 1.0, 0, 0.05, "cpu", 0)
        depth = inp.depth.detach().clone().requires_grad_(True)
        term = b.loss(model, inp._replace(depth=depth), cam, bg, {}, capacity)
        term.backward()
        results.append((term.detach(), depth.grad, int(b.overflows)))
    (t0, g0, n0), (t1, g1, n1), (t2, g2, n2) = results
    assert float(t0) > 0 and n0 == 0
    assert torch.equal(t1, t0) and torch.equal(g1, g0) and n1 == 0
    assert float(t2) == 0.0 and float(g2.abs().sum()) == 0.0 and n2 == 1


# ----------------------------------------------------------------------------------------------
# the general warp (pose_warp) and the capture path's partner (train.binocular_partner: path)


def pose_oracle(moved: torch.Tensor, depth: torch.Tensor, rel: torch.Tensor, K: torch.Tensor):
    """torch's grid_sample of ``moved`` where each pixel at its depth reprojects (float64, differentiable in
    ``moved`` and ``depth`` through the grid); its weight as the warp of an all-ones image."""
    H, W = depth.shape
    ys, xs = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64),
                            indexing="ij")
    pix = torch.stack([xs + 0.5, ys + 0.5, torch.ones_like(xs)], -1)
    p = pix @ torch.linalg.inv(K.double()).T * depth.double()[..., None]
    h = (p @ rel[:3, :3].double().T + rel[:3, 3].double()) @ K.double().T
    grid = torch.stack([2 * h[..., 0] / h[..., 2] / W - 1, 2 * h[..., 1] / h[..., 2] / H - 1], -1)[None]
    img = moved.double().permute(2, 0, 1)[None]
    out = torch.nn.functional.grid_sample(img, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    wgt = torch.nn.functional.grid_sample(torch.ones_like(img[:, :1]), grid, mode="bilinear", padding_mode="zeros",
                                          align_corners=False)
    return out[0].permute(1, 2, 0), wgt[0, 0]


@pytest.mark.parametrize("device", DEVICES)
def test_pose_warp_matches_grid_sample_and_its_gradients(device):
    from warpgs.regularizers.binocular import pose_warp
    from warpgs.geometry import axis_angle_to_rotmat

    g = torch.Generator().manual_seed(3)
    H, W = 7, 9
    K = torch.tensor([[8.0, 0, 4.5], [0, 8.0, 3.5], [0, 0, 1]])
    rel = torch.eye(4, dtype=torch.float64)
    axis = np.array([0.2, 1.0, 0.1])
    rel[:3, :3] = torch.as_tensor(axis_angle_to_rotmat(0.08 * axis / np.linalg.norm(axis)))  # a turn and a move in
    # every axis: taps inside and outside
    rel[:3, 3] = torch.tensor([0.15, -0.05, 0.1], dtype=torch.float64)
    moved = torch.rand(H, W, 3, generator=g)
    depth = 2.0 + torch.rand(H, W, generator=g)
    warped, weight = pose_warp(moved.to(device), depth.to(device), rel.float(), K)
    ref, ref_w = pose_oracle(moved, depth, rel, K)
    assert torch.allclose(warped.cpu().double(), ref, atol=1e-5)
    assert torch.allclose(weight.cpu().double(), ref_w, atol=1e-5)
    assert (weight < 1).any() and (weight == 1).any()

    v = torch.rand(H, W, 3, generator=g)
    m1 = moved.clone().to(device).requires_grad_(True)
    d1 = depth.clone().to(device).requires_grad_(True)
    (pose_warp(m1, d1, rel.float(), K)[0] * v.to(device)).sum().backward()
    m2 = moved.clone().double().requires_grad_(True)
    d2 = depth.clone().double().requires_grad_(True)
    (pose_oracle(m2, d2, rel, K)[0] * v.double()).sum().backward()
    assert torch.allclose(m1.grad.cpu().double(), m2.grad, atol=1e-5)
    assert torch.allclose(d1.grad.cpu().double(), d2.grad, atol=1e-4)
    assert d2.grad.abs().max() > 0.05  # the depth gradient is there to compare


def test_pose_warp_of_a_move_along_x_is_shift_warp_and_no_depth_warps_nothing():
    from warpgs.regularizers.binocular import pose_warp

    g = torch.Generator().manual_seed(4)
    H, W = 5, 12
    fx, t = 10.0, 0.4
    K = torch.tensor([[fx, 0, W / 2], [0, fx, H / 2], [0, 0, 1]])
    moved = torch.rand(H, W, 3, generator=g)
    depth = 1.0 + 2.0 * torch.rand(H, W, generator=g)
    depth[1, 4] = 0.0
    rel = moved_viewmat(torch.eye(4), torch.tensor([t]))  # camera coordinates x - t
    a, wa = pose_warp(moved, depth, rel, K)
    b, wb = shift_warp(moved, depth, fx * t)
    assert torch.allclose(a, b, atol=1e-5) and torch.allclose(wa, wb, atol=1e-5)
    assert wa[1, 4] == 0 and (a[1, 4] == 0).all()
    with pytest.raises(ValueError, match="pose_warp"):
        pose_warp(torch.zeros(4, 5, 3), torch.zeros(4, 6), torch.eye(4), K)


def test_path_partners_lie_on_the_capture_path_within_the_reach():
    """Three inputs on a line (x = 0, 1, 3): input 0's partners run from it a share of the way to input 1, input 1's
    to both sides, none farther than ``reach`` of the way; the first is the trajectory's second pose."""
    from warpgs.strategy.clearance import path_partners
    from warpgs.geometry import camera_centres
    from warpgs.pseudo.trajectory import path_trajectories

    V = np.stack([np.eye(4) for _ in range(3)])
    for k, x in enumerate([0.0, 1.0, 3.0]):
        V[k, 0, 3] = -x  # world-to-camera of a camera at (x, 0, 0)
    parts = path_partners(V, ["a", "b", "c"], "capture", reach=0.5, frames=11)
    assert {k: len(v) for k, v in parts.items()} == {"a": 5, "b": 10, "c": 5}
    xa = camera_centres(parts["a"].double().numpy())[:, 0]
    assert np.all(xa > 0) and np.all(xa <= 0.5 + 1e-6) and np.all(np.diff(xa) > 0)
    xb = camera_centres(parts["b"].double().numpy())[:, 0]
    assert np.all(np.abs(xb - 1.0) > 0) and xb.min() >= 0.5 - 1e-3 and xb.max() <= 2.0 + 0.1
    assert np.allclose(parts["a"][0].numpy(), path_trajectories(V, 11, order="capture")[0].viewmats[1], atol=1e-6)
    assert path_partners(V[:1], ["a"], "capture", 0.5) == {}


def test_path_partner_term_is_lower_with_the_true_depth_and_reaches_the_depth():
    """A smoothly textured plane seen from a partner moved in x, y and z: the term with the true depth is below
    the term with the depth 30% off, and its gradient reaches the input's depth. (No turn: opaque round Gaussians
    of a plane seen obliquely occlude their neighbours by depth order, so the render is no rigid texture; the
    turn's geometry is checked against grid_sample above.)"""
    from types import SimpleNamespace

    from warpgs.regularizers.binocular import Binocular
    from warpgs.model import GaussianModel

    n = 60 * 40
    gx, gy = np.meshgrid(np.linspace(-2.4, 2.4, 60), np.linspace(-1.6, 1.6, 40))
    means = torch.tensor(np.stack([gx.ravel(), gy.ravel(), np.full(n, 4.0)], 1), dtype=torch.float32)
    colours = np.stack([0.5 + 0.4 * np.sin(3 * gx + 1) * np.cos(2 * gy), 0.5 + 0.4 * np.cos(2.5 * gx - 2 * gy),
                        0.5 + 0.4 * np.sin(2 * gy + 0.5)], -1).reshape(-1, 3)
    model = GaussianModel.from_points(means, torch.tensor(colours, dtype=torch.float32), sh_degree=0,
                                      init_opacity=0.99, init_scale=1.0)
    W, H = 48, 32
    K = torch.tensor([[40.0, 0, W / 2], [0, 40.0, H / 2], [0, 0, 1]])
    vm = torch.eye(4)
    partner = torch.eye(4)
    partner[:3, 3] = torch.tensor([0.25, 0.1, 0.2])
    bg = torch.zeros(3)
    with torch.no_grad():
        inp = model.render(vm, K, W, H, background=bg)
    cam = SimpleNamespace(name="in", viewmat=vm, K=K, width=W, height=H, image=inp.image)
    b = Binocular(1.0, 1.0, 0, 0.0, "cpu", 0, path={"in": partner[None]})

    def term(scale):
        with torch.no_grad():
            return float(b.loss(model, inp._replace(depth=inp.depth * scale), cam, bg, {}))

    right = term(1.0)
    assert right < 0.5 * term(1.3) and right < 0.5 * term(0.7), (right, term(1.3), term(0.7))
    depth = (inp.depth * 1.1).requires_grad_(True)
    b.loss(model, inp._replace(depth=depth), cam, bg, {}).backward()
    assert depth.grad.abs().sum() > 0


def test_path_partner_trains_from_the_config_and_resumes_bit_for_bit(tmp_path):
    """``train.binocular_partner: path`` gives every input its path partners, trains with them (not as the
    shifted partner does), and a run stopped half-way resumes to the same parameters (the draws are the
    checkpointed generator's)."""
    from tests.tiny_scene import make_scene, param_copy, same_params, tiny_config
    from warpgs.train import Trainer

    def cfg_of(partner):
        cfg = tiny_config(30)
        cfg.train.binocular = 1.0
        cfg.train.binocular_start = 0.3
        cfg.train.binocular_partner = partner
        cfg.train.checkpoint_every = 15
        return cfg

    scene = make_scene()
    path = Trainer(cfg_of("path"), scene, tmp_path / "whole", log=lambda m: None)
    assert set(path.regularizers.get("binocular").path) == {c.name for c in scene.train}
    path.train()
    shift = Trainer(cfg_of("shift"), make_scene(), None, log=lambda m: None)
    assert shift.regularizers.get("binocular").path == {}
    shift.train()
    assert not same_params(param_copy(path), param_copy(shift))
    half = Trainer(cfg_of("path"), make_scene(), tmp_path / "half", log=lambda m: None)
    half.train(15)
    half.save_checkpoint()
    resumed = Trainer(cfg_of("path"), make_scene(), tmp_path / "half", log=lambda m: None)
    resumed.load_checkpoint()
    resumed.train()
    assert same_params(param_copy(resumed), param_copy(path))


def test_binocular_xy_sees_depth_errors_a_sideways_move_cannot():
    """Horizontal stripes (colour varies with the row only): a sideways partner warps along the rows and sees no
    error in the depth, whatever it is; ``train.binocular_axes: xy`` moves the camera up and down too, so the term
    with the depth 30% off is well above the term with the true depth. With the true depth both are small."""
    from warpgs.regularizers.binocular import Binocular

    n_x, n_y = 150, 40  # wider than the view and its moves: no edge of the plane in sight along the rows
    gx, gy = np.meshgrid(np.linspace(-6.0, 6.0, n_x), np.linspace(-1.6, 1.6, n_y))
    rows = np.repeat(np.arange(n_y) % 2, n_x).astype(np.float32)  # stripes one grid row high
    model, inp, cam, bg = _plane_view(gx, gy, np.stack([rows, 1 - rows, np.full_like(rows, 0.5)], 1))

    def term(axes, scale, draws=8):
        b = Binocular(1.0, 1.0, 0, 0.0, "cpu", 0, axes=axes)
        with torch.no_grad():  # the mean over a few draws of the move (one generator: different draws)
            return np.mean([float(b.loss(model, inp._replace(depth=inp.depth * scale), cam, bg, {}))
                            for _ in range(draws)])

    x_right, x_wrong = term("x", 1.0), term("x", 1.3)
    xy_right, xy_wrong = term("xy", 1.0), term("xy", 1.3)
    assert abs(x_wrong - x_right) < 0.2 * x_wrong + 1e-3  # blind to the depth
    assert xy_wrong > 2 * xy_right and xy_wrong > 2 * x_wrong
    with pytest.raises(ValueError, match="x or xy"):
        Binocular(1.0, 1.0, 0, 0.0, "cpu", 0, axes="z")
