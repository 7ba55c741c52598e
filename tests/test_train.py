"""Trainer: learning, determinism, checkpoints / resume, Ctrl-C, NaN guard, configs, the CLI."""

import json
import signal

import numpy as np
import pytest
import torch

from tiny_scene import make_scene, param_copy, same_params, tiny_config, write_nerfstudio
from warpgs.config import CONFIG_DIR, Config, ConfigError, load_config, parse_override, read_yaml
from warpgs.model import GaussianModel
from warpgs.train import CHECKPOINT, Trainer, TrainingDiverged, TrainingInterrupted


def _cfg(iterations=300, tmp_path=None, **train) -> Config:
    return tiny_config(iterations, str(tmp_path / "no-lpips-weights.pth") if tmp_path else "/nonexistent/alexnet.pth",
                       **train)


@pytest.fixture(scope="module")
def scene():
    return make_scene()


def test_training_lowers_loss_and_raises_test_psnr(scene, tmp_path):
    out = tmp_path / "run"
    tr = Trainer(_cfg(tmp_path=tmp_path), scene, out)
    n0 = len(tr.model)
    tr.train()
    m = tr.finish()
    first, last = np.mean(tr.losses[:20]), np.mean(tr.losses[-20:])
    assert last < 0.5 * first
    assert m["psnr"] > m["initial_psnr"] + 6.0, m
    assert m["train_psnr"] > m["psnr"] - 1.0
    assert m["iterations"] == 300 and m["num_gaussians"] == len(tr.model) != n0
    assert m["lpips"] is None and "no-lpips-weights.pth" in m["lpips_missing"]
    # what the output folder holds
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["psnr"] == m["psnr"] and len(saved["per_view"]) == len(scene.test)
    assert sorted(p.name for p in (out / "test").iterdir()) == ["000_test00.png", "001_test01.png"]
    from PIL import Image

    assert Image.open(out / "test" / "000_test00.png").size == (2 * 48, 48)  # render | ground truth
    assert (out / CHECKPOINT).is_file() and (out / "config.yaml").is_file()
    ply = GaussianModel.load_ply(out / "point_cloud.ply")
    cam = tr.test_cams[0]
    with torch.no_grad():
        a = tr.render(cam).image
        b = ply.render(cam.viewmat, cam.K, cam.width, cam.height, background=tr.background).image
    assert float((a - b).abs().max()) <= 1e-5


def test_embedded_synthetic_scene_three_views():
    """The default scene (a ray-traced room, 3 views at 128x96): a short CPU run lowers the loss and
    lifts the test views' PSNR well above the initial render's."""
    from warpgs.data import load_scene

    scene = load_scene("synthetic", views=3, downscale=2)
    cfg = load_config([CONFIG_DIR / "methods" / "baseline.yaml", CONFIG_DIR / "datasets" / "synthetic.yaml"],
                      ["train.iterations=200", "model.init_num=1500", "strategy.refine_start_iter=100",
                       "strategy.max_gaussians=3000", "train.device=cpu", "train.progress=false"])
    tr = Trainer(cfg, scene)
    tr.train()
    after = tr.evaluate(lpips=False)["mean"]["psnr"]
    assert np.mean(tr.losses[-20:]) < 0.85 * np.mean(tr.losses[:20])
    assert after > tr.initial["psnr"] + 1.5, (tr.initial["psnr"], after)


def test_same_seed_same_numbers(scene):
    runs = []
    for seed in (0, 0, 1):
        tr = Trainer(_cfg(80, seed=seed), scene)
        tr.train()
        runs.append((param_copy(tr), tr.losses, tr.evaluate(lpips=False)["mean"]))
    assert len(runs[0][0]["means"]) != 300  # densification ran (clone and split noise included)
    assert same_params(runs[0][0], runs[1][0]) and runs[0][1] == runs[1][1] and runs[0][2] == runs[1][2]
    assert not same_params(runs[0][0], runs[2][0])


def test_resume_continues_exactly(scene, tmp_path):
    straight = Trainer(_cfg(130), scene)
    straight.train()
    first = Trainer(_cfg(130), scene, tmp_path)
    first.train(70)  # past two refinements; the opacity reset at 120 and more refinements come after
    first.save_checkpoint()
    second = Trainer(_cfg(130), scene, tmp_path)
    second.load_checkpoint()
    assert second.step == 70 and len(second.model) == len(first.model)
    second.train()
    assert same_params(param_copy(straight), param_copy(second))
    assert straight.losses == second.losses


def test_ctrl_c_saves_a_checkpoint_then_resume(scene, tmp_path, monkeypatch):
    tr = Trainer(_cfg(60), scene, tmp_path)
    real_step = tr.train_step

    def step_with_ctrl_c():
        if tr.step == 25:
            signal.raise_signal(signal.SIGINT)  # as if the user pressed Ctrl-C during this step
        return real_step()

    monkeypatch.setattr(tr, "train_step", step_with_ctrl_c)
    before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the suite runs in a background job
    with pytest.raises(TrainingInterrupted) as e:
        tr.train()
    assert e.value.step == 26 and e.value.checkpoint == tmp_path / CHECKPOINT
    assert torch.load(tmp_path / CHECKPOINT, weights_only=False)["step"] == 26
    assert signal.getsignal(signal.SIGINT) is before  # the previous handler is restored
    assert not list(tmp_path.glob("*.tmp*"))  # the atomic write left no temporary file
    resumed = Trainer(_cfg(60), scene, tmp_path)
    resumed.load_checkpoint()
    resumed.train()
    straight = Trainer(_cfg(60), scene)
    straight.train()
    assert same_params(param_copy(straight), param_copy(resumed))
    # a checkpoint of the middle of a phase: the resumed run judges its steps against the same statistic
    # (and metrics.json's max_loss_ratio is the uninterrupted run's)
    assert resumed.guard.stat_start == straight.guard.stat_start
    assert resumed.guard.max_loss_ratio == straight.guard.max_loss_ratio


def test_nan_guard_skips_bad_steps_and_gives_up(scene, tmp_path, monkeypatch):
    tr = Trainer(_cfg(20, max_nan_steps=3), scene, tmp_path)
    real = tr.compute_loss

    def loss_nan_at_step_5(out, cam):
        loss, parts = real(out, cam)
        return (loss * float("nan"), parts) if tr.step == 5 else (loss, parts)

    monkeypatch.setattr(tr, "compute_loss", loss_nan_at_step_5)
    tr.train(5)
    before = param_copy(tr)
    tr.train(6)  # the NaN step changes nothing
    assert same_params(before, param_copy(tr)) and np.isnan(tr.losses[5])
    tr.train()
    assert all(np.isfinite(tr.losses[6:])) and all(bool(torch.isfinite(p).all()) for p in tr.model.params.values())
    monkeypatch.setattr(tr, "compute_loss", lambda out, cam: (out.image.sum() * float("nan"), {}))
    tr.save_checkpoint()
    with pytest.raises(TrainingDiverged, match="3 consecutive steps"):
        tr.train(40)


def test_depth_term_uses_the_prior(scene):
    cfg = _cfg(1)
    cfg.loss.depth_weight = 1.0
    tr = Trainer(cfg, scene)
    cam = tr.train_cams[0]
    out = tr.render(cam)
    loss0, parts0 = tr.compute_loss(out, cam)
    assert "depth" not in parts0  # the tiny scene's views carry no depth
    cam.depth = out.depth.detach() * 2 + 1  # a prior perfectly correlated with the render
    loss1, parts1 = tr.compute_loss(out, cam)
    assert abs(float(parts1["depth"])) < 1e-5 and abs(float(loss1 - loss0)) < 1e-5
    cam.depth = None


# ----------------------------------------------------------------------------------------------
# configs


def test_config_layers_and_errors(tmp_path):
    base = tmp_path / "base.yaml"
    base.write_text("train:\n  iterations: 123\n  seed: 4\nstrategy:\n  grow_grad2d: 0.001\n")
    child = tmp_path / "child.yaml"
    child.write_text("base: base.yaml\ntrain:\n  seed: 5\nmodel:\n  init_box: [-1, -1, -1, 1, 1, 1]\n")
    cfg = load_config([child], ["train.iterations=7", "strategy.max_gaussians=1000", "optim.means_lr=1e-3",
                                "data.views=all", "eval.lpips_weights=null"])
    assert (cfg.train.iterations, cfg.train.seed) == (7, 5)
    assert cfg.strategy.grow_grad2d == 0.001 and cfg.strategy.max_gaussians == 1000
    assert cfg.strategy.prune_opa == 0.005  # untouched defaults stay
    assert cfg.optim.means_lr == 1e-3 and isinstance(cfg.optim.means_lr, float)
    assert cfg.model.init_box == [-1, -1, -1, 1, 1, 1] and cfg.data.views == "all"
    with pytest.raises(ConfigError, match="unknown key 'iteratons'.*iterations"):
        load_config([], ["train.iteratons=5"])
    with pytest.raises(ConfigError, match="not a valid"):
        load_config([], ["train.iterations=lots"])
    with pytest.raises(ConfigError, match="key=value"):
        parse_override("train.iterations")
    loop = tmp_path / "loop.yaml"
    loop.write_text("base: loop.yaml\n")
    with pytest.raises(ConfigError, match="loops"):
        read_yaml(loop)


@pytest.mark.parametrize("name", ["synthetic", "blender", "llff", "dtu", "nerfstudio", "dl3dv", "colmap"])
def test_repository_configs_load(name):
    cfg = load_config([CONFIG_DIR / "methods" / "baseline.yaml", CONFIG_DIR / "datasets" / f"{name}.yaml"])
    assert cfg.method == "baseline" and cfg.train.iterations > 0
    if name == "blender":
        assert cfg.model.init == "hull" and len(cfg.model.init_box) == 6 and 7000 <= cfg.train.iterations <= 10000


# ----------------------------------------------------------------------------------------------
# the command line


def test_cli_runs_resumes_and_writes_outputs(tmp_path, capsys):
    from warpgs.pipelines.sparse import main

    data = write_nerfstudio(tmp_path / "scene")
    out = tmp_path / "out"
    common = ["--data", str(data), "--views", "3", "--device", "cpu", "--no-progress", "--method", "baseline",
              "--set", "model.init=box", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]",
              "--set", "model.init_num=200", "--set", f"eval.lpips_weights={tmp_path / 'none.pth'}",
              "--set", "eval.fps_repeats=1"]
    assert main(common + ["--iterations", "20", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["iterations"] == 20 and m["train_views"] == 3 and m["test_views"] == 2
    assert m["lpips"] is None and m["psnr"] > 0
    for f in ("config.yaml", CHECKPOINT, "point_cloud.ply"):
        assert (out / f).is_file(), f
    assert len(list((out / "test").glob("*.png"))) == 2
    assert "PSNR" in capsys.readouterr().out
    # --resume takes the saved config; a larger --iterations continues the run
    assert main(["--resume", str(out), "--iterations", "30", "--no-progress"]) == 0
    assert json.loads((out / "metrics.json").read_text())["iterations"] == 30
    assert load_config([out / "config.yaml"]).model.init_num == 200
    # errors are reported, not raised
    assert main(["--resume", str(tmp_path / "nothing")]) == 2
    assert main(["--method", "nonsense"]) == 2
    assert "available methods" in capsys.readouterr().err


def test_run_folder_holds_the_whole_resolved_config_and_resume_keeps_it(tmp_path, monkeypatch):
    """config.yaml is the complete config tree (every dataclass field, the pseudo-view and densification
    sections too), a default changed in a dataclass shows up there with no YAML touched, and --resume
    reads the same config back (from the checkpoint) and writes it unchanged."""
    import dataclasses

    import yaml

    from warpgs.config import Config, to_dict
    from warpgs.pipelines.sparse import build_parser, main, make_config
    from warpgs.pseudo.sampler import SamplerConfig

    defaults = list(SamplerConfig.__init__.__defaults__)
    names = [f.name for f in dataclasses.fields(SamplerConfig)]
    defaults[names.index("steps")] = 17  # the dataclass default, edited (no YAML sets it)
    monkeypatch.setattr(SamplerConfig.__init__, "__defaults__", tuple(defaults))
    data = write_nerfstudio(tmp_path / "scene")
    out = tmp_path / "out"
    argv = ["--data", str(data), "--views", "3", "--device", "cpu", "--no-progress", "--method", "baseline",
            "--set", "model.init=box", "--set", "model.init_box=[-1,-1,-1,1,1,1]", "--set", "model.init_num=100",
            "--set", "eval.fps_repeats=1", "--set", "eval.save_images=false", "--set", "densify.filter.std_ratio=3.5",
            "--iterations", "6", "--out", str(out)]
    assert main(argv) == 0
    saved = yaml.safe_load((out / "config.yaml").read_text())
    expected, _ = make_config(build_parser().parse_args(argv))
    assert saved == to_dict(expected)
    assert saved["pseudo"]["sampler"]["steps"] == 17 and saved["densify"]["filter"]["std_ratio"] == 3.5
    # what the run derived from it is in metrics.json: nerfstudio's baseline stops growing at half the run (3 of 6)
    import json
    assert saved["strategy"]["refine_stop_iter"] == 15_000 and saved["strategy"]["refine_stop_fraction"] == 0.5
    assert json.loads((out / "metrics.json").read_text())["refine_stop_iter"] == 3

    def keys(d, prefix=""):
        return {prefix + k for k, v in d.items() if not isinstance(v, dict)} | {
            x for k, v in d.items() if isinstance(v, dict) and v for x in keys(v, prefix + k + ".")}

    assert keys(saved) == keys(to_dict(Config()))  # every field of the tree is written
    assert main(["--resume", str(out), "--iterations", "8", "--no-progress"]) == 0
    again = yaml.safe_load((out / "config.yaml").read_text())
    assert {k: v for k, v in again.items() if k != "train"} == {k: v for k, v in saved.items() if k != "train"}
    assert again["train"] == {**saved["train"], "iterations": 8}


def test_keys_of_earlier_versions_are_read_where_they_live_now():
    from warpgs.config import build_config

    cfg = build_config([{"full": {"n_frames": 5, "geometric": False, "pseudo": {"sampler": {"steps": 3}},
                                  "densify_config": {"stereo": {"min_score": 0.8}}, "cycles": 1}}])
    assert cfg.pseudo.trajectory.n_frames == 5 and cfg.pseudo.uncertainty.geometric is False
    assert cfg.pseudo.sampler.steps == 3 and cfg.densify.stereo.min_score == 0.8 and cfg.full.cycles == 1
    later = build_config([{"pseudo": {"trajectory": {"n_frames": 7}}}, {"full": {"n_frames": 4}}])
    assert later.pseudo.trajectory.n_frames == 4  # a later layer wins, whichever spelling it uses
    # "compact" meant three things; two of them have their own names now
    renamed = build_config([{"train": {"compact": True, "seed": 3},
                             "strategy": {"compact_when_full": False, "compact_min_weight": 0.5}}])
    assert renamed.train.prune_unseen_at_end is True and renamed.train.seed == 3
    assert renamed.strategy.prune_unseen_when_full is False and renamed.strategy.unseen_min_weight == 0.5


def test_alpha_loss_is_the_mean_absolute_alpha_error():
    """loss.alpha_weight adds weight x mean |rendered alpha - input alpha| for inputs with an alpha channel."""
    import dataclasses

    from warpgs.config import Config
    from warpgs.train import Trainer

    scene = make_scene()
    for c in scene.train:
        c.alpha = np.full((c.height, c.width), 0.5, np.float32)
    cfg = Config()
    cfg.train.device, cfg.model.init, cfg.model.init_num = "cpu", "box", 50
    cfg.model.init_box = [-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]
    cfg.loss.alpha_weight = 0.7
    tr = Trainer(cfg, scene)
    cam = tr.train_cams[0]
    out = tr.render(cam)
    loss, parts = tr.compute_loss(out, cam)
    expect = (out.alpha - 0.5).abs().mean()
    assert torch.allclose(parts["alpha"], expect)
    cfg0 = dataclasses.replace(cfg, loss=dataclasses.replace(cfg.loss, alpha_weight=0.0))
    tr.cfg = cfg0
    loss0, parts0 = tr.compute_loss(out, cam)
    assert "alpha" not in parts0 and torch.allclose(loss - loss0, 0.7 * expect)


def test_alpha_binary_adds_its_weight_times_mean_alpha_one_minus_alpha():
    """train.alpha_binary: the input loss gains w mean(alpha (1 - alpha)) of the render, recorded apart from
    ``inputs`` (the divergence guard's part), and nothing when it is 0."""
    scene = make_scene()
    off = Trainer(tiny_config(1), scene)
    on = Trainer(tiny_config(1, alpha_binary=0.5), scene)
    cam = on.train_cams[0]
    out = on.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=on.background)
    loss, parts = on.input_loss(out, cam)
    expected = (out.alpha.detach().double() * (1 - out.alpha.detach().double())).mean()
    assert 0 < float(expected) < 0.25  # a render with partly covered pixels
    assert abs(float(parts["alpha_binary"]) - float(expected)) < 1e-6
    assert abs(float(loss - parts["inputs"]) - 0.5 * float(expected)) < 1e-6
    base, parts0 = off.input_loss(out, cam)
    assert "alpha_binary" not in parts0 and torch.equal(base, parts0["inputs"])
    assert torch.equal(parts0["inputs"], parts["inputs"])
