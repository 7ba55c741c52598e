"""A checkpoint written by the engine before it was split into ``warpgs.engine`` (commit e26aeea, the single
``warpgs/train.py``) still resumes, and the resumed run is the run of today's code without a stop.

``fixtures/checkpoint_e26aeea.pt`` was written by that commit's ``Trainer`` on ``tiny_scene.make_scene()`` with
the config of ``_cfg()`` (60 steps, 60 Gaussians, the binocular term, the path consistency, DropGaussian and the
opacity noise on, so every random stream of the ``progress`` part is in it) after ``train(40)`` and
``save_checkpoint()``."""

from pathlib import Path

import pytest
import torch

from tiny_scene import make_scene, param_copy, same_params, tiny_config
from warpgs.engine import Trainer, read_checkpoint

FIXTURE = Path(__file__).parent / "fixtures" / "checkpoint_e26aeea.pt"


def _cfg():
    cfg = tiny_config(60, binocular=0.5, binocular_start=0.2, path_consistency=0.5, path_consistency_start=0.3,
                      drop_rate=0.2, opacity_noise=0.3, checkpoint_every=0)
    cfg.model.init_num = 60
    cfg.strategy.max_gaussians = 120
    return cfg


def test_the_old_layout_holds_what_the_state_reads():
    ck = read_checkpoint(FIXTURE)
    assert ck["format"] == 2 and ck["step"] == 40 and ck["method_name"] == "baseline"
    # the regularisers' streams are top-level keys of the progress part, as the single trainer wrote them
    assert {"binocular_gen", "path_consistency_rng", "drop_gen", "split_gen", "view_rng"} <= set(ck)


def test_a_checkpoint_of_the_old_engine_resumes_to_the_uninterrupted_run(tmp_path):
    scene = make_scene()
    resumed = Trainer(_cfg(), scene, tmp_path)
    assert resumed.load_checkpoint(FIXTURE) == FIXTURE
    assert resumed.step == 40 and len(resumed.losses) == 40
    resumed.train()
    straight = Trainer(_cfg(), scene)
    straight.train(40)
    # the state at the stop is the old engine's, bit for bit
    old = torch.load(FIXTURE, weights_only=False)
    assert all(torch.equal(old["params"][k], v.detach().cpu()) for k, v in straight.model.params.items())
    straight.train()
    assert resumed.step == straight.step == 60
    assert same_params(param_copy(straight), param_copy(resumed)) and straight.losses == resumed.losses


def test_keys_of_the_single_train_section_load_where_they_live_now():
    """``train.<key>`` of the layout before the ``guard``, ``regularizers``, ``clearance``, ``hold`` and ``corgs``
    sections (and ``strategy.prune_unseen_at_end``) (config files, --set, the
    configs inside checkpoints) lands in them through ``MOVED``; ``cfg.train.<key>`` still reads and sets them."""
    from warpgs.config import ConfigError, config_from_dict, load_config

    cfg = load_config([], ["train.binocular=0.5", "train.binocular_start=0.25", "train.drop_rate=0.1",
                           "train.sync_every=3", "train.explode_factor=7"])
    assert cfg.regularizers.binocular.weight == 0.5 and cfg.regularizers.binocular.start == 0.25
    assert cfg.regularizers.dropout.rate == 0.1 and cfg.guard.sync_every == 3 and cfg.guard.explode_factor == 7
    assert cfg.train.binocular == 0.5 and cfg.train.sync_every == 3
    cfg.train.opacity_noise = 0.2
    assert cfg.regularizers.opacity_noise.sigma == 0.2
    moved = load_config([], ["train.path_clearance=0.2", "train.path_floaters_paths=both", "train.hold_geometry=stereo",
                             "train.hold_means_lr=0.3", "train.prune_unseen_at_end=true", "train.co_reg=true",
                             "train.co_reg_weight=0.5", "train.co_prune_dist=0.4"])
    assert moved.clearance.path == 0.2 and moved.clearance.floaters_paths == "both"
    assert moved.hold.geometry == "stereo" and moved.hold.means_lr == 0.3 and moved.strategy.prune_unseen_at_end
    assert moved.corgs.pair and moved.corgs.weight == 0.5 and moved.corgs.prune_dist == 0.4
    assert moved.train.co_reg and moved.train.hold_geometry == "stereo" and moved.train.path_clearance == 0.2
    with pytest.raises(ConfigError, match=r"corgs\.frames = 0 \(from --set train\.co_reg_frames=0\): must be >= 1"):
        load_config([], ["train.co_reg_frames=0"])
    saved = config_from_dict(read_checkpoint(FIXTURE)["config"])
    assert saved.regularizers.binocular.weight == 0.5 and saved.regularizers.path_consistency.start == 0.3
    assert saved.regularizers.dropout.rate == 0.2 and saved.regularizers.opacity_noise.sigma == 0.3
