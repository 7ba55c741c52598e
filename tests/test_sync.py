"""Host reads every ``train.sync_every`` steps (issue 15): between reads the trainer judges each step on the
device, skips the update of a bad one there, and acts on the verdicts at the next read. On the CPU (where
these tests run) the default reads every step; here the deferred path is forced with ``sync_every=5``.

What must hold: a healthy run is bit-identical whatever ``sync_every`` is (only the host reads move); a
non-finite gradient never reaches the parameters or Adam's moments; an exploding loss and non-finite
parameters are still caught and rolled back exactly, up to ``sync_every`` steps late; a Ctrl-C between
reads saves a state a resumed run continues exactly from; the device's exploding-loss verdict is the
host's (the same median in the same arithmetic).
"""

import math
import signal

import numpy as np
import pytest
import torch

from tiny_scene import make_scene, param_copy, same_params, tiny_config
from warpgs.config import ConfigError, load_config
from warpgs.guard import DivergenceGuard, LossWindow
from warpgs.train import CHECKPOINT, Trainer, finite_flags, masked_step, with_adam_options


@pytest.fixture(scope="module")
def scene():
    return make_scene()


def _reads(tr, monkeypatch) -> list[int]:
    """Records the step of every host read of the verdicts."""
    steps = []
    real = tr.stepguard.resolve

    def counted(*args, **kw):
        steps.append(tr.step)
        return real(*args, **kw)

    monkeypatch.setattr(tr.stepguard, "resolve", counted)
    return steps


def _finite(tr):
    return all(bool(torch.isfinite(p).all()) for p in tr.model.params.values())


def test_the_default_reads_every_step_on_the_cpu_and_the_setting_is_checked():
    assert load_config([]).train.sync_every is None
    assert load_config([], ["train.sync_every=7"]).train.sync_every == 7
    with pytest.raises(ConfigError, match="sync_every"):
        load_config([], ["train.sync_every=0"])
    tr = Trainer(tiny_config(1), make_scene())
    assert tr.sync_every == 1 and tr.stepguard.sync_due(0) and tr.stepguard.sync_due(3)


@pytest.mark.parametrize("kernels", [False, True])
def test_deferred_reads_give_the_same_run(scene, monkeypatch, kernels):
    """130 steps (densification every 20 from 30, an opacity reset at 120): the same parameters, losses and
    loss ratio with a read every step and every 5 steps, and 26 reads instead of 130; with the deferred
    verdicts from torch ops and from the Warp kernels (``train.guard_kernels``)."""
    runs = {}
    for every in (1, 5):
        tr = Trainer(tiny_config(130, sync_every=every, guard_kernels=kernels), scene)
        reads = _reads(tr, monkeypatch)
        tr.train()
        runs[every] = (param_copy(tr), tr.losses, tr.guard.max_loss_ratio, len(reads), tr)
    assert same_params(runs[1][0], runs[5][0]) and runs[1][1] == runs[5][1] and runs[1][2] == runs[5][2]
    assert (runs[1][3], runs[5][3]) == (130, 26) and not runs[5][4].stepguard.pending
    assert len(runs[5][1]) == 130 and len(runs[5][0]["means"]) != 300  # densification ran


def _inf_gradient_at(tr, steps):
    """The loss plus sqrt(x - x) of one SH coefficient at ``steps``: the loss is unchanged (finite), the
    gradient of sh0 is infinite there."""
    real = tr.compute_loss

    def loss(out, cam):
        value, parts = real(out, cam)
        if tr.step in steps:
            x = tr.model.params["sh0"][0, 0, 0]
            value = value + torch.sqrt(x - x.detach())
        return value, parts

    return loss


@pytest.mark.parametrize("kernels", [False, True])
def test_a_nonfinite_gradient_never_reaches_the_parameters_between_reads(scene, monkeypatch, kernels):
    tr = Trainer(tiny_config(40, sync_every=5, guard_kernels=kernels), scene)
    monkeypatch.setattr(tr, "compute_loss", _inf_gradient_at(tr, {12}))
    import warpgs.engine.stepguard

    seen = {}

    def watched(optimizer, apply, found_inf=None):  # the state around step 12's (deferred) update
        if tr.step == 12:
            seen["before"] = (param_copy(tr), [{k: v.clone() for k, v in st.items()} for st in optimizer.state.values()])
            seen["pending"] = len(tr.stepguard.pending)
        masked_step(optimizer, apply, found_inf)
        if tr.step == 12:
            seen["after"] = (param_copy(tr), [{k: v.clone() for k, v in st.items()} for st in optimizer.state.values()])

    monkeypatch.setattr(warpgs.engine.stepguard, "masked_step", watched)
    logs = []
    tr.log = logs.append
    tr.train()
    assert seen["pending"] == 2  # steps 10 and 11 were waiting: step 12 was judged on the device
    assert same_params(seen["before"][0], seen["after"][0])  # no parameter moved
    for a, b in zip(seen["before"][1], seen["after"][1]):  # nor a moment or a step count
        assert all(torch.equal(a[k], b[k]) for k in a)
    assert np.isnan(tr.losses[12]) and np.isfinite(np.delete(tr.losses, 12)).all() and _finite(tr)
    assert "warpgs: step 12 skipped: the gradient of sh0 is not finite" in logs
    assert all(int(st["step"]) == 39 for st in tr.optimizer.state.values()) and not tr.recoveries
    # and the run is the one that reads every step
    twin = Trainer(tiny_config(40, sync_every=1), scene)
    monkeypatch.setattr(twin, "compute_loss", _inf_gradient_at(twin, {12}))
    twin.log = lambda msg: None
    twin.train()
    assert same_params(param_copy(tr), param_copy(twin)) and tr.losses[:12] == twin.losses[:12]
    assert tr.losses[13:] == twin.losses[13:]


@pytest.mark.parametrize("kernels", [False, True])
def test_an_exploding_loss_between_reads_is_rolled_back_exactly(scene, monkeypatch, kernels):
    """As tests/test_stability.py's exact rollback, with reads every 5 steps: steps 70 and 71 skip their
    updates on the device, 72 is the divergence; the read at step 74 finds it and rolls back to 50."""
    tr = Trainer(tiny_config(100, snapshot_every=25, sync_every=5, guard_kernels=kernels), scene)
    real = tr.compute_loss

    def explode_from_70_until_a_rollback(out, cam):
        loss, parts = real(out, cam)
        if tr.step >= 70 and not tr.recoveries:
            return loss * 1e4, {**parts, "inputs": parts["inputs"] * 1e4}
        return loss, parts

    monkeypatch.setattr(tr, "compute_loss", explode_from_70_until_a_rollback)
    reads = _reads(tr, monkeypatch)
    tr.train()
    assert 74 in reads and not {70, 71, 72, 73} & set(reads)
    assert [(r["step"], r["rolled_back_to"], r["lr_scale"]) for r in tr.recoveries] == [(72, 50, 0.5)]
    cause = tr.recoveries[0]["cause"]
    assert cause.startswith("3 consecutive steps with an exploding loss (the last: the loss ") and "explode_factor=10" in cause
    assert len(tr.losses) == 100 and np.isfinite(tr.losses).all()
    twin = Trainer(tiny_config(100, snapshot_every=25, sync_every=5), scene)
    twin.train(50)
    twin.lr_scale = 0.5
    twin.apply_lr_scale()
    twin.train()
    assert same_params(param_copy(tr), param_copy(twin)) and tr.losses == twin.losses


def test_nan_losses_between_reads_roll_back(scene, monkeypatch):
    tr = Trainer(tiny_config(80, max_nan_steps=3, snapshot_every=20, sync_every=5), scene)
    real = tr.compute_loss

    def nan_at_51_to_53(out, cam):
        loss, parts = real(out, cam)
        return (loss * float("nan"), parts) if 51 <= tr.step <= 53 and not tr.recoveries else (loss, parts)

    monkeypatch.setattr(tr, "compute_loss", nan_at_51_to_53)
    tr.log = lambda msg: None
    tr.train()
    # 51 and 52 skipped on the device, 53 the third in a row (found at the read of step 54): back to 40
    assert [(r["step"], r["rolled_back_to"]) for r in tr.recoveries] == [(53, 40)]
    assert "3 consecutive steps without a usable loss and gradient (the last: the loss is not finite)" in tr.recoveries[0]["cause"]
    assert tr.step == 80 and len(tr.losses) == 80 and np.isfinite(tr.losses).all() and _finite(tr)


def test_nonfinite_parameters_between_reads_are_rolled_back(scene, monkeypatch):
    tr = Trainer(tiny_config(60, snapshot_every=20, sync_every=5), scene)
    real = tr.after_update

    def after_step_45_a_scale_is_infinite(step, out, cam, apply=None):  # finite as stored, infinite as rendered
        info = real(step, out, cam, apply)
        if step == 45 and not tr.recoveries:
            with torch.no_grad():
                tr.model.params["scales"][3] = 200.0
        return info

    monkeypatch.setattr(tr, "after_update", after_step_45_a_scale_is_infinite)
    tr.log = lambda msg: None
    tr.train()
    # step 45 was deferred; the read at step 49 finds the scales infinite and rolls back to the snapshot at 40
    assert [(r["step"], r["rolled_back_to"]) for r in tr.recoveries] == [(48, 40)]
    assert "scales are not finite after the optimiser step (of one of steps 45-48" in tr.recoveries[0]["cause"]
    assert tr.step == 60 and _finite(tr) and not tr.stepguard.nonfinite_parameters()


def test_ctrl_c_between_reads_saves_a_state_that_resumes_exactly(scene, tmp_path, monkeypatch):
    tr = Trainer(tiny_config(60, sync_every=5), scene, tmp_path)
    real = tr.strategy.step_post_backward

    def ctrl_c_during_step_22(*args, **kw):  # after step 22 decided not to read (22 + 1 is no multiple of 5)
        if tr.step == 22:
            signal.raise_signal(signal.SIGINT)
        return real(*args, **kw)

    monkeypatch.setattr(tr.strategy, "step_post_backward", ctrl_c_during_step_22)
    from warpgs.train import TrainingInterrupted

    with pytest.raises(TrainingInterrupted) as e:
        tr.train()
    assert e.value.step == 23 and torch.load(tmp_path / CHECKPOINT, weights_only=False)["step"] == 23
    assert len(tr.losses) == 23 and not tr.stepguard.pending
    resumed = Trainer(tiny_config(60, sync_every=5), scene, tmp_path)
    resumed.load_checkpoint()
    resumed.train()
    straight = Trainer(tiny_config(60, sync_every=5), scene)
    straight.train()
    assert same_params(param_copy(straight), param_copy(resumed)) and straight.losses == resumed.losses


def _random_guard(rng, factors):
    """A guard, its window and the host's losses at random: a window of 1-8, a factor from ``factors``, up to
    14 float32 losses with up to 3 NaN (skipped steps) and a restart anywhere. (guard, losses, window
    filled from them, the median the host takes (1 without one))."""
    from types import SimpleNamespace

    window = int(rng.integers(1, 9))
    cfg = SimpleNamespace(explode_factor=float(rng.choice(factors)), explode_window=window,
                          explode_patience=3, max_nan_steps=3)
    g = DivergenceGuard(cfg)
    n = int(rng.integers(0, 15))
    losses = [float(np.float32(x)) for x in rng.uniform(0.01, 1.0, n)]
    for i in rng.choice(n, size=min(n, int(rng.integers(0, 4))), replace=False) if n else []:
        losses[i] = float("nan")
    g.restart(int(rng.integers(0, n + 1)))
    w = LossWindow(window, "cpu")
    w.rebuild(losses, g.stat_start, n)
    recent = [x for x in losses[max(g.stat_start, n - window):] if math.isfinite(x)]
    return g, losses, w, float(np.median(recent)) if recent else 1.0


def test_the_device_verdict_is_the_hosts():
    """``exploding_on_device`` against ``exploding`` on random windows (NaN for skipped steps, restarts, odd
    and even counts), at and around the threshold."""
    rng = np.random.default_rng(0)
    for trial in range(60):
        g, losses, w, median = _random_guard(rng, [2.0, 10.0])
        cfg, window = g.cfg, w.size
        for v in (median * cfg.explode_factor, np.nextafter(median * cfg.explode_factor, np.inf),
                  np.nextafter(median * cfg.explode_factor, 0), 0.5 * median, 3.0):
            v = float(v)
            host = g.exploding(v, losses) is not None
            dev = bool(g.exploding_on_device(torch.tensor(v, dtype=torch.float64), w))
            assert host == dev, (trial, losses, g.stat_start, window, v)


def test_the_kernels_step_verdict_is_the_hosts():
    """``step_on_device`` (two Warp launches) against the host's ``exploding`` and ``finite_flags`` on random
    windows with skipped steps and restarts, float32 losses at and around the threshold, a NaN or inf
    gradient, an empty tensor and the check turned off: the record, whether the update applies, fused
    Adam's ``found_inf`` and the window's new entry."""
    rng = np.random.default_rng(1)
    for trial in range(80):
        g, losses, w, median = _random_guard(rng, [2.0, 10.0, 0.0])
        n, window, factor = len(losses), w.size, g.cfg.explode_factor
        threshold = np.float32(median * max(factor, 1.0))
        for v in (threshold, np.nextafter(threshold, np.float32(np.inf)), np.nextafter(threshold, np.float32(0)),
                  np.float32(0.5 * median), np.float32(3.0)):
            bad = [None, float("nan"), float("inf"), "empty"][int(rng.integers(0, 4))]
            grads = [torch.rand(4, 3), torch.zeros(()), torch.rand(2)]
            if bad == "empty":
                grads[1] = torch.zeros(0, 3)
            elif bad is not None:
                grads[2][1] = bad
            loss = torch.tensor(float(v) + 1.0, dtype=torch.float32)
            inputs = torch.tensor(float(v), dtype=torch.float32)
            w.rebuild(losses, g.stat_start, n)
            before = w.values.clone()
            if trial % 2:  # the slot from the step, or set beforehand (a CUDA graph's replay)
                record, apply, found_inf = g.step_on_device([loss] + grads, inputs, w, n)
            else:
                w.slot.fill_(-7)
                w.set_slot(n)
                record, apply, found_inf = g.step_on_device([loss] + grads, inputs, w, None)
            flags = finite_flags([loss] + grads)
            exploding = bool(flags.all()) and g.exploding(float(v), losses) is not None
            ok = bool(flags.all()) and not exploding
            want = [float(v)] + [float(f) for f in flags] + [float(exploding), 0.0]
            assert record.tolist() == want, (trial, bad, v, record.tolist(), want)
            assert apply.dtype == torch.bool and apply.shape == () and bool(apply) == ok
            assert found_inf.dtype == torch.float32 and float(found_inf) == float(not ok)
            before[n % window] = float(v) if ok else float("inf")
            assert torch.equal(w.values, before), (trial, w.values, before)


def test_masked_step_changes_nothing_when_told_so():
    """``masked_step`` with Adam as the trainer makes it on each device kind: torch's default (the CPU) and
    fused (CUDA; run here where the CPU has a fused kernel). The fused optimiser's state loads into a
    default one (a CUDA checkpoint resumed on the CPU)."""
    kinds = [{}]
    try:
        p = torch.nn.Parameter(torch.ones(2))
        p.grad = torch.ones(2)
        torch.optim.Adam([p], fused=True).step()
        kinds.append({"fused": True})
    except RuntimeError:  # no fused CPU kernel in this torch
        pass
    for opts in kinds:
        torch.manual_seed(0)
        params = [torch.nn.Parameter(torch.randn(5, 3)), torch.nn.Parameter(torch.randn(5))]
        twin = [torch.nn.Parameter(p.detach().clone()) for p in params]
        opt = torch.optim.Adam([{"params": [p], "lr": 0.1} for p in params], eps=1e-15, **opts)
        ref = torch.optim.Adam([{"params": [p], "lr": 0.1} for p in twin], eps=1e-15, **opts)
        for step, apply in enumerate([False, True, True, False, True]):  # the first one skipped: no state yet
            g = [torch.randn_like(p) for p in params]
            for p, q, gi in zip(params, twin, g):
                p.grad, q.grad = gi.clone(), gi.clone()
            masked_step(opt, torch.tensor(apply))
            if apply:
                ref.step()
            for p, q in zip(params, twin):
                assert torch.equal(p, q), (opts, step)
        for p, q in zip(params, twin):
            for k, v in ref.state[q].items():
                assert torch.equal(opt.state[p][k].float(), v.float()), (opts, k)
        assert not hasattr(opt, "found_inf")
    if len(kinds) > 1:
        fused = torch.optim.Adam([{"params": [p], "lr": 0.1} for p in params], fused=True)
        plain = torch.optim.Adam([{"params": [p], "lr": 0.1} for p in params])
        for p in params:
            p.grad = torch.ones_like(p)
        fused.step()
        plain.load_state_dict(with_adam_options(fused.state_dict(), plain))
        assert not plain.param_groups[0].get("fused")
        plain.step()


def test_finite_flags_find_nan_and_inf_and_take_empty_tensors():
    nan, inf = float("nan"), float("inf")
    ts = [torch.tensor(1.0), torch.tensor([1.0, nan]), torch.tensor([[-inf, 0.0]]), torch.tensor([2.0, -3.0])]
    assert finite_flags(ts).tolist() == [True, False, False, True]
    assert finite_flags(ts + [torch.zeros(0, 3)]).tolist() == [True, False, False, True, True]


def test_state_copies_are_independent_and_go_where_asked():
    """``state_copy`` (checkpoints, snapshots): every tensor of a nested state is a new tensor on the device
    asked for, with the same values, and changing the original afterwards leaves the copy as it was."""
    from warpgs.optim import state_copy

    a = torch.arange(6.0).reshape(2, 3).requires_grad_()
    st = {"params": {"means": a}, "moments": [torch.ones(3), (torch.zeros(2), 7)], "step": 5, "name": "x"}
    cp = state_copy(st, "cpu")
    assert cp["step"] == 5 and cp["name"] == "x" and cp["moments"][1][1] == 7
    assert isinstance(cp["moments"][1], tuple) and not cp["params"]["means"].requires_grad
    with torch.no_grad():
        a += 1
        st["moments"][0].mul_(3)
    assert torch.equal(cp["params"]["means"], torch.arange(6.0).reshape(2, 3))
    assert torch.equal(cp["moments"][0], torch.ones(3))
    if torch.cuda.is_available():  # the trainer's snapshots on CUDA stay on the GPU
        g = state_copy(st, "cuda")
        assert g["params"]["means"].is_cuda and torch.equal(g["params"]["means"].cpu(), a.detach())


def test_grouped_adam_is_torch_fused_adam_bit_for_bit():
    """``GroupedAdam`` (``make_optimizer``'s) against torch's fused Adam: the same parameters, moments and step
    counts after steps with and without ``found_inf`` set, groups with different learning rates, a parameter
    without a gradient in some steps, and a parameter added between steps (its first step: torch's path);
    the CPU's default Adam takes torch's path throughout and matches torch's default."""
    from warpgs.optim import GroupedAdam

    try:
        p = torch.nn.Parameter(torch.ones(2))
        p.grad = torch.ones(2)
        torch.optim.Adam([p], fused=True).step()
    except RuntimeError:  # no fused CPU kernel in this torch
        pytest.skip("torch has no fused Adam on the CPU")
    for opts in ({"fused": True}, {}):
        g = torch.Generator().manual_seed(3)
        shapes = [(7, 3), (7, 4), (7,), (7, 15, 3)]
        params = [torch.nn.Parameter(torch.randn(s, generator=g)) for s in shapes]
        twin = [torch.nn.Parameter(p.detach().clone()) for p in params]
        groups = lambda ps: [{"params": [p], "lr": 0.01 * (i + 1), "name": str(i)} for i, p in enumerate(ps)]
        ours = GroupedAdam(groups(params), eps=1e-15, **opts)
        ref = torch.optim.Adam(groups(twin), eps=1e-15, **opts)
        for step in range(12):
            if step == 5:  # densification adds a group's parameter: no state yet
                extra = torch.randn(4, 3, generator=g)
                for opt, ps in ((ours, params), (ref, twin)):
                    q = torch.nn.Parameter(extra.clone())
                    ps.append(q)
                    opt.add_param_group({"params": [q], "lr": 0.003, "name": "extra"})
            for i, (p, q) in enumerate(zip(params, twin)):
                grad = None if (step + i) % 4 == 3 else torch.randn(p.shape, generator=g)
                p.grad = None if grad is None else grad.clone()
                q.grad = None if grad is None else grad.clone()
            skip = torch.tensor(1.0 if step in (2, 8) else 0.0)
            for opt in (ours, ref):
                if opts:
                    opt.found_inf = skip
                    opt.grad_scale = None
                opt.step()
                if opts:
                    del opt.found_inf, opt.grad_scale
            for p, q in zip(params, twin):
                assert torch.equal(p, q), (opts, step)
                for k, v in ref.state[q].items():
                    assert torch.equal(ours.state[p][k], v), (opts, step, k)
