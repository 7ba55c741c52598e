"""bench/perf/race_gsplat.py's pure parts: the recipe mapped into warpgs's config (every regulariser and every
non-3D-GS dataset default off, the strategy's thresholds gsplat's DefaultStrategy's), the check of a built
trainer against the plain recipe, and the CPU smoke path (the warpgs side alone) on a tiny shrink of fern."""

import dataclasses
import importlib.util
import json
import math
import os
import sys
from pathlib import Path

import pytest
import torch

from tiny_scene import make_scene, tiny_config
from warpgs.config import RegularizersConfig
from warpgs.train import Trainer

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "perf"))

SHARED = Path(os.environ.get("WARPGS_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))


def gsplat_defaults() -> dict:
    """DefaultStrategy's dataclass defaults from gsplat itself where it is installed, else gsplat 1.5.3's, as
    gsplat/strategy/default.py lists them."""
    try:
        from gsplat.strategy import DefaultStrategy
    except ImportError:
        return {"prune_opa": 0.005, "grow_grad2d": 0.0002, "grow_scale3d": 0.01, "grow_scale2d": 0.05,
                "prune_scale3d": 0.1, "prune_scale2d": 0.15, "refine_scale2d_stop_iter": 0,
                "refine_start_iter": 500, "refine_stop_iter": 15_000, "reset_every": 3000, "refine_every": 100,
                "pause_refine_after_reset": 0}
    return {f.name: f.default for f in dataclasses.fields(DefaultStrategy)
            if f.name not in ("absgrad", "revised_opacity", "verbose", "key_for_gradient")}


@pytest.mark.parametrize("scale", ["fern3", "castle9", "lego8"])
def test_the_recipe_in_warpgs_config(scale):
    import race_gsplat as rg

    strategy = rg.gsplat_strategy_defaults()
    assert strategy == gsplat_defaults()
    cfg = rg.make_config(scale, "../shared/data", 7000, "cpu", 0, strategy, scene_scale=2.5)
    # the dataset's own config turns regularisers on (the binocular preset: dropout, opacity decay, the binocular
    # term); the recipe turns every one off, and a default RegularizersConfig has every one off
    assert cfg.regularizers == RegularizersConfig()
    r = cfg.regularizers
    assert (r.alpha_binary.weight, r.scale_reg.weight, r.dropout.rate, r.opacity_noise.sigma, r.opacity_decay.rate,
            r.binocular.weight, r.path_consistency.weight) == (0, 0, 0, 0, 0, 0, 0)
    t = cfg.train
    assert (t.far_field, t.path_clearance, t.view_clearance, t.path_floaters, t.hold_geometry, t.random_background,
            t.prune_unseen_at_end, t.co_reg) == ("none", 0, 0, 0, "off", False, False, False)
    assert not cfg.compact.enabled and cfg.method == "baseline"
    s = cfg.strategy
    assert {k: getattr(s, k) for k in strategy} == strategy
    assert s.refine_stop_fraction == 0 and s.max_gaussians == 0
    # simple_trainer's learning rates, loss, SH schedule, initial opacity and scale, and the race's scene scale
    o = cfg.optim
    assert (o.means_lr, o.scales_lr, o.quats_lr, o.opacities_lr, o.sh0_lr, o.eps) == (1.6e-4, 5e-3, 1e-3, 5e-2, 2.5e-3, 1e-15)
    assert math.isclose(o.shN_lr, 2.5e-3 / 20) and math.isclose(o.means_lr_final, 0.01 * o.means_lr)
    assert o.means_lr_decay_steps is None and o.scene_scale == 2.5
    assert (cfg.loss.l1_weight, cfg.loss.ssim_weight, cfg.loss.depth_weight, cfg.loss.alpha_weight) == (0.8, 0.2, 0, 0)
    assert (t.sh_degree_interval, cfg.model.sh_degree, cfg.model.init_opacity, cfg.model.init_scale) == (1000, 3, 0.1, 1.0)
    assert t.iterations == 7000


def test_without_the_recipe_the_datasets_turn_regularisers_on():
    """The overrides are needed: the same CLI layers without them switch on what the recipe turns off."""
    import race_gsplat as rg
    from warpgs.pipelines.sparse import build_parser, make_config

    for scale in rg.SCALES:
        cfg, _ = make_config(build_parser().parse_args(rg.scale_argv(scale, "../shared/data", 100, "cpu", 0)))
        assert cfg.regularizers != RegularizersConfig()
    cfg, _ = make_config(build_parser().parse_args(rg.scale_argv("castle9", "../shared/data", 100, "cpu", 0)))
    assert cfg.train.hold_geometry == "stereo" and cfg.train.far_field != "none" and cfg.strategy.grow_grad2d != 0.0002


def test_plain_problems_names_what_is_not_the_recipe():
    import race_gsplat as rg

    strategy = rg.gsplat_strategy_defaults()
    cfg = tiny_config(20)
    for k, v in strategy.items():
        setattr(cfg.strategy, k, v)
    cfg.strategy.max_gaussians = 0
    cfg.strategy.reset_opacity = False  # as gsplat 1.5.3 (its reset test is never true)
    cfg.model.alpha_max = 0.999  # its kernels' cap
    assert rg.plain_problems(Trainer(cfg, make_scene()), strategy) == []
    bad = tiny_config(20)  # its budget and thresholds are the tests', not gsplat's; 3D-GS's reset and alpha cap
    bad.regularizers.dropout.rate = 0.2
    bad.regularizers.opacity_decay.rate = 0.005
    bad.train.hold_geometry = "on"
    bad.loss.depth_weight = 0.5
    problems = rg.plain_problems(Trainer(bad, make_scene()), strategy)
    text = "; ".join(problems)
    assert "dropout" in text and "opacity_decay" in text and "geometry held" in text
    assert "strategy.refine_start_iter" in text and "strategy.max_gaussians" in text and "depth" in text
    assert "reset_opacity" in text and "alpha capped at 0.99" in text


@pytest.mark.skipif(not (SHARED / "llff_fern").is_dir(), reason=f"shared data not found at {SHARED}")
def test_cpu_smoke_writes_the_warpgs_side(tmp_path):
    import race_gsplat as rg

    out = tmp_path / "race.json"
    r = rg.main(["--device", "cpu", "--scale", "fern3", "--shrink", "16", "--iterations", "12",
                 "--data-root", str(SHARED), "--strategy-set", "refine_start_iter=2", "--strategy-set", "refine_every=5",
                 "--profile", "--profile-steps", "2", "--out", str(out)])
    assert json.loads(out.read_text()) == json.loads(json.dumps(r))
    s = r["scales"]["fern3"]
    assert "gsplat" not in s and s["time_ratio"] is None and s["counts_within_5pct"] is None
    w = s["warpgs"]
    assert w["gaussians"] != s["initial_gaussians"]  # densified at steps 5 and 10
    assert math.isfinite(w["test_psnr"]) and w["seconds"] > 0 and s["test_views"] == 3 and s["views"] == 3
    assert w["profile"]["steps"] == 2 and w["profile"]["top_cpu_ops"]
    assert s["iterations"] == 12 and r["recipe"]["strategy"]["refine_start_iter"] == 2
    assert "regularizers.dropout.rate=0" in r["recipe"]["warpgs_overrides"]
    assert r["machine"]["torch"] and r["machine"]["warp"]


def test_repeats_take_the_medians_and_give_each_sides_spread():
    import race_gsplat as rg

    rows = [{"seconds": 10.0, "it_per_s": 700.0, "gaussians": 1000, "test_psnr": 20.0, "train_psnr": 30.0, "ssim": "x"},
            {"seconds": 14.0, "it_per_s": 500.0, "gaussians": 1100, "test_psnr": 22.5, "train_psnr": 31.0, "ssim": "x"},
            {"seconds": 12.0, "it_per_s": 583.33, "gaussians": 900, "test_psnr": 21.0, "train_psnr": 32.0, "ssim": "x"}]
    m = rg.median_row(rows)
    assert (m["seconds"], m["gaussians"], m["test_psnr"], m["train_psnr"], m["runs"]) == (12.0, 1000, 21.0, 31.0, 3)
    assert m["it_per_s"] == pytest.approx(7000 / 12.0, abs=0.01) and m["ssim"] == "x"
    assert rg.median_row(rows[:1]) is rows[0]
    sp = rg.spread(rows)
    assert sp == {"test_psnr_db": 2.5, "gaussians_rel": 0.2, "seconds_rel": round(4.0 / 12.0, 4)}


class _Means2d:
    """gsplat's ``info["means2d"]`` [C, N, 2] over warpgs's [N, 2] (which ``rasterize`` retains the gradient of)."""

    def __init__(self, t):
        self.t = t

    def retain_grad(self):
        pass

    @property
    def grad(self):
        return None if self.t.grad is None else self.t.grad[None]


def warpgs_as_gsplat_rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, *,
                                   near_plane, far_plane, sh_degree, packed, absgrad, backgrounds, rasterize_mode):
    """``gsplat.rasterization``'s interface (one camera, packed=False) over warpgs's CPU rasterizer: gsplat's CUDA
    kernels cannot run here, its loop, strategy, optimisers and scheduler can."""
    from warpgs.render import rasterize

    assert packed is False and absgrad is False and rasterize_mode == "classic"
    out = rasterize(means, quats, scales, opacities, colors, viewmats[0], Ks[0], width, height, sh_degree=sh_degree,
                    background=backgrounds[0], near_plane=near_plane, far_plane=far_plane)
    info = {"means2d": _Means2d(out.means2d), "radii": out.radii[None], "width": width, "height": height,
            "n_cameras": 1, "gaussian_ids": None}
    return out.image[None], out.alpha[None], info


@pytest.mark.skipif(importlib.util.find_spec("gsplat") is None, reason="gsplat is not installed")
def test_the_gsplat_loop_and_the_trainer_train_alike_on_one_rasterizer(monkeypatch):
    """The gsplat side (its DefaultStrategy, Adam per parameter, ExponentialLR) and the warpgs side (the trainer with
    the recipe's overrides), on warpgs's rasterizer, from the same initial Gaussians in the same view order: the
    same parameters, bit for bit, until the first refinement (learning rates, their decay, the loss, the SH
    schedule, the order), then counts within 5% of each other (the split noise comes from different generators)."""
    import gsplat
    import race_gsplat as rg
    from warpgs.config import load_config

    monkeypatch.setattr(gsplat, "rasterization", warpgs_as_gsplat_rasterization)
    strategy = {**rg.gsplat_strategy_defaults(), "refine_start_iter": 3, "refine_every": 6, "reset_every": 1000}
    steps, interval = 20, 2

    def build(scene_scale):
        return load_config(overrides=rg.recipe_overrides(strategy, scene_scale) + [
            "train.device=cpu", "train.progress=false", f"train.iterations={steps}", "train.checkpoint_every=0",
            f"train.sh_degree_interval={interval}", "model.init=box", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]",
            "model.init_num=300"])

    sc = rg.Scale("tiny", make_scene(), build, strategy, seed=0)
    g, w = rg.GsplatSide(sc, steps, {"sh_degree_interval": interval}), rg.WarpgsSide(sc, steps)
    g.train(6)  # steps 0-5: SH degrees 0, 1, 2; the first refinement is at step 6
    w.train(6)
    for name, p in g.splats.items():
        assert torch.equal(p.detach(), w.tr.model.params[name].detach()), name
    assert not torch.equal(g.splats["means"].detach(), sc.params()["means"])  # they did train
    g.train(steps)
    w.train(steps)
    assert len(w) != sc.initial_gaussians  # densified
    assert abs(len(g) - len(w)) <= 0.05 * len(w)
    lr = g.optimizers["means"].param_groups[0]["lr"]
    assert math.isclose(lr, 1.6e-4 * sc.scene_scale * 0.01, rel_tol=1e-6)  # simple_trainer's decay, to 0.01x
    assert math.isclose(w.tr.means_lr(steps), lr, rel_tol=1e-6)
