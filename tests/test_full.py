"""The generation-guided pipeline (warpgs/pipelines/full.py): the loop runs end to end on the embedded
synthetic scene, writes its outputs, resumes, and its switches reach the config."""

import dataclasses
import json
import math
import os
from pathlib import Path

import pytest
import torch

from warpgs.config import FullConfig
from warpgs.methods.full import ABLATIONS, append_gaussians, check_settings, phase_boundaries


def test_phase_boundaries_split_the_iterations():
    assert phase_boundaries(1000, FullConfig(cycles=2, baseline_fraction=0.4)) == [400, 700, 1000]
    assert phase_boundaries(90, FullConfig(cycles=3, baseline_fraction=0.0)) == [0, 30, 60, 90]
    assert phase_boundaries(50, FullConfig(cycles=0)) == [50]


def test_full_method_end_to_end_and_resume(tmp_path, capsys):
    from warpgs.pipelines.sparse import main

    out = tmp_path / "full"
    args = ["--method", "full", "--iterations", "30", "--out", str(out), "--device", "cpu", "--no-progress",
            "--set", "full.n_frames=5", "--set", "full.pseudo={sampler: {steps: 4}}", "--set", "full.flythrough_frames=3",
            "--set", "eval.fps_repeats=1", "--set", f"eval.lpips_weights={tmp_path / 'none.pth'}"]
    assert main(args) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["method"] == "full" and m["iterations"] == 30
    assert [c["cycle"] for c in m["cycles"]] == [0, 1, 2]
    for c in m["cycles"][1:]:  # each cycle made pseudo views and densified from them, and timed both
        assert c["pseudo_views_s"] > 0 and c["densify_s"] > 0 and c["added"] >= 0 and c["psnr"] > 5
    # no LPIPS weights here: the fallback is said and recorded
    assert m["pseudo_loss"] == "l1" and "alexnet" in m["lpips_fallback_reason"].lower()
    for f in ("report.md", "flythrough.gif", "point_cloud.ply", "config.yaml", "charts/psnr_per_cycle.png",
              "charts/time_per_stage.png", "cycle_1/densified.ply"):
        assert (out / f).is_file(), f
    assert not list(out.glob("*.tmp"))  # the GIF and metrics.json are written through a rename
    seqs = sorted((out / "cycle_1" / "pseudo").glob("seq_*"))
    assert len(seqs) == 2 and len(list(seqs[0].glob("uncertainty_*.png"))) == 5
    # the viewer reads each cycle's trajectories and densified cloud from these files
    from warpgs.view import load_run

    cycles = load_run(out, cameras=False).cycles
    assert [c.index for c in cycles] == [1, 2] and all(len(c.trajectories) == 2 for c in cycles)
    assert all(t.shape == (5, 4, 4) for t in cycles[0].trajectories) and cycles[0].cloud["origin"] is not None
    # a resumed run with more iterations continues from the checkpoint (cycles already done are kept)
    assert main(["--resume", str(out), "--iterations", "40", "--no-progress"]) == 0
    m2 = json.loads((out / "metrics.json").read_text())
    assert m2["iterations"] == 40 and [c["cycle"] for c in m2["cycles"]][:3] == [0, 1, 2]


def test_ablation_switches_reach_the_config(tmp_path):
    from warpgs.pipelines.sparse import build_parser, make_config

    args = build_parser().parse_args(["--method", "full", "--ablation", "no_densify", "--ablation", "l1_pseudo",
                                      "--ablation", "render_guidance", "--ablation", "no_geometric", "--cycles", "3"])
    cfg, _ = make_config(args)
    assert cfg.full.densify is False and cfg.full.pseudo_loss == "l1" and cfg.full.guidance == "render"
    assert cfg.pseudo.uncertainty.geometric is False and cfg.pseudo.uncertainty.photometric is True
    assert cfg.full.cycles == 3
    assert set(ABLATIONS) == {"render_guidance", "no_geometric", "no_photometric", "no_filter", "no_densify",
                              "l1_pseudo"}


def test_appended_gaussians_train_with_fresh_adam_state():
    from warpgs.config import build_config
    from warpgs.data import load_scene
    from warpgs.methods.full import FullMethod
    from warpgs.train import Trainer

    cfg = build_config([{"method": "full", "train": {"device": "cpu", "progress": False, "iterations": 2},
                         "model": {"init": "box", "init_num": 50, "init_box": [-1, -1, 2, 1, 1, 4]},
                         "full": {"pseudo_loss": "l1"}}])
    scene = load_scene("synthetic", views=3, downscale=2)
    tr = Trainer(cfg, scene, None, method=FullMethod())
    tr.train(1)
    n0 = len(tr.model)
    added = append_gaussians(tr.context, torch.tensor([[0.0, 0.0, 3.0], [0.1, 0.0, 3.0]]), torch.tensor([[1.0, 0, 0], [0, 1.0, 0]]),
                             torch.full((2, 3), 0.05), 0.1)
    assert added == 2 and len(tr.model) == n0 + 2
    assert torch.allclose(tr.model.opacities[-2:], torch.full((2,), 0.1), atol=1e-6)
    assert torch.allclose(tr.model.scales[-2:], torch.full((2, 3), 0.05), atol=1e-6)
    for g in tr.optimizer.param_groups:  # moments line up with the grown parameters, zero for the new rows
        st = tr.optimizer.state[g["params"][0]]
        assert st["exp_avg"].shape == g["params"][0].shape
        assert float(st["exp_avg"][-2:].abs().max()) == 0.0
    tr.train(2)  # and training goes on
    assert tr.step == 2


def test_compare_in_two_processes_matches_compare_in_turn(tmp_path, capsys):
    """--jobs 2 trains the baseline in a second process: on the CPU (deterministic) its metrics are the
    ones a run in turn gives, and the side-by-side table and report use them."""
    from warpgs.pipelines.sparse import main

    common = ["--iterations", "12", "--device", "cpu", "--no-progress", "--set", "model.init_num=300",
              "--set", "full.n_frames=3", "--set", "full.pseudo={sampler: {steps: 2}}", "--set", "full.flythrough_frames=2",
              "--set", "eval.fps_repeats=1", "--set", "eval.save_images=false",
              "--set", f"eval.lpips_weights={tmp_path / 'none.pth'}"]
    assert main(common + ["--jobs", "2", "--out", str(tmp_path / "par")]) == 0
    assert main(common + ["--jobs", "1", "--out", str(tmp_path / "seq")]) == 0
    par = json.loads((tmp_path / "par" / "comparison.json").read_text())
    seq = json.loads((tmp_path / "seq" / "comparison.json").read_text())
    for method in ("baseline", "full"):
        for key in ("psnr", "ssim", "num_gaussians"):
            assert par[method][key] == seq[method][key], (method, key)
    assert (tmp_path / "par" / "baseline.log").read_text().strip()
    report = (tmp_path / "par" / "full" / "report.md").read_text()
    assert f"| baseline | {par['baseline']['psnr']:.2f} |" in report


def test_pseudo_view_masks_follow_the_uncertainty():
    """full.pseudo_mask: 'seen' keeps every pixel an input sees (U < 1), 'reliable' only where guidance was
    fused (U < delta), 'all' every pixel."""
    from warpgs.pseudo.views import PseudoSequence

    g = torch.Generator().manual_seed(0)
    n, h, w = 4, 5, 6
    u = torch.rand(n, h, w, generator=g)
    u[1, 0, 0], u[2, 1, 1] = 1.0, 0.5
    z = torch.zeros(n, h, w, 3)
    seq = PseudoSequence(start=0, end=1, viewmats=torch.eye(4).repeat(n, 1, 1), K=torch.eye(3), width=w, height=h,
                         frames=z, guidance=z, warped=z, uncertainty=u, renders=z, depths=u, sources=u, tau=u[:, 0, 0])
    u[1, 2, 2] = 7.0  # no input sees it
    seen, rel = seq.pseudo_cameras(), seq.pseudo_cameras(max_uncertainty=0.5)
    every = seq.pseudo_cameras(max_uncertainty=math.inf)
    assert all(c.mask is None for c in every) and len(every) == len(seen) and not seen[0].mask[2, 2]
    assert [c.name for c in seen] == ["pseudo_0_1_001", "pseudo_0_1_002"]
    for i, (a, b) in enumerate(zip(seen, rel), start=1):
        assert torch.equal(a.mask, u[i] < 1.0) and torch.equal(b.mask, u[i] < 0.5)
    assert not seen[0].mask[0, 0] and seen[1].mask[1, 1] and not rel[1].mask[1, 1]


def test_growth_budget_caps_the_cycles_and_bad_settings_are_named(tmp_path):
    from tiny_scene import small_full_trainer

    _, tr = small_full_trainer(tmp_path, "--set", "full.growth_budget=1.5")
    configured = tr.cfg.strategy.max_gaussians
    settled = min(tr.cfg.strategy.reset_every, tr.cfg.strategy.refine_stop_iter)
    assert tr.strategy.max_gaussians == configured > 300  # the baseline phase runs under the configured budget
    tr.method.history = [{"cycle": 0, "step": settled, "num_gaussians": 10 * configured}]
    tr.method.apply_growth_budget()
    assert tr.strategy.max_gaussians == configured  # the growth budget never raises the configured one
    tr.method.history = [{"cycle": 0, "step": settled, "num_gaussians": 200}]
    tr.method.apply_growth_budget()
    assert tr.strategy.max_gaussians == 300  # 1.5 x the 200 the model had when its first growth period ended
    tr.method.history = [{"cycle": 0, "step": settled - 1, "num_gaussians": 200}]
    tr.method.apply_growth_budget()
    assert tr.strategy.max_gaussians == configured  # growth not settled yet (a short baseline phase): no cap
    tr.method.history.append({"cycle": 1, "step": settled + 5, "num_gaussians": 250})
    tr.method.apply_growth_budget()
    assert tr.strategy.max_gaussians == 375  # the first record after the growth period is the reference
    tr.method.history = [{"cycle": 0, "step": settled, "num_gaussians": 100}]
    tr.method.apply_growth_budget()
    assert tr.strategy.max_gaussians == len(tr.model)  # never below what the model has
    assert tr.cfg.strategy.max_gaussians == configured  # the config itself is left as it was
    for bad, msg in (({"pseudo_mask": "every"}, "pseudo_mask"), ({"growth_budget": -1.0}, "growth_budget"),
                     ({"drop_rate": 1.0}, "drop_rate")):
        with pytest.raises(ValueError, match=msg):
            check_settings(FullConfig(**bad))


def test_early_input_depth_is_the_scene_depth_where_confident_and_trains_from_step_0():
    """full.early_depth: plane-sweep stereo between the inputs gives each a depth prior before the first step;
    where it is kept (confident) it matches the synthetic scene's ground-truth depth, and the first step's loss
    has the input depth term. A view with too few confident pixels gets no prior (depth_prior)."""
    from warpgs.config import build_config
    from warpgs.data import load_scene
    from warpgs.methods.full import FullMethod, depth_prior
    from warpgs.train import Trainer

    cfg = build_config([{"method": "full", "train": {"device": "cpu", "progress": False, "iterations": 2},
                         "model": {"init": "box", "init_num": 50, "init_box": [-1, -1, 2, 1, 1, 4]},
                         "full": {"pseudo_loss": "l1", "early_depth": True}}])
    scene = load_scene("synthetic", views=3, downscale=2)
    tr = Trainer(cfg, scene, None, method=FullMethod())
    tr.method.early_input_depths()
    assert set(tr.method.input_depths) == {c.name for c in tr.train_cams}
    for cam in tr.train_cams:
        prior = tr.method.input_depths[cam.name]
        kept = prior > 0
        assert int(kept.sum()) > 0.02 * kept.numel()
        rel = (prior[kept] - cam.depth[kept]).abs() / cam.depth[kept]
        assert float(rel.median()) < 0.03 and float((rel < 0.05).float().mean()) > 0.6
    cam = tr.train_cams[0]
    out = tr.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=tr.background)
    _, parts = tr.compute_loss(out, cam)
    assert "input_depth" in parts and float(parts["input_depth"].detach()) > 0
    mask = torch.zeros(4, 5, dtype=torch.bool)
    mask[0, :4] = True
    assert depth_prior(mask, torch.ones(4, 5), "cpu", min_pixels=4) is None
    mask[1, 0] = True
    p = depth_prior(mask, torch.full((4, 5), 2.0), "cpu", min_pixels=4)
    assert torch.equal(p > 0, mask) and float(p.max()) == 2.0


def test_cycle_iterations_follow_the_baseline_run(tmp_path):
    """``full.cycle_iterations`` (the paper's schedule): the baseline phase is the baseline's own run, step for step
    (the same model when the first pseudo views are made), and each cycle adds that many steps."""
    from tiny_scene import small_full_trainer

    assert phase_boundaries(1000, FullConfig(cycles=2, cycle_iterations=300)) == [1000, 1300, 1600]
    assert phase_boundaries(1000, FullConfig(cycles=0, cycle_iterations=300)) == [1000]
    _, base = small_full_trainer(tmp_path / "b", "--method", "baseline", "--iterations", "20")
    base.run()
    _, tr = small_full_trainer(tmp_path / "f", "--iterations", "20", "--set", "full.cycle_iterations=6")
    at_first_cycle = []
    update = tr.method.update_pseudo_views

    def snapshot(cycle):
        if cycle == 1:
            at_first_cycle.append((tr.step, {k: v.detach().clone() for k, v in tr.model.params.items()}))
        return update(cycle)

    tr.method.update_pseudo_views = snapshot
    tr.run()
    step, params = at_first_cycle[0]
    assert step == 20 and tr.step == 32
    assert params.keys() == base.model.params.keys()
    for k, v in params.items():
        assert torch.equal(v, base.model.params[k].detach()), k
    assert [h["step"] for h in tr.method.history] == [20, 26, 32]
    with pytest.raises(ValueError, match="cycle_iterations"):
        check_settings(FullConfig(cycle_iterations=-1))


def test_cycle_iterations_resume_past_train_iterations(tmp_path, monkeypatch):
    """Ctrl-C in the second cycle (step 28, past train.iterations = 20): the checkpoint holds that step, and the resumed
    run ends at 20 + 2 x 6 with the cycles' records and the model of the uninterrupted run."""
    import signal

    from tiny_scene import small_full_trainer
    from warpgs.train import TrainingInterrupted

    opts = ("--iterations", "20", "--set", "full.cycle_iterations=6")
    _, straight = small_full_trainer(tmp_path / "a", *opts)
    straight.run()
    _, tr = small_full_trainer(tmp_path / "b", *opts)
    real_step = tr.train_step

    def step_with_ctrl_c():
        if tr.step == 28:
            signal.raise_signal(signal.SIGINT)
        return real_step()

    monkeypatch.setattr(tr, "train_step", step_with_ctrl_c)
    with pytest.raises(TrainingInterrupted) as e:
        tr.run()
    assert e.value.step == 29
    _, again = small_full_trainer(tmp_path / "b", *opts)
    again.load_checkpoint()
    assert again.step == 29 and again.method.cycles_done == 1
    again.run()
    assert again.step == straight.step == 32
    assert [h["step"] for h in again.method.history] == [h["step"] for h in straight.method.history] == [20, 26, 32]
    assert [c.name for c in again.method.pseudo_cams] == [c.name for c in straight.method.pseudo_cams]
    for k, v in straight.model.params.items():
        assert torch.allclose(again.model.params[k].detach(), v.detach(), atol=1e-6), k


def test_a_step_from_a_recordings_copies_is_the_step_itself(tmp_path):
    """What a CUDA graph of a full-method step holds (``FullMethod.graph_inputs`` / ``graph_bind``): the pseudo view
    is picked once, before the step, from the host's generator; the loss computed from the recording's own copies
    of the step's tensors (pose, image, depth, mask, the input's depth prior) is the loss of the step itself, bit
    for bit, with its gradient; and the pick is the step's either way (a step that is not replayed uses it, so the
    pseudo views follow the same order with or without the graphs)."""
    from tiny_scene import small_full_trainer

    _, tr = small_full_trainer(tmp_path, "--set", "full.reliable_weight=3.0")
    tr.run()
    fm = tr.method
    with torch.no_grad():  # depth priors of the inputs and the pseudo views (the stereo's, in a run that densifies)
        fm.input_depths = {c.name: tr.render(c).depth * 1.3 + 0.1 for c in tr.train_cams}
        fm.pseudo_cams = [dataclasses.replace(c, depth=tr.render(c).depth * 0.9) for c in fm.pseudo_cams]
    assert fm.pseudo_cams and fm.graph_safe()
    cam = next(c for c in tr.train_cams if c.name in fm.input_depths)
    key, tensors, cams = fm.graph_inputs(cam)
    pick = fm._pick
    assert cams == [pick] and pick in fm.pseudo_cams
    assert {"prior", "pseudo_viewmat", "pseudo_K", "pseudo_image", "pseudo_depth", "reliable"} <= set(tensors)
    assert fm.graph_inputs(cam)[0] == key and fm._pick is pick  # asked again: the same pick, nothing drawn
    order = list(fm.pseudo_order)

    def step_loss():
        params = [p for p in tr.model.params.values()]
        for p in params:
            p.grad = None
        tr.drop_gen.manual_seed(7)  # the pseudo view's render draws its dropout mask
        out = tr.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=tr.background_for(cam))
        parts = {}
        loss = fm.loss_terms(out, cam, out.image.sum() * 0, parts)
        loss.backward()
        return loss.detach(), {k: float(v) for k, v in parts.items()}, [p.grad.clone() for p in params]

    fm.graph_bind({k: v.clone() for k, v in tensors.items()})
    bound = step_loss()
    assert fm._pick is pick  # a recording leaves the pick for the step
    fm.graph_bind(None)
    eager = step_loss()
    assert fm._pick is None and fm.pseudo_order == order  # the step used the pick it was given
    assert {"input_depth", "pseudo"} <= set(eager[1])
    assert torch.equal(bound[0], eager[0]) and bound[1] == eager[1]
    assert all(torch.equal(a, b) for a, b in zip(bound[2], eager[2]))
    # the bound step reads the copies (a replay's inputs), not the views it was recorded from
    for name in ("pseudo_image", "prior"):
        fm._pick = pick
        fm.graph_bind({k: (v.flip(-1) if k == name else v.clone()) for k, v in tensors.items()})  # (Pearson:
        # blind to an affine change of the prior)
        changed = step_loss()
        fm.graph_bind(None)
        assert not torch.equal(changed[0], eager[0]), name
        assert (changed[1]["pseudo" if name == "pseudo_image" else "input_depth"]
                != eager[1]["pseudo" if name == "pseudo_image" else "input_depth"]), name
    # a pseudo view without a depth (densification's stereo reached only some) is the same recording: it reads zeros,
    # for which the depth term adds exactly 0 to the loss and its gradients, as the step without the term
    assert fm.settings.depth_weight > 0
    fm._pick = bare = dataclasses.replace(pick, depth=None)
    key_bare, tensors_bare, _ = fm.graph_inputs(cam)
    assert key_bare == key and not tensors_bare["pseudo_depth"].any()
    fm.graph_bind({k: v.clone() for k, v in tensors_bare.items()})
    bound = step_loss()
    fm.graph_bind(None)
    fm._pick = bare
    eager = step_loss()
    assert torch.equal(bound[0], eager[0]) and bound[1] == eager[1]
    assert all(torch.equal(a, b) for a, b in zip(bound[2], eager[2]))
    fm._pick = dataclasses.replace(pick, depth=pick.depth.flip(-1))  # (the term counts where there is a depth; this
    with_depth = step_loss()  # one's agrees with the render but for its scale, which Pearson does not see)
    assert not torch.equal(with_depth[0], eager[0])
    # a pseudo view without a mask is another recording
    fm._pick = dataclasses.replace(pick, mask=None) if pick.mask is not None else dataclasses.replace(
        pick, mask=torch.ones(pick.height, pick.width, dtype=torch.bool))
    assert fm.graph_inputs(cam)[0] != key
    fm.graph_done()
    assert fm._pick is None


def test_the_video_model_loads_while_the_baseline_phase_trains(monkeypatch):
    """FullMethod.run starts prefetch_backend before the baseline phase's first step, with the pseudo views' settings
    and the trainer's device; run again with its cycles made (a resumed run at its end), or resumed in its last cycle
    past the step its pseudo views were made at, it starts nothing."""
    import warpgs.methods.full as full
    from warpgs.config import build_config
    from warpgs.data import load_scene
    from warpgs.train import Trainer

    cfg = build_config([{"method": "full", "train": {"device": "cpu", "progress": False, "iterations": 6},
                         "model": {"init": "box", "init_num": 50, "init_box": [-1, -1, 2, 1, 1, 4]},
                         "full": {"pseudo_loss": "l1", "cycles": 1, "baseline_fraction": 0.5},
                         "pseudo": {"backend": "default", "trajectory": {"n_frames": 3}, "sampler": {"steps": 1}}}])
    tr = Trainer(cfg, load_scene("synthetic", views=3, downscale=2), None, method=full.FullMethod())
    calls = []
    monkeypatch.setattr(full, "prefetch_backend", lambda pcfg, device: calls.append((repr(pcfg), device, tr.step)))
    tr.run()
    assert tr.step == 6 and calls == [(repr(tr.method.pseudo_config()), tr.device, 0)]
    tr.method.run()
    assert len(calls) == 1
    tr.method.cycles_done = 0  # in cycle 1 (steps 3-6) at step 6: its pseudo views were made at step 3

    def stop(until):
        raise KeyboardInterrupt

    monkeypatch.setattr(tr, "train", stop)
    with pytest.raises(KeyboardInterrupt):
        tr.method.run()
    assert len(calls) == 1


CASTLE = Path(os.environ.get("WARPGS_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data")) \
    / "castle_p30" / "images_4" / "0000.jpg"


@pytest.mark.skipif(not CASTLE.is_file(), reason="the shared scenes are not here (../shared/data)")
def test_the_flythrough_gif_holds_the_rendered_frames(tmp_path):
    """write_flythrough with a stand-in trainer whose renders pan over a photo (48 frames of 192x128, two segments of
    24): the GIF decodes to every frame at that size, all in one palette, each close to its render. The thresholds
    come from the measurement in shared_palette's docstring and this case: every frame >= 37 dB (the worst was 38.2
    dB at 512x341, 39.4 here), the mean at most 2 dB under Pillow's own palette a frame (1.0-1.5 dB under it
    measured; Floyd-Steinberg dithering would fall 2.5-3 dB under)."""
    import io
    from types import SimpleNamespace

    import numpy as np
    from PIL import Image

    from warpgs.engine.evaluation import shared_palette, write_flythrough
    from warpgs.viz import to_uint8

    photo = np.asarray(Image.open(CASTLE).convert("RGB").resize((288, 192), Image.LANCZOS))
    rendered = []

    def render(viewmat, K, width, height, background=None):  # pose i: the window at (2i, i)
        i = int(viewmat[0, 3])
        image = torch.from_numpy(photo[i:i + height, 2 * i:2 * i + width].copy()).float() / 255
        rendered.append(to_uint8(image))
        return SimpleNamespace(image=image)

    def trajectories(n):
        return [SimpleNamespace(viewmats=[np.diag([1.0, 1, 1, 1]) + np.eye(4, k=3) * (s * n + k) for k in range(n)])
                for s in range(2)]

    cam = SimpleNamespace(width=384, height=256, K=torch.tensor([[300.0, 0, 192], [0, 300, 128], [0, 0, 1]]))
    trainer = SimpleNamespace(train_cams=[cam] * 3, cameras=SimpleNamespace(trajectories=trajectories), device="cpu",
                              model=SimpleNamespace(render=render), background_for=lambda view, keep: None)
    path = write_flythrough(trainer, tmp_path / "flythrough.gif", frames_per_segment=24, max_width=192)

    def decoded(gif):
        im = Image.open(gif)
        out = []
        for i in range(im.n_frames):
            im.seek(i)
            out.append(np.asarray(im.convert("RGB")))
        return out

    def psnr(a, b):
        return 10 * math.log10(255.0**2 / float(np.mean((a.astype(np.float64) - b) ** 2)))

    frames = decoded(path)
    assert len(rendered) == len(frames) == 48 and all(f.shape == (128, 192, 3) for f in frames)
    ours = [psnr(f, r) for f, r in zip(frames, rendered)]
    pillow = io.BytesIO()
    rgb = [Image.fromarray(r) for r in rendered]
    rgb[0].save(pillow, format="GIF", save_all=True, append_images=rgb[1:], duration=80, loop=0)
    theirs = [psnr(f, r) for f, r in zip(decoded(pillow), rendered)]
    assert min(ours) >= 37.0 and np.mean(ours) >= np.mean(theirs) - 2.0, (min(ours), np.mean(ours), np.mean(theirs))
    assert len({bytes(im.getpalette()) for im in shared_palette(rendered)}) == 1
