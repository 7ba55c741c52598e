"""CoR-GS's co-regularised pair (``train.co_reg``, warpgs/coreg.py): the co-pruning decision against a
brute-force nearest-neighbour oracle, the co-regularisation term, training / checkpoint / resume of the pair,
the full method with it, and the default run left as it was."""

import json

import numpy as np
import pytest
import torch

from test_rasterizer import DEVICES
from tiny_scene import make_scene, param_copy, same_params, small_full_trainer, tiny_config
from warpgs.config import Config, ConfigError, load_config
from warpgs.coreg import co_prune_masks, co_reg_loss
from warpgs.model import PARAM_NAMES, GaussianModel
from warpgs.train import CHECKPOINT, Trainer


@pytest.fixture(scope="module")
def scene():
    return make_scene()


def nearest_distance(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The oracle: each query's distance to its nearest point, by brute force in float64."""
    d2 = ((queries[:, None, :].astype(np.float64) - points[None, :, :].astype(np.float64)) ** 2).sum(-1)
    return np.sqrt(d2.min(axis=1))


# ----------------------------------------------------------------------------------------------
# (a) the co-pruning decision


@pytest.mark.parametrize("device", DEVICES)
def test_co_prune_matches_brute_force_nearest_neighbour(device):
    rng = np.random.default_rng(0)
    cases = ((500, 400, 1.0, 0.08), (300, 700, 2.0, 0.3), (50, 60, 10.0, 6.0), (200, 5, 1.0, 0.2))
    for na, nb, spread, radius in cases:
        a = (rng.normal(size=(na, 3)) * spread).astype(np.float32)
        b = (rng.normal(size=(nb, 3)) * spread + 0.05).astype(np.float32)
        prune_a, prune_b = co_prune_masks(torch.tensor(a, device=device), torch.tensor(b, device=device), radius)
        assert prune_a.shape == (na,) and prune_b.shape == (nb,) and prune_a.dtype == torch.bool
        for got, d in ((prune_a, nearest_distance(a, b)), (prune_b, nearest_distance(b, a))):
            clear = np.abs(d - radius) > 1e-5 * max(radius, 1.0)  # float32 cannot decide a tie at the radius
            assert clear.mean() > 0.99
            expect = d > radius
            assert np.array_equal(got.cpu().numpy()[clear], expect[clear]), (na, nb, radius)
            assert 0 < expect.sum() < len(expect) or len(expect) < 10  # both outcomes occur


@pytest.mark.parametrize("device", DEVICES)
def test_co_prune_removes_exactly_the_isolated_points(device):
    # two clouds on one grid, jittered by much less than the radius, and points that only one of them has
    rng = np.random.default_rng(1)
    grid = np.stack(np.meshgrid(*[np.arange(6) * 0.5] * 3, indexing="ij"), -1).reshape(-1, 3)
    a = grid + rng.uniform(-0.02, 0.02, grid.shape)
    b = grid + rng.uniform(-0.02, 0.02, grid.shape)
    lonely_a = np.array([[10.0, 0.0, 0.0], [0.0, -7.0, 1.0], [1.25, 1.25, 1.25]])  # 1.25: halfway between grid nodes
    lonely_b = np.array([[0.0, 0.0, 20.0], [-3.0, -3.0, -3.0]])
    a = np.concatenate([a[:100], lonely_a, a[100:]]).astype(np.float32)
    b = np.concatenate([lonely_b, b]).astype(np.float32)
    prune_a, prune_b = co_prune_masks(torch.tensor(a, device=device), torch.tensor(b, device=device), 0.1)
    assert torch.nonzero(prune_a).flatten().tolist() == [100, 101, 102]
    assert torch.nonzero(prune_b).flatten().tolist() == [0, 1]
    with pytest.raises(ValueError, match="radius"):
        co_prune_masks(torch.tensor(a), torch.tensor(b), 0.0)


# ----------------------------------------------------------------------------------------------
# (b) the co-regularisation term


def test_co_reg_loss_is_zero_for_identical_models_and_trains_both(scene):
    cam = Trainer(tiny_config(1), scene).train_cams[0]
    g = torch.Generator().manual_seed(0)
    model_a = GaussianModel.random_box(200, [-1, -1, -1], [1, 1, 1], generator=g, init_opacity=0.5)

    def copy_of(model):
        return GaussianModel(*(model.params[n].detach() for n in PARAM_NAMES), max_sh_degree=model.max_sh_degree)

    twin = copy_of(model_a)

    def image(model):
        return model.render(cam.viewmat, cam.K, cam.width, cam.height).image

    assert float(co_reg_loss(image(model_a), image(twin)).detach()) == pytest.approx(0.0, abs=1e-6)
    # a partner that differs: the term is positive and its gradient reaches every parameter of both models
    model_b = copy_of(model_a)
    with torch.no_grad():
        model_b.params["means"] += 0.05 * torch.randn(model_b.params["means"].shape, generator=g)
        model_b.params["sh0"] += 0.3
    loss = co_reg_loss(image(model_a), image(model_b))
    assert float(loss.detach()) > 1e-3
    loss.backward()
    for model in (model_a, model_b):
        for name in ("means", "scales", "opacities", "sh0"):  # (isotropic Gaussians: no gradient of the rotation)
            grad = model.params[name].grad
            assert grad is not None and bool(torch.isfinite(grad).all()) and float(grad.abs().sum()) > 0, name


# ----------------------------------------------------------------------------------------------
# (c) training, checkpoints and resume of the pair


def _pair_config(iterations: int, **train) -> Config:
    # co-regularisation from step 10, co-pruning every 20 steps after step 30 (at 40 and 60) with a radius small
    # enough to remove Gaussians: the resume at step 50 lies between them, after the first
    cfg = tiny_config(iterations, co_reg=True, co_reg_start=10, co_prune_every=20, co_prune_dist=0.04,
                      co_reg_frames=4, **train)
    cfg.strategy.refine_stop_iter = 1000
    return cfg


def test_pair_trains_checkpoints_and_resumes_exactly(scene, tmp_path):
    straight = Trainer(_pair_config(70), scene)
    straight.train()
    pair = straight.pair
    assert pair is not None and len(pair.views) == 2 * 4
    assert [e["step"] for e in pair.co_pruned] == [40, 60]
    assert all(e["removed"] > 0 and e["partner_removed"] > 0 for e in pair.co_pruned)
    assert not same_params(param_copy(straight), {k: v.detach() for k, v in pair.model.params.items()})

    first = Trainer(_pair_config(70), scene, tmp_path)
    first.train(50)
    first.save_checkpoint()
    saved = torch.load(tmp_path / CHECKPOINT, weights_only=False)
    assert torch.equal(saved["pair"]["params"]["means"], first.pair.model.means.detach())
    second = Trainer(_pair_config(70), scene, tmp_path)
    second.load_checkpoint()
    assert second.step == 50 and len(second.pair.model) == len(first.pair.model)
    second.train()
    assert same_params(param_copy(straight), param_copy(second))
    assert same_params({k: v.detach() for k, v in straight.pair.model.params.items()},
                       {k: v.detach() for k, v in second.pair.model.params.items()})
    assert straight.losses == second.losses and straight.pair.co_pruned == second.pair.co_pruned

    m = second.finish()  # the first model is the run's result; the partner is reported beside it
    co = json.loads((tmp_path / "metrics.json").read_text())["co_reg"]
    assert m["num_gaussians"] == len(second.model) and co["partner_gaussians"] == len(second.pair.model)
    assert co["co_pruned"] == straight.pair.co_pruned and co["partner_psnr"] > 10
    # a checkpoint of the pair resumed with the switch off goes on with the first model alone
    alone = Trainer(tiny_config(70), scene, tmp_path)
    alone.load_checkpoint()
    assert alone.pair is None and same_params(param_copy(alone), param_copy(second))
    # and one written without the pair cannot resume a run with it
    Trainer(tiny_config(5), scene, tmp_path / "plain").save_checkpoint()
    with pytest.raises(Exception, match="corgs.pair off"):
        Trainer(_pair_config(70), scene, tmp_path / "plain").load_checkpoint()


def test_pair_is_judged_as_one_and_deferred_reads_change_nothing(scene):
    """Host reads every 4 steps (the deferred verdicts of CUDA) give the numbers of reads every step, for both
    models; a step whose partner loss is not finite makes no update of either model."""
    runs = []
    for every in (1, 4):
        tr = Trainer(_pair_config(45, sync_every=every), scene)
        tr.train()
        runs.append(tr)
    a, b = runs
    assert [e["step"] for e in a.pair.co_pruned] == [40] and a.losses == b.losses
    assert same_params(param_copy(a), param_copy(b))
    assert same_params(dict(a.pair.model.params), dict(b.pair.model.params))

    tr = Trainer(_pair_config(20), scene)
    partner_loss = tr.pair.loss
    before = {}

    def nan_at_step_12(step, cam, background, parts):
        loss = partner_loss(step, cam, background, parts)
        if step == 12:
            partner = {k: v.detach().clone() for k, v in tr.pair.model.params.items()}
            before.update(model=param_copy(tr), partner=partner)
            loss = loss * float("nan")
        return loss

    tr.pair.loss = nan_at_step_12
    tr.train(13)
    assert np.isnan(tr.losses[12]) and np.isfinite(tr.losses[:12]).all()
    assert same_params(before["model"], param_copy(tr)) and same_params(before["partner"], dict(tr.pair.model.params))


def test_full_method_with_the_pair(tmp_path):
    _, tr = small_full_trainer(tmp_path, "--set", "train.co_reg=true", "--set", "train.co_reg_start=0",
                               "--set", "train.co_reg_frames=2")
    tr.run()
    assert tr.step == 40 and tr.pair is not None and tr.method.pseudo_cams  # the full method's cycles ran
    assert len(tr.pair.model) > 0 and torch.isfinite(tr.pair.model.means).all()
    assert not torch.equal(tr.pair.model.params["sh0"], tr.model.params["sh0"])


def test_settings_are_checked():
    cfg = load_config([], ["train.co_reg=true"])
    assert cfg.train.co_reg and cfg.train.co_reg_weight == 1.0 and cfg.train.co_prune_every == 500
    for bad in ("train.co_prune_dist=0", "train.co_reg_weight=-1", "train.co_reg_frames=0", "train.co_prune_every=-5"):
        with pytest.raises(ConfigError, match=bad.split("=")[0].split(".")[1]):
            load_config([], [bad])


# ----------------------------------------------------------------------------------------------
# (d) off by default: the default run trains one model, as a pair whose couplings are off trains its first

def test_off_by_default_trains_exactly_as_before(scene):
    assert Config().train.co_reg is False
    plain = Trainer(tiny_config(60), scene)
    assert plain.pair is None and len(plain.optimizers) == 1
    plain.train()
    assert np.mean(plain.losses[-10:]) < 0.8 * np.mean(plain.losses[:10])  # it trains
    # a pair without its two couplings (no co-regularisation, no co-pruning) leaves the first model's training
    # exactly as it is alone: the partner only adds its own loss, whose gradient is its own
    uncoupled = Trainer(tiny_config(60, co_reg=True, co_reg_weight=0.0, co_prune_every=0), scene)
    uncoupled.train()
    assert uncoupled.losses == plain.losses and same_params(param_copy(uncoupled), param_copy(plain))


def test_the_method_corgs_is_the_baseline_with_the_pair(scene):
    """``--method corgs`` (``warpgs.methods.corgs``) trains what ``train.co_reg=true`` over the baseline trains,
    bit for bit, and the command line knows it."""
    from warpgs.methods import method_class
    from warpgs.pipelines.sparse import build_parser, make_config

    cfg = _pair_config(30)
    cfg.train.co_reg = False
    as_method = Trainer(cfg, scene, method=method_class("corgs")())
    as_flag = Trainer(_pair_config(30), scene)
    assert as_method.pair is not None and as_method.method.name == "corgs"
    as_method.train()
    as_flag.train()
    assert as_method.losses == as_flag.losses and same_params(param_copy(as_method), param_copy(as_flag))
    assert same_params({k: v for k, v in as_method.pair.model.params.items()},
                       {k: v for k, v in as_flag.pair.model.params.items()})
    parsed, _ = make_config(build_parser().parse_args(["--method", "corgs"]))
    assert parsed.method == "corgs"
