"""The generation-guided pipeline (warpgs/pipelines/full.py): the loop runs end to end on the embedded
synthetic scene, writes its outputs, resumes, and its switches reach the config."""

import json

import torch

from warpgs.config import FullConfig
from warpgs.pipelines.full import ABLATIONS, append_gaussians, phase_boundaries


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
    seqs = sorted((out / "cycle_1" / "pseudo").glob("seq_*"))
    assert len(seqs) == 2 and len(list(seqs[0].glob("uncertainty_*.png"))) == 5
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
    assert cfg.full.geometric is False and cfg.full.photometric is True and cfg.full.cycles == 3
    assert set(ABLATIONS) == {"render_guidance", "no_geometric", "no_photometric", "no_filter", "no_densify",
                              "l1_pseudo"}


def test_appended_gaussians_train_with_fresh_adam_state():
    from warpgs.config import build_config
    from warpgs.data import load_scene
    from warpgs.pipelines.full import GenerativeTrainer

    cfg = build_config([{"method": "full", "train": {"device": "cpu", "progress": False, "iterations": 2},
                         "model": {"init": "box", "init_num": 50, "init_box": [-1, -1, 2, 1, 1, 4]},
                         "full": {"pseudo_loss": "l1"}}])
    scene = load_scene("synthetic", views=3, downscale=2)
    tr = GenerativeTrainer(cfg, scene, None)
    tr.train(1)
    n0 = len(tr.model)
    added = append_gaussians(tr, torch.tensor([[0.0, 0.0, 3.0], [0.1, 0.0, 3.0]]), torch.tensor([[1.0, 0, 0], [0, 1.0, 0]]),
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
