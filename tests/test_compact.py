"""Compact mode (warpgs/strategy/compact.py): importance pruning, the search's tolerance on the training views,
SH-degree reduction, PLY at a reduced degree, byte counts, the schedule during training, the CLI flag."""

import copy
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import reference
from tiny_scene import camera_ring, make_scene, tiny_config, write_nerfstudio
from warpgs.strategy.compact import (CompactConfig, ScheduledPruning, attach, check_config, importance, lowest_mask, param_bytes,
                            ply_bytes, prune_lowest, search, size_report, truncate_sh, virtual_cameras)
from warpgs.config import Config
from warpgs.model import GaussianModel
from warpgs.train import Trainer, make_optimizer


def _model(n=30, degree=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g) * 2 - 1) * torch.tensor([1.0, 1.0, 0.6]) + torch.tensor([0.0, 0.0, 4.0])
    quats = torch.randn(n, 4, generator=g)
    scales = torch.log(0.05 + 0.25 * torch.rand(n, 3, generator=g))
    opac = torch.logit(0.05 + 0.9 * torch.rand(n, generator=g))
    sh0 = torch.randn(n, 1, 3, generator=g)
    shN = 0.5 * torch.randn(n, (degree + 1) ** 2 - 1, 3, generator=g)
    m = GaussianModel(means, quats, scales, opac, sh0, shN, max_sh_degree=degree)
    m.active_sh_degree = degree
    return m


def _cams(w=24, h=20):
    K = torch.tensor([[26.0, 0, w / 2], [0, 26.0, h / 2], [0, 0, 1]])
    V1 = torch.eye(4)
    V2 = torch.eye(4)
    a = math.radians(12)
    V2[:3, :3] = torch.tensor([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    V2[:3, 3] = torch.tensor([-0.6, 0.1, 0.3])
    return [SimpleNamespace(viewmat=V, K=K, width=w, height=h) for V in (V1, V2)]


def brute_force_weights(model, cams) -> torch.Tensor:
    """sum over pixels and cameras of alpha_i T_i, by the torch oracle's compositing loop (float64)."""
    total = torch.zeros(len(model), dtype=torch.float64)
    p = {k: v.detach().double() for k, v in model.params.items()}
    for cam in cams:
        V, K, W, H = cam.viewmat.double(), cam.K.double(), cam.width, cam.height
        m2d, conics, depths, o, radii = reference.project(p["means"], p["quats"], torch.exp(p["scales"]),
                                                         torch.sigmoid(p["opacities"]), V, K, W, H)
        mask = reference.tile_mask(m2d, radii, W, H)
        py, px = torch.meshgrid(torch.arange(H, dtype=torch.float64) + 0.5, torch.arange(W, dtype=torch.float64) + 0.5,
                                indexing="ij")
        T = torch.ones(H, W, dtype=torch.float64)
        done = torch.zeros(H, W, dtype=torch.bool)
        for g in torch.argsort(depths, stable=True).tolist():
            dx, dy = m2d[g, 0] - px, m2d[g, 1] - py
            sigma = 0.5 * (conics[g, 0] * dx * dx + conics[g, 2] * dy * dy) + conics[g, 1] * dx * dy
            alpha = torch.clamp(o[g] * torch.exp(-sigma), max=0.99)
            use = mask[g] & (sigma >= 0) & (alpha >= 1 / 255) & ~done
            nxt = T * (1 - alpha)
            stop = use & (nxt <= 1e-4)
            done |= stop
            use &= ~stop
            total[g] += float(torch.where(use, alpha * T, torch.zeros_like(T)).sum())
            T = torch.where(use, nxt, T)
    return total


def test_importance_is_the_blending_weight_and_pruning_keeps_the_highest():
    m, cams = _model(), _cams()
    w = importance(m, cams)
    bf = brute_force_weights(m, cams)
    assert float(bf.max()) > 1.0 and int((bf == 0).sum()) < len(m) // 2
    assert torch.allclose(w.double(), bf, rtol=1e-4, atol=1e-5)
    # pruning half: the kept ones are the brute-force top half (modulo near-ties at the threshold)
    ratio = 0.5
    k = int(round(ratio * len(m)))
    order = torch.argsort(bf, stable=True)
    threshold = float(bf[order[k - 1]] + bf[order[k]]) / 2
    near_tie = (bf - threshold).abs() < 1e-4 * max(threshold, 1e-3)
    before = {name: v.detach().clone() for name, v in m.params.items()}
    opt = make_optimizer(m, Config(), 1.0)
    state = {"grad2d": torch.arange(len(m), dtype=torch.float32)}
    assert prune_lowest(m, opt, state, w, ratio) == k
    kept = state["grad2d"].long()  # the statistic tracked the rows: it holds the kept indices, in order
    assert len(m) == len(before["means"]) - k and torch.equal(kept, torch.sort(kept).values)
    expect = set(order[k:].tolist())
    assert {i for i in kept.tolist() if not near_tie[i]} == {i for i in expect if not near_tie[i]}
    assert float(bf[kept].min()) >= float(bf[order[:k]].max()) - 1e-6
    for name in before:  # the rows are the originals', and the optimiser holds the new tensors
        assert torch.equal(m.params[name], before[name][kept])
        assert any(q is m.params[name] for gr in opt.param_groups for q in gr["params"])
    # weight_volume: LightGaussian's weight x (volume / max)^power ranks by that product
    wv = importance(m, cams, kind="weight_volume", volume_power=0.5)
    vol = m.scales.detach().prod(-1)
    assert torch.allclose(wv, importance(m, cams) * (vol / vol.max()) ** 0.5, rtol=1e-5)


def test_lowest_mask_counts_and_keeps_one():
    s = torch.tensor([3.0, 1.0, 2.0, 0.0, 5.0])
    assert lowest_mask(s, 0.4).tolist() == [False, True, False, True, False]
    assert lowest_mask(s, 0.0).sum() == 0
    assert lowest_mask(s, 0.99).sum() == 4  # at least one Gaussian stays
    assert lowest_mask(torch.zeros(4), 0.5).tolist() == [True, True, False, False]  # ties: lower index first


@pytest.mark.parametrize("degree", [0, 1, 2])
def test_sh_truncation_renders_like_the_full_model_at_that_degree(degree):
    m = _model(degree=3, seed=1)
    cam = _cams()[1]
    with torch.no_grad():
        full = m.render(cam.viewmat, cam.K, cam.width, cam.height, sh_degree=degree).image
        at3 = m.render(cam.viewmat, cam.K, cam.width, cam.height).image
    opt = make_optimizer(m, Config(), 1.0)
    for p in m.params.values():
        p.grad = torch.ones_like(p)
    opt.step()
    opt.zero_grad()
    m_ref = copy.deepcopy(m)
    truncate_sh(m, degree, opt)
    assert m.max_sh_degree == degree and m.params["shN"].shape == (len(m), (degree + 1) ** 2 - 1, 3)
    st = opt.state[m.params["shN"]]
    assert st["exp_avg"].shape == m.params["shN"].shape
    with torch.no_grad():
        m_ref_img = m_ref.render(cam.viewmat, cam.K, cam.width, cam.height, sh_degree=degree).image
        img = m.render(cam.viewmat, cam.K, cam.width, cam.height, sh_degree=3).image  # its own maximum
    assert float((img - m_ref_img).abs().max()) <= 1e-6
    assert float((at3 - full).abs().max()) > 1e-3  # the higher bands did matter, so the check means something


def test_ply_at_reduced_degree_reloads_and_renders_the_same(tmp_path):
    m = _model(n=40, degree=3, seed=2)
    truncate_sh(m, 1)
    path = m.save_ply(tmp_path / "c.ply")
    assert path.stat().st_size == ply_bytes(len(m), 1)
    header = path.read_bytes().split(b"end_header")[0].decode()
    assert header.count("f_rest_") == 9
    back = GaussianModel.load_ply(path)
    assert back.max_sh_degree == 1 and len(back) == 40
    for cam in _cams():
        with torch.no_grad():
            a = m.render(cam.viewmat, cam.K, cam.width, cam.height, sh_degree=1).image
            b = back.render(cam.viewmat, cam.K, cam.width, cam.height).image
        assert float((a - b).abs().max()) <= 1e-5


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_byte_counts_match_the_parameter_arrays(degree, tmp_path):
    m = _model(n=17, degree=degree)
    numel = sum(p.numel() for p in m.params.values())
    assert param_bytes(len(m), degree) == 4 * numel
    rep = size_report(m)
    assert rep == {"num_gaussians": 17, "sh_degree": degree, "param_bytes": 4 * numel,
                   "ply_bytes": m.save_ply(tmp_path / "m.ply").stat().st_size}
    assert param_bytes(1, 3) == 236 and param_bytes(1, 0) == 56


def test_virtual_cameras_lie_between_the_inputs():
    cams = [SimpleNamespace(viewmat=torch.tensor(np.linalg.inv(c), dtype=torch.float32), K=torch.eye(3), width=8, height=6)
            for c in camera_ring([0, 40, 80])]
    v = virtual_cameras(cams, 3)
    assert len(v) == 2 * 3
    centres = [torch.linalg.inv(c.viewmat)[:3, 3] for c in v]
    ends = [torch.linalg.inv(c.viewmat)[:3, 3] for c in cams]
    angles = [math.degrees(math.atan2(float(c[0]), -float(c[2]))) for c in centres]
    assert all(0 < a < 80 for a in angles) and all(float(min((c - e).norm() for e in ends)) > 0.1 for c in centres)


# ----------------------------------------------------------------------------------------------
# with the trainer


def _cfg(iterations=120):
    cfg = tiny_config(iterations, sh_degree_interval=30)
    cfg.strategy.refine_stop_iter, cfg.strategy.reset_every = 100, 1000
    c = cfg.compact
    c.prune_at = []
    c.ratios = [0.2, 0.4, 0.6, 0.8]
    c.finetune_steps = 15
    return cfg


@pytest.fixture(scope="module")
def scene():
    return make_scene()


@pytest.fixture(scope="module")
def trained(scene):
    tr = Trainer(_cfg(), scene, None, log=lambda m: None)
    tr.train()
    return tr


def _state(tr):
    return {k: v.detach().clone() for k, v in tr.model.params.items()}


def test_search_respects_the_tolerance_on_the_training_views(trained):
    tr = copy.deepcopy(trained)
    cfg = copy.deepcopy(tr.cfg.compact)
    cfg.tolerance_db = 0.1
    n0 = len(tr.model)
    rep = search(tr.context, cfg)
    pts = rep["points"]
    best = max(p["train_psnr"] for p in pts)
    assert rep["best_train_psnr"] == best and rep["judged_on"] == "train views"
    assert pts[0]["ratio"] == 0.0 and pts[0]["num_gaussians"] == n0  # the unpruned reference, fine-tuned alike
    final = pts[rep["chosen"]]
    assert final["train_psnr"] >= best - cfg.tolerance_db
    for p in pts:
        assert p["within_tolerance"] == (p["train_psnr"] >= best - cfg.tolerance_db)
        if p["within_tolerance"]:  # nothing evaluated within tolerance is smaller (or as small and lighter)
            assert (p["num_gaussians"], p["param_bytes"]) >= (final["num_gaussians"], final["param_bytes"])
    # the trainer holds the chosen model: its size and its training-view PSNR are the reported ones
    assert len(tr.model) == final["num_gaussians"] and tr.model.max_sh_degree == final["sh_degree"]
    again = tr.evaluate(tr.train_cams, lpips=False)["mean"]["psnr"]
    assert abs(again - final["train_psnr"]) < 1e-9
    assert rep["after"]["num_gaussians"] == len(tr.model) and rep["before"]["num_gaussians"] == n0
    assert rep["after"]["param_bytes"] == param_bytes(len(tr.model), tr.model.max_sh_degree)
    # a prune point of ratio r keeps round((1 - r) n0)
    for p in pts:
        if p["kind"] == "prune":
            assert p["num_gaussians"] == n0 - int(round(p["ratio"] * n0))
    # the optimiser follows the kept model, so training can go on
    assert all(g["params"][0] is tr.model.params[g["name"]] for g in tr.optimizer.param_groups)
    # a tolerance of 0 keeps only the best point
    tr0 = copy.deepcopy(trained)
    cfg0 = copy.deepcopy(cfg)
    cfg0.tolerance_db, cfg0.sh_search = 0.0, False
    rep0 = search(tr0.context, cfg0)
    assert rep0["points"][rep0["chosen"]]["train_psnr"] == max(p["train_psnr"] for p in rep0["points"])


def test_the_fine_tune_trains_with_the_runs_regularisers_at_the_steps_it_stands_in_for(scene, monkeypatch):
    """The search's fine-tune is the run's training without densification: every step draws DropGaussian's mask
    and adds the binocular term as the trainer would at the steps it replaces (ctx.step on), and applies the
    opacity decay after each update. Each candidate sees the same draws (two fine-tunes from one state end equal),
    and the binocular term's own generator is the run's again afterwards, its state untouched. Without the
    regularisers (the earlier fine-tune) a 3-view capture's fine-tune overfits its inputs."""
    from warpgs.strategy.compact import finetune

    cfg = _cfg(60)
    cfg.regularizers.dropout.rate = 0.2
    cfg.regularizers.binocular.weight, cfg.regularizers.binocular.start = 1.0, 0.0
    cfg.regularizers.opacity_decay.rate = 0.01
    tr = Trainer(cfg, scene, None, log=lambda m: None)
    tr.train(40)
    ctx, regs = tr.context, tr.regularizers
    binocular, decay = regs.get("binocular"), regs.get("opacity_decay")
    assert binocular is not None and decay is not None
    scales, terms, decays = [], [], []
    real_scale, real_term, real_decay = type(ctx).opacity_scale, type(binocular).step_term, type(decay).after_update
    monkeypatch.setattr(type(ctx), "opacity_scale",
                        lambda self, step, model=None, generator=None: (scales.append(step),
                                                                        real_scale(self, step, model, generator))[1])
    monkeypatch.setattr(type(binocular), "step_term",
                        lambda self, c, step, *a: (terms.append(step), real_term(self, c, step, *a))[1])
    monkeypatch.setattr(type(decay), "after_update", lambda self, c, step: (decays.append(step),
                                                                            real_decay(self, c, step))[1])
    gen, state = binocular.gen, binocular.gen.get_state()
    start, before = ctx.state_dict(("model",)), _state(tr)
    assert finetune(ctx, 6, seed=3) == 0
    first = _state(tr)
    assert scales == terms == decays == list(range(40, 46))
    assert binocular.gen is gen and torch.equal(binocular.gen.get_state(), state)
    ctx.load_state_dict(start)
    finetune(ctx, 6, seed=3)
    assert all(torch.equal(first[k], v) for k, v in _state(tr).items())
    assert not all(torch.equal(first[k], before[k]) for k in first)  # it trained


def test_search_never_looks_at_the_test_views(trained):
    cfg = copy.deepcopy(trained.cfg.compact)
    cfg.ratios, cfg.sh_search = [0.3, 0.6], False
    a = copy.deepcopy(trained)
    ra = search(a.context, cfg)
    b = copy.deepcopy(trained)
    for cam in b.test_cams:  # other test images, and no test PSNR recorded
        cam.image = torch.rand_like(cam.image)
    cfg_b = copy.deepcopy(cfg)
    cfg_b.report_test = False
    rb = search(b.context, cfg_b)
    assert ra["chosen"] == rb["chosen"]
    assert [p["train_psnr"] for p in ra["points"]] == [p["train_psnr"] for p in rb["points"]]
    assert all(torch.equal(a.model.params[k], b.model.params[k]) for k in a.model.params)
    assert "test_psnr" in ra["points"][0] and "test_psnr" not in rb["points"][0]


def test_pruning_during_training_follows_the_schedule(scene):
    cfg = _cfg(iterations=40)
    cfg.strategy.refine_start_iter = 1000  # no densification: the count changes only by the schedule
    cfg.compact.enabled = True
    cfg.compact.prune_at, cfg.compact.prune_ratio = [0.5], 0.25
    cfg.compact.ratios, cfg.compact.sh_search = [], False
    tr = Trainer(cfg, scene, None, log=lambda m: None)
    attach(tr)
    assert isinstance(tr.strategy, ScheduledPruning) and tr.strategy.prune_steps == [20]
    assert tr.strategy.max_gaussians == 800  # the wrapped strategy's fields show through
    n0 = len(tr.model)
    tr.train(20)
    assert len(tr.model) == n0 - int(round(0.25 * n0))
    assert tr.strategy.log == [{"step": 20, "before": n0, "after": len(tr.model)}]
    assert all(v.shape[0] == len(tr.model) for v in tr.state.values())
    tr.train()
    m = tr.finish()
    assert m["num_gaussians"] == n0 - int(round(0.25 * n0))
    assert m["param_bytes"] == param_bytes(len(tr.model), tr.model.max_sh_degree) and "compact" in m


def test_cap_after_pruning_keeps_densification_from_growing_back(scene):
    cfg = _cfg(iterations=40)
    s = cfg.strategy
    s.refine_start_iter, s.refine_every, s.grow_grad2d, s.max_gaussians = 4, 4, 1e-9, 0  # grows at every refinement
    cfg.compact.enabled = True
    cfg.compact.prune_at, cfg.compact.prune_ratio = [0.5], 0.4
    cfg.compact.cap_after_prune = True
    cfg.compact.ratios, cfg.compact.sh_search = [], False
    tr = Trainer(cfg, scene, None, log=lambda m: None)
    attach(tr)
    tr.train(19)
    assert len(tr.model) > 300  # it grew
    tr.train(20)
    cap = tr.strategy.log[0]["after"]
    assert len(tr.model) == cap and tr.strategy.max_gaussians == cap
    for step in range(24, 41, 4):  # refinements go on (within the cap)
        tr.train(step)
        assert len(tr.model) <= cap
    assert cfg.strategy.max_gaussians == 0 and tr.cfg.strategy.max_gaussians == 0  # the run's config is untouched


def test_config_checks():
    with pytest.raises(ValueError, match="importance_views"):
        check_config(CompactConfig(importance_views=["test"]))
    with pytest.raises(ValueError, match="ratios"):
        check_config(CompactConfig(ratios=[0.5, 1.0]))
    with pytest.raises(ValueError, match="importance"):
        check_config(CompactConfig(importance="volume"))


def test_cli_flag_and_bench(tmp_path, capsys):
    from warpgs.pipelines.sparse import build_parser, make_config, main

    cfg, _ = make_config(build_parser().parse_args(["--method", "baseline", "--compact"]))
    assert cfg.compact.enabled and cfg.compact.tolerance_db == 0.1
    cfg, _ = make_config(build_parser().parse_args(["--method", "full", "--compact", "--set", "compact.finetune_steps=7"]))
    assert cfg.compact.enabled and cfg.compact.finetune_steps == 7 and cfg.method == "full"
    assert not make_config(build_parser().parse_args(["--method", "baseline"]))[0].compact.enabled

    data = write_nerfstudio(tmp_path / "scene")
    sets = ["model.init=box", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]", "model.init_num=200",
            f"eval.lpips_weights={tmp_path / 'none.pth'}", "eval.fps_repeats=1", "train.sh_degree_interval=10"]
    small = ["compact.finetune_steps=3", "compact.ratios=[0.3,0.6]",
             "compact.prune_at=[0.5]"]
    out = tmp_path / "out"
    argv = ["--data", str(data), "--views", "3", "--device", "cpu", "--no-progress", "--method", "baseline",
            "--iterations", "24", "--compact", "--out", str(out)]
    for s in sets + small:
        argv += ["--set", s]
    assert main(argv) == 0
    m = json.loads((out / "metrics.json").read_text())
    c = m["compact"]
    assert m["num_gaussians"] == c["after"]["num_gaussians"] and m["sh_degree"] == c["after"]["sh_degree"]
    assert (out / "point_cloud.ply").stat().st_size == m["ply_bytes"]
    # the search's fine-tunes are the run's last 3 steps: 21 trained steps, pruned at half of them, 24 in all
    assert c["trained_steps_before_search"] == 21 and m["iterations"] == 24
    assert c["pruned_during_training"][0]["step"] == round(0.5 * 21) and c["judged_on"] == "train views"
    assert all(p["finetune_steps"] == 3 for p in c["points"])
    capsys.readouterr()

    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("bench_compact", Path(__file__).resolve().parents[1] / "bench" / "quality" / "compact.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    res = bench.run_compact(str(data), "cpu", 24, tmp_path / "bench", views=3, overrides=sets,
                            compact_overrides=small)
    for f in ("compact.json", "compact.png", "compact.md"):
        assert (tmp_path / "bench" / f).is_file()
    saved = json.loads((tmp_path / "bench" / "compact.json").read_text())
    assert saved["compact"]["num_gaussians"] == res["compact"]["num_gaussians"] and saved["points"]
    assert (saved["views"], saved["seed"]) == (3, 0)  # the chart names the pair by them (castle_p30_3v_..._s0)
    assert saved["count_reduction"] == pytest.approx(1 - res["compact"]["num_gaussians"] / res["default"]["num_gaussians"])


def test_full_method_compact(tmp_path):
    """--method full --compact: pruning and the search run inside the generation-guided loop; the pseudo
    views count towards importance; the iterations add up."""
    from warpgs.pipelines.sparse import main

    out = tmp_path / "full"
    args = ["--method", "full", "--iterations", "30", "--out", str(out), "--device", "cpu", "--no-progress", "--compact",
            "--set", "pseudo.trajectory.n_frames=4", "--set", "pseudo.sampler.steps=3", "--set", "full.flythrough_frames=2",
            "--set", "eval.fps_repeats=1", "--set", f"eval.lpips_weights={tmp_path / 'none.pth'}",
            "--set", "compact.finetune_steps=4", "--set", "compact.ratios=[0.5]", "--set", "compact.prune_at=[0.9]"]
    assert main(args) == 0
    m = json.loads((out / "metrics.json").read_text())
    c = m["compact"]
    assert m["method"] == "full" and m["iterations"] == 30 and c["trained_steps_before_search"] == 26
    assert [r["step"] for r in c["pruned_during_training"]] == [round(0.9 * 26)]
    assert c["num_importance_views"] > m["train_views"]  # the pseudo views too
    assert m["num_gaussians"] == c["after"]["num_gaussians"] and (out / "point_cloud.ply").stat().st_size == m["ply_bytes"]
    assert [p["ratio"] for p in c["points"] if p["kind"] == "prune"] == [0.0, 0.5]
