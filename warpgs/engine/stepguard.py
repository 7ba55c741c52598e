"""The step guard: each training step's verdict (make the update, skip it, or roll back), the host reads
that are deferred between ``guard.sync_every`` steps and their replay, the snapshots of the last good state
and the rollback to it.

Divergence (judged by ``warpgs.guard.DivergenceGuard``, acted on here): a step is skipped (no update)
when its loss or gradients are not finite, or when its loss on the input views (``parts["inputs"]`` of
``Trainer.compute_loss``; pseudo views are left out) explodes: above ``guard.explode_factor`` x the median of
the last ``guard.explode_window`` finite losses (the statistic restarts with each ``Trainer.train()`` call,
i.e. each phase of the full method, and after an opacity reset or a pruning, whose expected jumps are not
divergence). A divergence is ``guard.max_nan_steps`` skipped steps in a row, ``guard.explode_patience`` exploding ones
in a row (one high loss alone, e.g. a hard view early in a phase, costs one step, never the run), or
parameters that are not finite after the optimiser step. The guard keeps an in-memory snapshot of the
last good state (parameters, Adam moments, densification statistics, RNGs), taken at each ``train()``
call and every ``guard.snapshot_every`` steps when all of it is finite; on a divergence it rolls back to
it, scales every learning rate by ``guard.recovery_lr_factor`` and goes on (each recovery is logged and
listed in metrics.json). After ``guard.max_recoveries`` recoveries the next divergence stops the run with
``TrainingDiverged``, naming the step, the cause and the last good checkpoint on disk; the model is left
at the last good state. A checkpoint is never written from a state that is not finite, so the one on disk
stays the last good one.

Host reads (``guard.sync_every``; 10 on CUDA, every step on the CPU): reading a loss or a flag on the host
waits for the device, so on CUDA the verdicts are read every ``sync_every`` steps (and before every
snapshot, checkpoint, evaluation, the end of a phase and a stop). In between, a step is judged on the
device (finite loss and gradients; the exploding-loss median over ``warpgs.guard.LossWindow``, the same
statistic in the same arithmetic) and a bad step's update is skipped there (``masked_step``: fused Adam's
``found_inf``), so a non-finite gradient never reaches the parameters. The read replays the verdicts
through the guard in order; a divergence is acted on then, up to ``sync_every`` steps late, and rolls back
as above (the steps after it are undone with it). Only the reads move: a run gives the same numbers for
every ``sync_every``. The progress bar's loss and PSNR are those of the reading steps.
"""

from __future__ import annotations

import math

import torch

from warpgs.engine.checkpoint import CheckpointError, TrainingDiverged, read_checkpoint
from warpgs.guard import DivergenceGuard, LossWindow
from warpgs.optim import finite_flags, masked_step

SYNC_EVERY_CUDA = 10  # guard.sync_every's default on CUDA: host reads of the verdicts every this many steps
# a step's record (StepGuard.step_record): [loss, loss finite, each gradient finite ..., exploding, MSE]
_VALUE, _LOSS_FINITE, _EXPLODING, _MSE = 0, 1, -2, -1


def all_finite(tensors) -> bool:
    """Whether every tensor is finite, with one device sync."""
    checks = [torch.isfinite(t).all() for t in tensors if isinstance(t, torch.Tensor) and t.is_floating_point()]
    if not checks:
        return True
    dev = checks[0].device  # tensors may live on several devices (CPU-side state next to CUDA parameters)
    return bool(torch.stack([c.to(dev) for c in checks]).all())


class StepGuard:
    """A trainer's step verdicts, deferred host reads, snapshots and rollbacks (module docstring). It reads
    the trainer's model, optimisers, losses and history, and writes the losses, the recoveries and the
    learning-rate scale."""

    def __init__(self, trainer):
        self.tr = trainer
        self.guard = DivergenceGuard(trainer.cfg.guard)
        self.snapshot: dict | None = None
        # host reads every guard.sync_every steps: the deferred steps' records, the end of the running phase
        # (None: outside train(), every step reads), the guard's statistic on the device
        self.pending: list[tuple[int, int, torch.Tensor]] = []
        self.phase_end: int | None = None
        self.window: LossWindow | None = None

    # ------------------------------------------------------------------------------------------
    # a step's verdict

    def judge(self, step: int, loss: torch.Tensor, inputs: torch.Tensor, out, cam) -> dict:
        """Step ``step`` after its backward (``out``: its render of ``cam``): deferred (``deferred_step``), or
        judged on the host with the deferred steps before it replayed, its update made or skipped."""
        tr = self.tr
        if not self.sync_due(step):
            return self.deferred_step(step, loss, inputs, out, cam)
        record = self.step_record(loss, inputs)
        with torch.no_grad():
            record[_MSE] = ((out.image.detach().clamp(0, 1) - cam.image) ** 2).mean()
        rolled_back, row = self.resolve(record)  # the one host read of the step, with the deferred steps'
        if rolled_back is not None:
            return rolled_back
        value = row[_VALUE]
        if not all(row[_LOSS_FINITE:_EXPLODING]):
            return self.skip(step, self.nonfinite_cause(row))
        exploding = self.guard.exploding(value, tr.losses)
        if exploding:
            if self.guard.exploded():
                return self.diverge(step, f"{self.guard.explode_steps} consecutive steps with an exploding loss "
                                          f"(the last: {exploding})")
            return self.skip(step, exploding)
        for opt in tr.optimizers:
            opt.step()
            opt.zero_grad(set_to_none=True)
        tr.regularizers.after_update(tr.context, step)
        self.guard.healthy()
        info = tr.after_update(step, out, cam)
        bad = self.nonfinite_parameters()
        if bad:
            return self.diverge(step, f"the parameters {', '.join(bad)} are not finite after the optimiser step")
        tr.losses.append(value)
        if self.window is not None:
            self.window.push(step, value)
        every = tr.cfg.guard.snapshot_every
        if every and (step + 1) % every == 0:
            self.take_snapshot(step + 1)
        return {"loss": value, "psnr": -10 * math.log10(max(row[_MSE], 1e-10)), **info}

    def skip(self, step: int, why: str) -> dict:
        """A step judged on the host that makes no update."""
        for opt in self.tr.optimizers:
            opt.zero_grad(set_to_none=True)
        result = self.skipped(step, why)
        if self.window is not None and not result.get("rolled_back"):
            self.window.push(step, float("nan"))
        return result

    def skipped(self, step: int, why: str) -> dict:
        """Counts a step that made no update: the log line, the guard's count (a divergence when it is the
        ``guard.max_nan_steps``-th in a row), a NaN loss."""
        self.tr.log(f"warpgs: step {step} skipped: {why}")
        if self.guard.skipped():
            return self.diverge(step, f"{self.guard.nan_steps} consecutive steps without a usable loss and gradient "
                                      f"(the last: {why})")
        self.tr.losses.append(float("nan"))
        return {"loss": float("nan"), "psnr": float("nan"), "skipped": 1}

    # ------------------------------------------------------------------------------------------
    # host reads (guard.sync_every): deferred verdicts

    @property
    def sync_every(self) -> int:
        """Steps between host reads of the verdicts (``guard.sync_every``; None: ``SYNC_EVERY_CUDA`` on CUDA,
        every step on the CPU, where a read costs nothing)."""
        n = self.tr.cfg.guard.sync_every
        if n is None:
            n = SYNC_EVERY_CUDA if self.tr.device.type == "cuda" else 1
        return max(int(n), 1)

    def sync_due(self, step: int) -> bool:
        """Whether step ``step`` reads the verdicts on the host: every ``sync_every`` steps, and where what comes
        after the step needs them all (a snapshot, a checkpoint, an evaluation, the end of the phase, a stop).
        Outside ``train()`` every step does."""
        every, end = self.sync_every, self.phase_end
        if every <= 1 or end is None:
            return True
        n, tc = step + 1, self.tr.cfg.train
        return (n % every == 0 or n >= end or self.tr.stop_requested
                or any(k and n % k == 0 for k in (self.tr.cfg.guard.snapshot_every, tc.checkpoint_every, tc.eval_every)))

    def step_record(self, loss: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        """A step's record, float64 on the device: [the input views' loss, whether the loss and each
        parameter's gradient are finite (1 / 0), exploding (a deferred verdict's), the render's MSE (where
        read)]."""
        flags = finite_flags(self.guarded_tensors(loss))
        record = torch.zeros(len(flags) + 3, dtype=torch.float64, device=loss.device)
        record[_VALUE] = inputs
        record[_LOSS_FINITE:_EXPLODING] = flags
        return record

    def guarded_tensors(self, loss: torch.Tensor) -> list[torch.Tensor]:
        """What must be finite for a step to make its update: the loss and each trained parameter's gradient
        (a zero for one without)."""
        grads = [p.grad for p in self.tr.trained_parameters().values()]
        if any(g is None for g in grads):
            zero = loss.new_zeros(())
            grads = [zero if g is None else g for g in grads]
        return [loss] + grads

    def nonfinite_cause(self, row: list[float]) -> str:
        if not row[_LOSS_FINITE]:
            return "the loss is not finite"
        bad = [n for n, ok in zip(self.tr.trained_parameters(), row[_LOSS_FINITE + 1:_EXPLODING]) if not ok]
        return f"the gradient of {', '.join(bad)} is not finite"

    def deferred_step(self, step: int, loss: torch.Tensor, inputs: torch.Tensor, out, cam) -> dict:
        """A step whose verdict the host reads later: the guard's verdict on the device (non-finite, or an
        exploding loss against ``LossWindow``, which gets the step's entry; ``DivergenceGuard.step_on_device``
        with ``guard.guard_kernels``, else ``deferred_verdict``), the update made or skipped there
        (``masked_step``), and only a step that made its update counts in the densification statistics. The
        record waits in ``pending`` for the next read (``resolve``)."""
        record, apply = self.update_on_device(step, loss, inputs)
        self.pending.append((step, self.guard.stat_start, record))
        # a step without its update is one in which no Gaussian was seen, for the densification statistics
        return self.tr.after_update(step, out._replace(radii=out.radii * apply), cam, apply)

    def update_on_device(self, step: int | None, loss: torch.Tensor, inputs: torch.Tensor):
        """A deferred step's verdict and its update, made or skipped on the device (``masked_step``); returns
        (the step's record, whether the update applies). ``step`` None: the guard kernels' window slot was set
        beforehand (a CUDA graph's replay, ``warpgs.engine.graphstep``, which needs ``guard.guard_kernels``)."""
        tr = self.tr
        if tr.cfg.guard.guard_kernels:
            window = self.window if step is None else self.loss_window(step)
            record, apply, found_inf = self.guard.step_on_device(self.guarded_tensors(loss), inputs, window, step)
        else:
            record, apply, found_inf = self.deferred_verdict(step, loss, inputs)
        for opt in tr.optimizers:
            masked_step(opt, apply, found_inf)
            opt.zero_grad(set_to_none=True)
        tr.regularizers.after_update(tr.context, tr.step if step is None else step)
        return record, apply

    def deferred_verdict(self, step: int, loss: torch.Tensor, inputs: torch.Tensor):
        """``DivergenceGuard.step_on_device``'s results from torch ops (record, apply, found_inf): the step's
        record, its verdict on the device and its entry in the loss window."""
        record = self.step_record(loss, inputs)
        value = record[_VALUE]
        finite = record[_LOSS_FINITE:_EXPLODING].all()
        exploding = finite & self.guard.exploding_on_device(value, self.loss_window(step))
        apply = finite & ~exploding
        record[_EXPLODING] = exploding
        self.window.push(step, torch.where(apply, value, float("inf")))
        return record, apply, (~apply).to(torch.float32)  # one flag for every optimiser (fused Adam's skip)

    def loss_window(self, step: int) -> LossWindow:
        if self.window is None:  # after a new statistic: from the host's losses (none, at a phase's start)
            self.window = LossWindow(self.tr.cfg.guard.explode_window, self.tr.device)
            self.window.rebuild(self.tr.losses, self.guard.stat_start, step)
        return self.window

    def restart_statistic(self, step: int) -> None:
        """The exploding-loss statistic starts again at ``step`` (``DivergenceGuard.restart``), on the device too."""
        self.guard.restart(step)
        self.window = None

    def resolve(self, record: torch.Tensor | None = None) -> tuple[dict | None, list[float] | None]:
        """The host read: the deferred steps' records, ``record`` (the reading step's own, if given) and, after
        deferred steps, the parameters' flags, in one transfer. Replays the deferred verdicts (``replay``); the
        parameters must be finite after their updates. Returns (the rollback's result when they diverged, else
        None; ``record`` as a list)."""
        pending, self.pending = self.pending, []
        parts = [r for _, _, r in pending] + ([record] if record is not None else [])
        if not parts:
            return None, None
        if pending:
            parts.append(self.parameter_flags().double())
        values = torch.cat(parts).tolist()
        w = parts[0].numel()
        rows = [values[i * w:(i + 1) * w] for i in range(len(pending) + (record is not None))]
        if pending:
            result = self.replay(pending, rows[:len(pending)])
            if result is None:
                bad = [n for n, ok in zip(self.tr.trained_parameters(), values[len(rows) * w:]) if not ok]
                if bad:
                    first, last = pending[0][0], pending[-1][0]
                    result = self.diverge(last, f"the parameters {', '.join(bad)} are not finite after the optimiser "
                                                f"step (of one of steps {first}-{last}, read at step {last + 1})")
            if result is not None:
                return result, None
        return None, (rows[-1] if record is not None else None)

    def replay(self, pending: list, rows: list[list[float]]) -> dict | None:
        """The host's part of the deferred verdicts, in order (their updates were made or skipped on the device):
        the log lines, the guard's counts and ``max_loss_ratio``, the losses. A divergence rolls back at the
        step it happened (its result is returned; the later steps are undone with it)."""
        losses = self.tr.losses
        latest = self.guard.stat_start
        for (k, stat_start, _), row in zip(pending, rows):
            if len(losses) != k:
                raise RuntimeError(f"warpgs: internal error: {len(losses)} losses recorded before step {k}")
            self.guard.stat_start = stat_start  # the statistic as it was at that step
            value = row[_VALUE]
            if not all(row[_LOSS_FINITE:_EXPLODING]):
                result = self.skipped(k, self.nonfinite_cause(row))
            else:
                why = self.guard.exploding(value, losses)  # the same verdict, with its numbers
                if not row[_EXPLODING]:
                    self.guard.healthy()
                    losses.append(value)
                    continue
                why = why or f"the loss {value:.4g} is above guard.explode_factor x the running median"
                if self.guard.exploded():
                    return self.diverge(k, f"{self.guard.explode_steps} consecutive steps with an exploding loss "
                                           f"(the last: {why})")
                result = self.skipped(k, why)
            if result.get("rolled_back"):
                return result
        self.guard.stat_start = latest
        return None

    def abandon_pending(self) -> None:
        """Training left by an exception between host reads: the deferred steps' losses go into the history as
        the device judged them (NaN where the update was skipped), and nothing else is acted on."""
        pending, self.pending = self.pending, []
        try:
            rows = torch.stack([r for _, _, r in pending]).tolist()
        except Exception:  # noqa: BLE001 - the device may be what failed
            rows = [None] * len(pending)
        for row in rows:
            ok = row is not None and all(row[_LOSS_FINITE:_EXPLODING]) and not row[_EXPLODING]
            self.tr.losses.append(row[_VALUE] if ok else float("nan"))
        self.window = None

    # ------------------------------------------------------------------------------------------
    # the last good state: finite checks, snapshots, rollback

    def nonfinite_parameters(self) -> list[str]:
        """Names of the parameters that are not finite, or whose value as rendered is not (a log-scale
        above ~88 is an infinite scale, which the rasterizer refuses); one device sync."""
        flags = self.parameter_flags().tolist()
        return [n for n, ok in zip(self.tr.trained_parameters(), flags) if not ok]

    def parameter_flags(self) -> torch.Tensor:
        """Per parameter (in ``trained_parameters``' order), on the device: whether it is finite, as stored and
        as rendered."""
        p = self.tr.trained_parameters()
        flags = finite_flags([t.detach() for t in p.values()])
        for i, (name, t) in enumerate(p.items()):
            if name.rsplit(".", 1)[-1] == "scales":
                flags[i] = flags[i] & torch.isfinite(torch.exp(t.detach())).all()
        return flags

    def state_is_finite(self) -> bool:
        """Whether the parameters (as rendered), the optimisers' moments and the densification statistics
        are all finite."""
        tr = self.tr
        tensors = list(tr.state.values()) + (list(tr.pair.state.values()) if tr.pair is not None else [])
        for opt in tr.optimizers:
            for st in opt.state.values():
                tensors += [v for v in st.values() if isinstance(v, torch.Tensor)]
        return not self.nonfinite_parameters() and all_finite(tensors)

    def take_snapshot(self, step: int | None = None) -> bool:
        """Keeps the current ``model`` and ``progress`` in memory as the last good state, if it is all finite;
        returns whether it did. On CUDA with ``guard.snapshot_on_device`` (default) the copy stays in GPU memory
        (the training state once more; a copy there takes microseconds, where one to the CPU stops the host
        for each transfer: about 160 MB every 100 steps for 225,000 Gaussians), else it goes to the CPU."""
        tr = self.tr
        if not self.state_is_finite():
            return False
        on_device = tr.device.type == "cuda" and tr.cfg.guard.snapshot_on_device
        self.snapshot = None  # the old copy goes first: at most one extra copy of the state at a time
        try:
            self.snapshot = tr.state_dict(("model", "progress"), device=tr.device if on_device else "cpu")
        except torch.cuda.OutOfMemoryError:  # no room for a second copy on the GPU: this one goes to the CPU
            self.snapshot = tr.state_dict(("model", "progress"))
        if step is not None:
            self.snapshot["step"] = step
        return True

    def restore_snapshot(self) -> int:
        """Puts the last good state back (the learning-rate scale stays as it is now; the losses and curve
        after its step go); returns its step."""
        tr = self.tr
        tr.load_state_dict(self.snapshot)
        del tr.losses[tr.step:]
        tr.curve = [row for row in tr.curve if row["step"] <= tr.step]
        self.restart_statistic(self.snapshot["stat_start"])
        self.guard.healthy()
        return tr.step

    def after_out_of_memory(self) -> int | None:
        """After the device ran out of memory in a step (another process took it, or the model outgrew it):
        drops the step's gradients and the step graph, frees the allocator's cache and puts the last good state
        back; returns its step, or None when there is none (the model then stays as the failed step left it)."""
        tr = self.tr
        for opt in tr.optimizers:
            opt.zero_grad(set_to_none=True)
        tr.graph = None  # a capture or replay cut short is not replayed again
        if tr.device.type == "cuda":
            torch.cuda.empty_cache()
        if self.snapshot is None:
            return None
        return self.restore_snapshot()

    def diverge(self, step: int, cause: str) -> dict:
        """A divergence at ``step``: rolls back to the last good state with lower learning rates, or, when
        ``guard.max_recoveries`` are spent (or there is no good state), stops with ``TrainingDiverged``."""
        tr = self.tr
        tc, gc = tr.cfg.train, tr.cfg.guard
        for opt in tr.optimizers:
            opt.zero_grad(set_to_none=True)
        if self.snapshot is None or len(tr.recoveries) >= gc.max_recoveries:
            if self.snapshot is not None:
                self.restore_snapshot()  # leave the model at the last good state, never at the diverged one
            ck = tr.last_checkpoint()
            if self.snapshot is None:
                tried = "there was no finite state to roll back to"
            elif gc.max_recoveries <= 0:
                tried = "recovery is off (guard.max_recoveries=0)"
            else:
                tried = (f"{len(tr.recoveries)} recoveries (each a rollback to the last good state with the learning "
                         f"rates x{gc.recovery_lr_factor:g}, now x{tr.lr_scale:g}) did not help")
            if ck is not None:
                saved = tr.saved_step
                if saved is None:  # a file this trainer neither wrote nor read
                    try:
                        saved = read_checkpoint(ck).get("step")
                    except CheckpointError:
                        saved = "unreadable"
                where = f"The last good checkpoint is {ck} (step {saved}); it was not overwritten."
            else:
                where = ("No checkpoint was written before it "
                         f"({'no output folder' if tr.out is None else f'train.checkpoint_every={tc.checkpoint_every}'}), "
                         "so there is nothing on disk to resume from.")
            raise TrainingDiverged(f"training diverged at step {step}: {cause}; {tried}. {where} Lower the learning "
                                   f"rates (--set optim.NAME_lr=...) or check the inputs (poses, images).",
                                   step=step, cause=cause, checkpoint=ck)
        tr.lr_scale *= gc.recovery_lr_factor
        back_to = self.restore_snapshot()
        tr.recoveries.append({"step": step, "cause": cause, "rolled_back_to": back_to, "lr_scale": tr.lr_scale})
        tr.log(f"warpgs: step {step}: {cause}; rolled back to step {back_to} (the last good state) with the learning "
               f"rates x{tr.lr_scale:g} (recovery {len(tr.recoveries)} of {gc.max_recoveries})")
        return {"loss": float("nan"), "psnr": float("nan"), "rolled_back": 1}
