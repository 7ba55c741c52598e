"""train.hold_geometry: the configuration it derives (exact factors, only when the points came from stereo in
``stereo`` mode) and what it does to training on the tiny ground-truth scene (no growth or pruning, the means
moving about as much less as their learning rate is smaller)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from tests.tiny_scene import make_scene, tiny_config
from warpgs.config import Config, build_config
from warpgs.train import Trainer, hold_geometry


def test_off_and_sfm_points_leave_the_config_alone():
    cfg = Config()
    assert hold_geometry(cfg, SimpleNamespace(method="stereo")) == (cfg, None)  # off by default
    cfg.train.hold_geometry = "stereo"
    for geo in (None, SimpleNamespace(method="sfm"), SimpleNamespace(method="sfm+stereo"), SimpleNamespace(method="none")):
        assert hold_geometry(cfg, geo) == (cfg, None)


@pytest.mark.parametrize("mode,method", [("stereo", "stereo"), ("on", "sfm"), ("on", None)])
def test_held_config_scales_the_geometry_rates_and_stops_the_strategy(mode, method):
    cfg = Config()
    cfg.train.hold_geometry = mode
    cfg.train.hold_means_lr, cfg.train.hold_scales_lr, cfg.train.hold_quats_lr = 0.1, 0.25, 0.5
    o = cfg.optim
    held, why = hold_geometry(cfg, None if method is None else SimpleNamespace(method=method))
    assert why is not None and why["mode"] == mode
    h = held.optim
    assert h.means_lr == pytest.approx(0.1 * o.means_lr) and h.means_lr_final == pytest.approx(0.1 * o.means_lr_final)
    assert h.scales_lr == pytest.approx(0.25 * o.scales_lr) and h.quats_lr == pytest.approx(0.5 * o.quats_lr)
    assert (h.opacities_lr, h.sh0_lr, h.shN_lr) == (o.opacities_lr, o.sh0_lr, o.shN_lr)  # colours train as before
    assert held.strategy.refine_stop_iter == 0 and cfg.strategy.refine_stop_iter == Config().strategy.refine_stop_iter
    assert held.strategy.prune_opa == cfg.strategy.prune_opa and held.train == cfg.train  # nothing else moves


def test_on_and_off_read_as_words_from_yaml_and_the_command_line():
    from warpgs.config import load_config

    assert load_config(overrides=["train.hold_geometry=on"]).train.hold_geometry == "on"  # YAML 1.1: True
    assert load_config(overrides=["train.hold_geometry=off"]).train.hold_geometry == "off"
    assert load_config([Path(__file__).resolve().parents[1] / "configs" / "datasets" / "dl3dv.yaml"]).train.hold_geometry == "stereo"  # the captures' default
    with pytest.raises(ValueError, match="far_field"):  # a boolean where on / off mean nothing stays an error
        load_config(overrides=["train.far_field=on"])


def test_a_bad_mode_is_named():
    with pytest.raises(ValueError, match="hold_geometry"):
        build_config([("--set train.hold_geometry=always", {"train": {"hold_geometry": "always"}})])
    cfg = Config()
    cfg.train.hold_geometry = "always"  # built in code, past the config's checks
    with pytest.raises(ValueError, match="off, on or stereo"):
        hold_geometry(cfg, None)


def _train(hold: str, steps: int = 60):
    cfg = tiny_config(steps, hold_geometry=hold)
    t = Trainer(cfg, make_scene(), None, log=lambda m: None)
    start = t.model.params["means"].detach().clone()
    t.train()
    return t, start


def test_held_training_keeps_the_gaussians_and_moves_the_means_less():
    free, start_free = _train("off")
    held, start_held = _train("on")
    assert torch.equal(start_free, start_held)  # the same initial Gaussians
    assert len(free.model) != 300  # the tiny config grows and prunes from step 30 ...
    assert len(held.model) == 300 and held.held["mode"] == "on"  # ... and holding stops both
    # the free run's survivors are not row-aligned with the start: the means' movement is compared with a run
    # without densification, where rows stay put
    cfg = tiny_config(60)
    cfg.strategy.refine_stop_iter = 0
    t = Trainer(cfg, make_scene(), None, log=lambda m: None)
    s0 = t.model.params["means"].detach().clone()
    t.train()
    moved_nogrow = (t.model.params["means"].detach() - s0).norm(dim=1).median()
    moved_held = (held.model.params["means"].detach() - start_held).norm(dim=1).median()
    assert moved_nogrow > 0 and moved_held > 0
    assert moved_held < 0.3 * moved_nogrow  # Adam's steps scale with the learning rate (x 0.1 here)
    # the training views are still fitted: the colours and opacities learn at their full rates
    assert held.losses[-1] < 0.7 * held.losses[0]


def test_a_resumed_held_run_holds_once_and_keeps_its_growth_schedule(tmp_path):
    """The checkpoint (and config.yaml) hold the configuration as requested, not the one derived from it at run time
    (held learning rates, growth resolved against the run's length): resuming from it derives the same again. A
    saved held one would make a resumed held run scale its geometry's learning rates twice (x 0.01)."""
    from warpgs.config import config_from_dict
    from warpgs.train import read_checkpoint

    cfg = tiny_config(40, hold_geometry="on")
    cfg.strategy.refine_stop_fraction = 0.5
    t = Trainer(cfg, make_scene(), tmp_path, log=lambda m: None)
    assert t.cfg.optim.means_lr == pytest.approx(0.1 * cfg.optim.means_lr)
    path = t.save_checkpoint()
    saved = config_from_dict(read_checkpoint(path)["config"])
    assert saved.optim == cfg.optim and saved.strategy == cfg.strategy  # as requested
    again = Trainer(saved, make_scene(), tmp_path, log=lambda m: None)  # what --resume builds from the checkpoint
    assert again.cfg.optim == t.cfg.optim and again.cfg.strategy == t.cfg.strategy  # held once, not twice
    # without the hold: growth resolved against the resumed run's length, not frozen at the first run's
    free = tiny_config(40)
    free.strategy.refine_stop_fraction = 0.5
    t = Trainer(free, make_scene(), tmp_path / "free", log=lambda m: None)
    assert t.cfg.strategy.refine_stop_iter == 20
    longer = config_from_dict(read_checkpoint(t.save_checkpoint())["config"])
    longer.train.iterations = 100  # --resume --iterations 100
    assert Trainer(longer, make_scene(), tmp_path / "free", log=lambda m: None).cfg.strategy.refine_stop_iter == 50
