"""The weight-free regularisers of issue 14, each a config switch that is off by default: opacity noise
(``train.opacity_noise``, with DropGaussian's ``train.drop_rate`` in ``Trainer.opacity_scale``), the
anisotropy prior (``train.scale_reg``) and the pseudo views' edge-aware depth smoothness
(``full.pseudo_depth_smooth``). Each is checked against its definition, and each switched off against the
training it replaces: the new code does not run and the losses are those of the code without it."""

import math

import numpy as np
import pytest
import torch

from tiny_scene import make_scene, param_copy, record_loss_parts, same_params, small_full_trainer, tiny_config
from warpgs import losses
from warpgs.config import ConfigError, load_config
from warpgs.train import Trainer


def dropout_scale(tr, step):
    """DropGaussian's factors alone for one training render of ``tr``'s model at ``step`` (None at rate 0)."""
    return tr.regularizers.get("dropout").opacity_factor(tr.context, step, len(tr.model), tr.drop_gen)


def _trainer(tmp_path=None, iterations=30, init_num=300, **train):
    cfg = tiny_config(iterations, **train)
    cfg.model.init_num = init_num
    return Trainer(cfg, make_scene(), tmp_path)


def _normal_cdf(x):
    return 0.5 * (1 + math.erf(x / math.sqrt(2)))


# ----------------------------------------------------------------------------------------------
# opacity noise (Co-Adaptation) and its composition with DropGaussian


def test_opacity_noise_factors_have_the_clipped_normal_statistics():
    """1 + eps, eps = sigma clip(Z, -1, 1), Z standard normal: mean 1, variance sigma^2 E[min(Z^2, 1)] =
    sigma^2 (1 - 2 phi(1)), a share P(|Z| > 1) on the bounds 1 -+ sigma; each within 4 standard errors."""
    sigma, n = 0.8, 20000
    tr = _trainer(init_num=n, opacity_noise=sigma)
    s = tr.opacity_scale(0).double()
    assert s.shape == (n,) and dropout_scale(tr, 0) is None
    phi1 = math.exp(-0.5) / math.sqrt(2 * math.pi)
    p_out = 2 * (1 - _normal_cdf(1.0))
    m2 = 1 - 2 * phi1  # E[min(Z^2, 1)]
    m4 = 3 * (1 - p_out) - 8 * phi1 + p_out  # E[min(Z^4, 1)]
    assert float(s.min()) >= 1 - sigma - 1e-6 and float(s.max()) <= 1 + sigma + 1e-6
    assert abs(float(s.mean()) - 1) < 4 * sigma * math.sqrt(m2 / n)
    y2 = ((s - 1) / sigma) ** 2
    assert abs(float(y2.mean()) - m2) < 4 * math.sqrt((m4 - m2 ** 2) / n)
    on_bounds = float(((s - 1).abs() > sigma - 1e-5).double().mean())
    assert abs(on_bounds - p_out) < 4 * math.sqrt(p_out * (1 - p_out) / n)
    # seeded: the same seed gives the same factors, another seed others
    assert torch.equal(_trainer(init_num=n, opacity_noise=sigma).opacity_scale(0), s.float())
    assert not torch.equal(_trainer(init_num=n, opacity_noise=sigma, seed=1).opacity_scale(0), s.float())


def test_opacity_noise_composes_with_dropgaussian():
    """With both: DropGaussian's mask (drawn first, so the same as without noise) times the noise; the
    dropped stay at 0, the kept get 1 / (1 - rate) x (1 + eps), and the opacity is kept in expectation."""
    n, sigma, rate = 20000, 0.5, 0.2
    both = _trainer(init_num=n, opacity_noise=sigma, drop_rate=rate)
    drop = _trainer(init_num=n, drop_rate=rate)
    step = both.total_steps  # the final rate
    s, d = both.opacity_scale(step), drop.opacity_scale(step)
    assert torch.equal(s == 0, d == 0)
    assert abs(float((s == 0).float().mean()) - rate) < 4 * math.sqrt(rate * (1 - rate) / n)
    kept = s[s > 0] * (1 - rate)
    assert float(kept.min()) >= 1 - sigma - 1e-6 and float(kept.max()) <= 1 + sigma + 1e-6
    # Var(keep / (1 - rate) (1 + eps)) = E[X^2] - 1 with E[X^2] = (1 + sigma^2 m2) / (1 - rate)
    m2 = 1 - 2 * math.exp(-0.5) / math.sqrt(2 * math.pi)
    var = (1 + sigma ** 2 * m2) / (1 - rate) - 1
    assert abs(float(s.double().mean()) - 1) < 4 * math.sqrt(var / n)


def test_switched_off_the_noise_draws_nothing():
    tr = _trainer(drop_rate=0.2)
    before = tr.drop_gen.get_state()
    assert tr.opacity_scale(0) is None  # the rate starts at 0 and there is no noise
    assert torch.equal(tr.drop_gen.get_state(), before)
    ref = _trainer(drop_rate=0.2)
    assert torch.equal(tr.opacity_scale(20), dropout_scale(ref, 20))


def test_noise_and_dropout_act_on_training_renders_only(monkeypatch):
    """Every training render gets per-Gaussian factors; the evaluation renders (test metrics, the curve)
    get none: they render the model as it is."""
    tr = _trainer(iterations=6, opacity_noise=0.8, drop_rate=0.3)
    calls = []
    render = tr.model.render

    def spy(*a, **kw):  # the training step's render is the one without input checks
        calls.append(("train" if kw.get("check_finite") is False else "eval", kw.get("opacity_scale")))
        return render(*a, **kw)

    monkeypatch.setattr(tr.model, "render", spy)
    tr.train()  # (it evaluates the initial model first)
    train = [s for kind, s in calls if kind == "train"]
    assert len(train) == 6 and all(s is not None and s.shape == (len(tr.model),) for s in train)
    assert [s for kind, s in calls if kind == "eval"] == [None] * len(tr.test_cams)
    calls.clear()
    ev = tr.evaluate(lpips=False)["mean"]
    assert calls and all(s is None for _, s in calls)
    cam = tr.test_cams[0]  # the test render is the model as it is
    clean = render(cam.viewmat, cam.K, cam.width, cam.height, background=tr.background)
    assert torch.equal(tr.render(cam).image, clean.image) and np.isfinite(ev["psnr"])


# ----------------------------------------------------------------------------------------------
# anisotropy prior on the scales (PhysGaussian)


def test_scale_anisotropy_loss_by_hand():
    """Axis ratios 40, 1 and 100 with r = 10: (30 + 0 + 90) / 3 = 40; the gradient on a penalised
    Gaussian's log-scales is +ratio / N on its largest, -ratio / N on its smallest, 0 on the middle one."""
    s = torch.tensor([[1.0, 2.0, 40.0], [3.0, 3.0, 3.0], [0.5, 10.0, 0.1]], dtype=torch.float64)
    ls = s.log().requires_grad_(True)
    value = losses.scale_anisotropy_loss(ls, 10.0)
    assert float(value.detach()) == pytest.approx(40.0, rel=1e-12)
    value.backward()
    want = torch.tensor([[-40 / 3, 0, 40 / 3], [0, 0, 0], [0, 100 / 3, -100 / 3]], dtype=torch.float64)
    assert torch.allclose(ls.grad, want, rtol=1e-10, atol=1e-12)
    assert float(losses.scale_anisotropy_loss(ls.detach()[:0], 10.0)) == 0.0
    with pytest.raises(ValueError, match=r"\[N, 3\]"):
        losses.scale_anisotropy_loss(ls.detach()[:, :2], 10.0)
    with pytest.raises(ValueError, match="max_ratio"):
        losses.scale_anisotropy_loss(ls.detach(), 0.5)


def test_scale_anisotropy_loss_gradient_matches_finite_differences():
    g = torch.Generator().manual_seed(3)
    ls = (torch.randn(40, 3, generator=g, dtype=torch.float64) * 1.5).requires_grad_(True)
    ratio = torch.exp(ls.max(1).values - ls.min(1).values)
    assert (ratio > 4.0).any() and (ratio < 4.0).any()  # both sides of r; no ratio at the kink
    assert float((ratio - 4.0).abs().min()) > 1e-3
    assert torch.autograd.gradcheck(lambda x: losses.scale_anisotropy_loss(x, 4.0), (ls,), eps=1e-7, atol=1e-7)


def test_scale_reg_adds_its_weighted_term_to_the_loss():
    tr = _trainer(scale_reg=0.5, scale_reg_ratio=1.5)
    with torch.no_grad():  # the initial Gaussians are round: stretch them
        tr.model.params["scales"] += torch.randn(tr.model.params["scales"].shape, generator=torch.Generator().manual_seed(0))
    cam = tr.train_cams[0]
    out = tr.render(cam)
    loss, parts = tr.compute_loss(out, cam)
    want = losses.scale_anisotropy_loss(tr.model.params["scales"], 1.5)
    assert float(parts["scale_reg"]) == float(want) > 0
    assert torch.allclose(loss, parts["inputs"] + 0.5 * want)


# ----------------------------------------------------------------------------------------------
# edge-aware depth smoothness


def slow_edge_aware_smoothness(depth, image, eps=1e-7):
    """The definition, pixel by pixel: |D(x+1) - D(x)| exp(-mean_c |I_c(x+1) - I_c(x)|), averaged over the
    horizontal pairs, plus the same over the vertical pairs, with D = depth / mean(depth)."""
    h, w = depth.shape
    d = depth / (depth.sum() / (h * w) + eps)
    sx, sy = 0.0, 0.0
    for y in range(h):
        for x in range(w):
            if x + 1 < w:
                edge = sum(abs(image[y, x + 1, c] - image[y, x, c]) for c in range(image.shape[2])) / image.shape[2]
                sx = sx + abs(d[y, x + 1] - d[y, x]) * torch.exp(-edge)
            if y + 1 < h:
                edge = sum(abs(image[y + 1, x, c] - image[y, x, c]) for c in range(image.shape[2])) / image.shape[2]
                sy = sy + abs(d[y + 1, x] - d[y, x]) * torch.exp(-edge)
    return sx / (h * (w - 1)) + sy / ((h - 1) * w)


def test_edge_aware_smoothness_against_the_slow_oracle():
    g = torch.Generator().manual_seed(0)
    depth = (1 + 3 * torch.rand(7, 9, generator=g, dtype=torch.float64)).requires_grad_(True)
    image = torch.rand(7, 9, 3, generator=g, dtype=torch.float64)
    image[:, 4:] += 0.8  # an edge: depth may jump there at less cost
    fast = losses.edge_aware_smoothness(depth, image)
    slow = slow_edge_aware_smoothness(depth, image)
    assert float(fast) == pytest.approx(float(slow), rel=1e-12)
    (g_fast,) = torch.autograd.grad(fast, depth)
    (g_slow,) = torch.autograd.grad(slow, depth)
    assert torch.allclose(g_fast, g_slow, rtol=1e-10, atol=1e-12)
    # blind to the depth's scale (but for eps); 0 on a constant depth whatever the image
    assert float(losses.edge_aware_smoothness(depth.detach() * 7.5, image)) == pytest.approx(float(fast), rel=1e-6)
    assert float(losses.edge_aware_smoothness(torch.full((7, 9), 2.5, dtype=torch.float64), image)) == 0.0
    assert float(losses.edge_aware_smoothness(torch.zeros(7, 9), image.float())) == 0.0
    with pytest.raises(ValueError, match="one size"):
        losses.edge_aware_smoothness(depth.detach(), image[:-1])


# ----------------------------------------------------------------------------------------------
# switched off: the losses of the code without them


def _losses_of_a_run(tr):
    """The training loss of every step of ``tr.run()`` (all of the method's phases) and the final parameters."""
    seen = []
    compute = tr.compute_loss

    def record(out, cam):
        loss, parts = compute(out, cam)
        seen.append(float(loss.detach()))
        return loss, parts

    tr.compute_loss = record
    tr.run()
    return seen, param_copy(tr)


def test_baseline_switches_off_give_the_losses_of_the_code_without_them(monkeypatch):
    """A tiny baseline run (densification included) with the switches off, against the same run where the
    switches' code cannot run: ``opacity_scale`` is DropGaussian's factor alone, as the training render
    used before, and the new loss terms raise. Identical losses at every step and identical parameters;
    each switch turned on changes them."""
    steps = 40
    off_losses, off_params = _losses_of_a_run(_trainer(iterations=steps, drop_rate=0.2))
    with monkeypatch.context() as mp:
        mp.setattr(Trainer, "opacity_scale", lambda self, step, *rest: dropout_scale(self, step))

        def forbidden(*a, **kw):
            raise AssertionError("a switched-off regulariser ran")

        mp.setattr(losses, "scale_anisotropy_loss", forbidden)
        mp.setattr(losses, "edge_aware_smoothness", forbidden)
        old_losses, old_params = _losses_of_a_run(_trainer(iterations=steps, drop_rate=0.2))
    assert off_losses == old_losses and same_params(off_params, old_params)
    for switch in ({"opacity_noise": 0.8}, {"scale_reg": 0.1, "scale_reg_ratio": 1.0}):
        on_losses, _ = _losses_of_a_run(_trainer(iterations=steps, drop_rate=0.2, **switch))
        assert on_losses != off_losses, switch


def test_full_method_pseudo_depth_smoothness_switch(tmp_path, monkeypatch):
    """The full method: off (the default) the smoothness never runs; on, it is a term of every step with
    a pseudo view, recorded in the step's parts, and zero before the first cycle."""
    def forbidden(*a, **kw):
        raise AssertionError("a switched-off regulariser ran")

    with monkeypatch.context() as mp:
        mp.setattr(losses, "edge_aware_smoothness", forbidden)
        _, tr = small_full_trainer(tmp_path / "off")
        assert tr.cfg.full.pseudo_depth_smooth == 0
        off_losses, _ = _losses_of_a_run(tr)
    _, tr = small_full_trainer(tmp_path / "on", "--set", "full.pseudo_depth_smooth=0.5")
    parts_seen = record_loss_parts(tr)
    on_losses, _ = _losses_of_a_run(tr)
    with_pseudo = [p for p in parts_seen if "pseudo" in p]
    assert with_pseudo and all("pseudo_depth_smooth" in p for p in with_pseudo)
    assert all("pseudo_depth_smooth" not in p for p in parts_seen if "pseudo" not in p)
    assert all(float(p["pseudo_depth_smooth"]) >= 0 for p in with_pseudo)
    first = next(i for i, p in enumerate(parts_seen) if "pseudo" in p)
    assert on_losses[:first] == off_losses[:first] and on_losses[first:] != off_losses[first:]


def test_bad_switch_values_are_named():
    for override, words in (("train.opacity_noise=1.5", "train.opacity_noise"),
                            ("train.scale_reg=-1", "train.scale_reg"),
                            ("train.scale_reg_ratio=0.5", "train.scale_reg_ratio"),
                            ("full.pseudo_depth_smooth=-0.1", "full.pseudo_depth_smooth")):
        with pytest.raises(ConfigError, match=words.replace(".", r"\.")):
            load_config(overrides=[override])
    cfg = tiny_config(10)
    cfg.train.opacity_noise = 2.0  # options built in code
    with pytest.raises(ValueError, match="opacity_noise"):
        Trainer(cfg, make_scene())
