"""Densification: clone / split / prune / reset on constructed gradients, the budget, pruning the unseen."""

import math
from types import SimpleNamespace

import pytest
import torch

from warpgs.model import GaussianModel
from warpgs.strategy import DefaultStrategy, contribution, quat_to_rotmat, reset_opacities
from warpgs.train import make_optimizer
from warpgs.config import Config


def _model(scales, opacities, seed=0):
    n = len(scales)
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) + torch.tensor([0.0, 0.0, 5.0])
    quats = torch.nn.functional.normalize(torch.randn(n, 4, generator=g), dim=-1)
    sc = torch.log(torch.tensor(scales, dtype=torch.float32))[:, None].repeat(1, 3)
    op = torch.logit(torch.tensor(opacities, dtype=torch.float32))
    sh0 = torch.randn(n, 1, 3, generator=g)
    shN = torch.randn(n, 15, 3, generator=g)
    return GaussianModel(means, quats, sc, op, sh0, shN)


CAMERA = (torch.eye(4), torch.tensor([[30.0, 0, 16], [0, 30.0, 16], [0, 0, 1]]))  # (viewmat, K) of a 32x32 view


def _rendered_and_backward(model):
    """The 32x32 render of ``model`` from ``CAMERA``, after the backward of its image's sum (the densification
    statistic reads its 2D gradients)."""
    out = model.render(*CAMERA, 32, 32)
    out.image.sum().backward()
    return out


def _with_adam_state(model):
    opt = make_optimizer(model, Config(), 1.0)
    for p in model.params.values():
        p.grad = torch.ones_like(p)
    opt.step()  # every moment becomes non-zero
    opt.zero_grad()
    return opt


def test_grow_clones_small_and_splits_large():
    s = DefaultStrategy(grow_grad2d=0.5, grow_scale3d=0.1)
    # 0: high grad, small -> clone; 1: high grad, large -> split; 2: low grad; 3: high grad, small -> clone
    m = _model([0.05, 0.5, 0.05, 0.08], [0.5, 0.5, 0.5, 0.5])
    opt = _with_adam_state(m)
    st = s.initialize_state(4, "cpu")
    st["grad2d"][:] = torch.tensor([3.0, 2.0, 0.1, 1.2])
    st["count"][:] = torch.tensor([2.0, 2.0, 2.0, 2.0])  # means 1.5, 1.0, 0.05, 0.6
    before = {k: v.detach().clone() for k, v in m.params.items()}
    n_clone, n_split = s.grow(m, opt, st, step=1000, scene_scale=1.0, generator=torch.Generator().manual_seed(0))
    assert (n_clone, n_split) == (2, 1)
    assert len(m) == 4 + 2 + 1  # clones add one each; a split replaces one by two
    # layout (gsplat): [kept originals 0, 2, 3] + [clones of 0, 3] + [2 children of 1]
    order = [0, 2, 3, 0, 3]
    for name in ("quats", "opacities", "sh0", "shN"):
        assert torch.equal(m.params[name][:5], before[name][order]), name
        assert torch.equal(m.params[name][5], before[name][1]) and torch.equal(m.params[name][6], before[name][1])
    assert torch.equal(m.params["means"][:5], before["means"][order])
    # children: scale / 1.6, means sampled around the parent (so they differ from it and each other)
    assert torch.allclose(m.scales[5:], torch.exp(before["scales"][1]).expand(2, 3) / 1.6)
    assert not torch.equal(m.params["means"][5], m.params["means"][6])
    assert float((m.params["means"][5:] - before["means"][1]).norm(dim=-1).max()) < 0.5 * 6
    # Adam moments: kept for the originals, zero for the new ones; every tensor follows the parameters
    for name, p in m.params.items():
        st_p = opt.state[p]
        assert st_p["exp_avg"].shape == p.shape
        assert bool((st_p["exp_avg"][:3] != 0).all()) and bool((st_p["exp_avg"][3:] == 0).all()), name
        assert any(q is p for g in opt.param_groups for q in g["params"])
    assert st["grad2d"].shape == (7,)


def test_split_samples_follow_the_gaussian():
    # many splits of one anisotropic Gaussian: the offsets' covariance is R S^2 R^T
    s = DefaultStrategy(grow_grad2d=0.0, grow_scale3d=0.0)
    n = 4000
    m = _model([1.0] * n, [0.5] * n)
    q = torch.nn.functional.normalize(torch.tensor([0.9, 0.3, -0.2, 0.1]), dim=0)
    with torch.no_grad():
        m.params["quats"][:] = q
        m.params["scales"][:] = torch.log(torch.tensor([0.5, 0.1, 0.2]))
        m.params["means"][:] = 0
    st = s.initialize_state(n, "cpu")
    st["grad2d"][:] = 1.0
    st["count"][:] = 1.0
    s.grow(m, None, st, step=1000, scene_scale=1.0, generator=torch.Generator().manual_seed(0))
    off = m.params["means"].detach()
    R = quat_to_rotmat(q[None])[0]
    want = R @ torch.diag(torch.tensor([0.25, 0.01, 0.04])) @ R.T
    got = off.T @ off / off.shape[0]
    assert torch.allclose(got, want, atol=0.01)


def test_budget_keeps_the_largest_gradients():
    s = DefaultStrategy(grow_grad2d=0.5, grow_scale3d=0.1, max_gaussians=6)
    m = _model([0.05, 0.05, 0.05, 0.05, 0.05], [0.5] * 5)
    st = s.initialize_state(5, "cpu")
    st["grad2d"][:] = torch.tensor([1.0, 4.0, 2.0, 3.0, 0.1])
    st["count"][:] = 1.0
    before = m.params["sh0"].detach().clone()
    n_clone, n_split = s.grow(m, None, st, step=1000, scene_scale=1.0)
    assert (n_clone, n_split, len(m)) == (1, 0, 6)
    assert torch.equal(m.params["sh0"][5], before[1])  # the largest gradient grew
    n_clone, _ = s.grow(m, None, st, step=1100, scene_scale=1.0)
    assert n_clone == 0 and len(m) == 6  # full


def test_prune_opacity_and_size_after_reset():
    s = DefaultStrategy(prune_opa=0.01, prune_scale3d=0.1, reset_every=3000)
    m = _model([0.05, 0.05, 0.5, 0.05], [0.5, 0.005, 0.5, 0.5])
    st = s.initialize_state(4, "cpu")
    keep_sh = m.params["sh0"].detach()[[0, 2, 3]].clone()
    assert s.prune(m, None, st, step=1000, scene_scale=1.0) == 1  # transparent only: no size rule yet
    assert torch.equal(m.params["sh0"], keep_sh)
    assert s.prune(m, None, st, step=3100, scene_scale=1.0) == 1  # now the large one (0.5 > 0.1) goes
    assert len(m) == 2 and float(m.scales.max()) < 0.1


def test_reset_opacities_clamps_and_zeroes_moments():
    m = _model([0.05] * 3, [0.9, 0.005, 0.5])
    opt = _with_adam_state(m)
    before = m.opacities.detach().clone()
    reset_opacities(m, opt, 0.01)
    assert float(before[1]) < 0.01
    assert torch.allclose(m.opacities, torch.tensor([0.01, float(before[1]), 0.01]), atol=1e-6)
    p = m.params["opacities"]
    assert bool((opt.state[p]["exp_avg"] == 0).all()) and bool((opt.state[p]["exp_avg_sq"] == 0).all())
    assert bool((opt.state[m.params["means"]]["exp_avg"] != 0).all())


def test_step_post_backward_schedule_and_statistic():
    s = DefaultStrategy(refine_start_iter=2, refine_every=2, reset_every=4, refine_stop_iter=7, grow_grad2d=1e9)
    m = _model([0.05] * 20, [0.5] * 20)
    with torch.no_grad():  # half of them behind the camera: never visible
        m.params["means"][10:, 2] = -5.0
    opt = make_optimizer(m, Config(), 1.0)
    st = s.initialize_state(len(m), "cpu")
    events = []
    for step in range(9):
        out = _rendered_and_backward(m)
        if step == 0:
            from warpgs.render import means2d_grad_norm
            expect = means2d_grad_norm(out, 32, 32)
        info = s.step_post_backward(m, opt, st, step, out, 32, 32, 1.0)
        opt.zero_grad()
        if step == 0:  # the statistic: the norm in normalised device units, counted where visible
            vis = (out.radii > 0).all(-1)
            assert torch.allclose(st["grad2d"], torch.where(vis, expect, torch.zeros_like(expect)))
            assert torch.equal(st["count"], vis.float())
            assert int(vis[10:].sum()) == 0
        events.append((step, info["reset"]))
        if step in (4,):  # refined at step 4 (> start, % every == 0): statistics restart
            assert float(st["count"].sum()) == 0
    assert [e for e, r in events if r] == [4]  # reset at 4; 8 is past refine_stop_iter
    assert math.isclose(float(m.opacities.max()), 0.01, rel_tol=1e-4)


def test_contribution_is_the_blending_weight():
    V, K = CAMERA

    Cam = SimpleNamespace(viewmat=V, K=K, width=32, height=32)

    m = _model([0.3, 0.3, 0.3], [0.7, 0.7, 0.7], seed=3)
    with torch.no_grad():
        m.params["means"][:] = torch.tensor([[0.0, 0, 4], [0.3, 0, 5], [0.0, 0, -4]])  # last: behind
    w = contribution(m, [Cam, Cam])
    # with white colours on black the image is the accumulated alpha = sum of all weights
    alpha = m.render(V, K, 32, 32, sh_degree=None).alpha  # sh path irrelevant for alpha
    assert torch.allclose(w.sum(), 2 * alpha.sum(), rtol=1e-4)
    assert float(w[2]) == 0.0 and float(w[0]) > float(w[1]) > 0
    # a lone Gaussian: its weight is its alpha image
    one = _model([0.3], [0.7], seed=3)
    with torch.no_grad():
        one.params["means"][:] = torch.tensor([[0.1, 0.0, 4.0]])
    assert torch.allclose(contribution(one, [Cam])[0], one.render(V, K, 32, 32).alpha.sum(), rtol=1e-5)


def test_prune_unseen_drops_unseen_and_transparent():
    V, K = CAMERA

    Cam = SimpleNamespace(viewmat=V, K=K, width=32, height=32)

    s = DefaultStrategy(prune_opa=0.005, unseen_min_weight=0.05)
    m = _model([0.3, 0.3, 0.3, 0.3], [0.7, 0.7, 0.003, 0.7], seed=4)
    with torch.no_grad():
        m.params["means"][:] = torch.tensor([[0.0, 0, 4], [0.0, 0, -4], [0.2, 0, 4], [50.0, 0, 4]])
    opt = make_optimizer(m, Config(), 1.0)
    st = s.initialize_state(4, "cpu")
    keep = m.params["means"][0].detach().clone()
    assert s.prune_unseen(m, opt, st, [Cam]) == 3  # behind, transparent, off-screen
    assert len(m) == 1 and torch.equal(m.params["means"][0], keep)
    assert st["grad2d"].shape == (1,)


@pytest.mark.parametrize("q", [[1.0, 0, 0, 0], [0.7, 0.1, -0.5, 0.3]])
def test_quat_to_rotmat_is_a_rotation(q):
    q = torch.nn.functional.normalize(torch.tensor(q), dim=0)
    R = quat_to_rotmat(q[None])[0]
    assert torch.allclose(R @ R.T, torch.eye(3), atol=1e-6)
    assert math.isclose(float(torch.det(R)), 1.0, rel_tol=1e-6)
    # rotating by q: v' = q v q*, checked on the x axis
    w, x, y, z = q.tolist()
    vx = torch.tensor([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])
    assert torch.allclose(R[:, 0], vx, atol=1e-6)


def test_without_the_opacity_reset_the_large_are_still_pruned_after_reset_every(monkeypatch):
    """``reset_opacity: false`` (gsplat 1.5.3's DefaultStrategy, whose reset test is never true): no reset at
    ``reset_every``, the opacities and their Adam moments untouched there, and the pruning of the too large
    still starts after it, at the same refinement steps."""
    for reset in (True, False):
        s = DefaultStrategy(refine_start_iter=2, refine_every=2, reset_every=4, refine_stop_iter=7, grow_grad2d=1e9,
                            prune_opa=0.001, prune_scale3d=0.1, reset_opacity=reset)
        m = _model([0.05] * 5 + [0.5], [0.5] * 6)
        opt = _with_adam_state(m)
        st = s.initialize_state(len(m), "cpu")
        events = []
        for step in range(9):
            out = _rendered_and_backward(m)
            before = m.opacities.detach().clone()
            info = s.step_post_backward(m, opt, st, step, out, 32, 32, 1.0)
            events.append((step, info["reset"], info["pruned"]))
            if step == 4 and not reset:
                assert torch.equal(m.opacities, before)  # nothing clamped
                assert bool((opt.state[m.params["opacities"]]["exp_avg"] != 0).any())
            assert s.only_updates_state(step) == (not (info["reset"] or step in (4, 6)))
        assert [e for e, r, _ in events if r] == ([4] if reset else [])
        assert [e for e, _, p in events if p] == [6] and len(m) == 5  # the large one, after reset_every


@pytest.mark.parametrize("pause", [0, 3])
def test_only_updates_state_is_what_step_post_backward_does(monkeypatch, pause):
    """``only_updates_state(step)`` (whether a CUDA graph may hold the step's densification) is true exactly at
    the steps where ``step_post_backward`` neither grows, prunes nor resets, over a schedule with its start,
    stop, pause after a reset and reset steps."""
    s = DefaultStrategy(refine_start_iter=3, refine_every=2, reset_every=6, refine_stop_iter=20,
                        pause_refine_after_reset=pause)
    m = _model([0.05] * 4, [0.5] * 4)
    opt = make_optimizer(m, Config(), 1.0)
    st = s.initialize_state(len(m), "cpu")
    acted = []
    monkeypatch.setattr(s, "update_state", lambda *a: None)
    monkeypatch.setattr(s, "grow", lambda *a, **k: acted.append("grow") or (0, 0))
    monkeypatch.setattr(s, "prune", lambda *a, **k: acted.append("prune") or 0)
    monkeypatch.setattr("warpgs.strategy.default.reset_opacities", lambda *a, **k: acted.append("reset"))
    seen = set()
    for step in range(26):
        acted.clear()
        s.step_post_backward(m, opt, st, step, None, 8, 8, 1.0)
        assert s.only_updates_state(step) == (not acted), (step, acted)
        seen.add(bool(acted))
    assert seen == {True, False}


# ----------------------------------------------------------------------------------------------
# strategy.refine_stop_fraction: growth stopped at a share of the run (warpgs.train.growth_schedule)


def test_refine_stop_fraction_resolves_against_the_run_length():
    from warpgs.train import growth_schedule

    cfg = Config()
    cfg.train.iterations = 3000
    assert growth_schedule(cfg) is cfg  # 0: refine_stop_iter alone, the config untouched
    cfg.strategy.refine_stop_fraction = 0.5
    assert growth_schedule(cfg).strategy.refine_stop_iter == 1500
    assert cfg.strategy.refine_stop_iter == 15_000  # the caller's config is not changed
    cfg.train.iterations = 40_000  # 20,000 comes after refine_stop_iter: the earlier one holds
    assert growth_schedule(cfg).strategy.refine_stop_iter == 15_000
    cfg.train.iterations = 3001
    assert growth_schedule(cfg).strategy.refine_stop_iter == 1500  # round(1500.5): banker's rounding, an int
    # the full method's own fraction when set (0 too: growth as refine_stop_iter says); the baseline ignores it
    cfg.train.iterations = 3000
    cfg.full.refine_stop_fraction = 0.0
    assert growth_schedule(cfg, "full").strategy.refine_stop_iter == 15_000
    assert growth_schedule(cfg, "baseline").strategy.refine_stop_iter == 1500
    cfg.full.refine_stop_fraction = 0.25
    assert growth_schedule(cfg, "full").strategy.refine_stop_iter == 750
    cfg.full.refine_stop_fraction = None
    assert growth_schedule(cfg, "full").strategy.refine_stop_iter == 1500


def test_refine_stop_fraction_is_the_same_training_as_the_step_it_names():
    """On the tiny scene (growth every 20 steps from step 30): 0.7 of 100 steps trains exactly as
    refine_stop_iter=70 (growth at 40 and 60, none at 80), and differs from growth to the end."""
    from tests.tiny_scene import make_scene, param_copy, same_params, tiny_config
    from warpgs.train import Trainer

    def run(**strategy):
        cfg = tiny_config(100)
        for k, v in strategy.items():
            setattr(cfg.strategy, k, v)
        t = Trainer(cfg, make_scene(), None, log=lambda m: None)
        t.train()
        return t

    frac = run(refine_stop_fraction=0.7)
    assert frac.cfg.strategy.refine_stop_iter == 70 and frac.strategy.refine_stop_iter == 70
    assert frac.requested_cfg.strategy.refine_stop_iter == 250  # what its checkpoints keep (tests/test_hold_geometry.py)
    step = run(refine_stop_iter=70)
    assert same_params(param_copy(frac), param_copy(step))
    free = run()
    assert len(free.model) != len(frac.model)  # the free run grew or pruned at step 80 too


def test_a_bad_refine_stop_fraction_is_named():
    from warpgs.config import ConfigError, load_config

    with pytest.raises(ConfigError, match="refine_stop_fraction"):
        load_config(overrides=["strategy.refine_stop_fraction=1.5"])
    with pytest.raises(ConfigError, match="refine_stop_fraction"):
        load_config(overrides=["full.refine_stop_fraction=-0.1"])
