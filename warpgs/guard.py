"""The divergence guard: decides, step by step, whether training is healthy, skips a bad step, or has
diverged. It only judges; the trainer acts on its verdicts (skip the update, or roll back to the last good
state with lower learning rates; ``warpgs.engine.stepguard``).

    guard = DivergenceGuard(cfg.guard)
    guard.restart(step)                       # a new phase: its losses make their own statistic
    why = guard.exploding(value, losses)      # None, or why this finite loss counts as exploding
    guard.skipped() / guard.exploded()        # True when that many in a row make a divergence
    guard.healthy()                           # a good step: the counts in a row start again

    window = LossWindow(cfg.guard.explode_window, device)   # the same statistic on the device (no host read)
    window.rebuild(losses, guard.stat_start, step)           # from the losses the host holds
    flag = guard.exploding_on_device(value, window)          # a bool tensor: ``exploding``'s verdict
    window.push(step, value)                                 # the step's entry (not finite: skipped)
    record, apply, found_inf = guard.step_on_device(tensors, value, window, step)   # all of a deferred
                                                             # step's verdict in two Warp launches

A step is skipped when its loss or gradients are not finite, or when its loss explodes: above
``explode_factor`` x the median of the last ``explode_window`` finite losses of the phase. A divergence is
``max_nan_steps`` skipped steps in a row, or ``explode_patience`` exploding ones in a row (one high loss
alone costs one step, never the run).

On CUDA the trainer reads the verdicts only every ``guard.sync_every`` steps (a host read waits for the
device): between reads a step's verdict is computed on the device from ``LossWindow``, the last
``explode_window`` losses of the phase kept there, and the update is skipped there; at the read the
host replays the verdicts through the counts above. ``exploding_on_device`` computes the same median, in
the same float64 arithmetic, as ``exploding``, so both give the same verdict; the trainer's deferred steps
use ``step_on_device``, the same arithmetic in two kernels (warpgs/kernels/guard.py) instead of two dozen
small torch ops.
"""

from __future__ import annotations

import math

import numpy as np
import torch


def inf_norms(tensors: list[torch.Tensor]) -> torch.Tensor:
    """Each tensor's largest absolute value, stacked on the device (no host read), finite exactly when the
    tensor is: one fused reduction, which keeps NaN and inf (``torch._foreach_norm``'s infinity norm, as
    ``clip_grad_norm_`` relies on), or, where a tensor is empty, one check each (0 when finite, NaN when not)."""
    if all(t.numel() for t in tensors):
        return torch.stack(torch._foreach_norm(tensors, float("inf")))
    return torch.where(torch.stack([torch.isfinite(t).all() for t in tensors]), 0.0, float("nan"))


class DivergenceGuard:
    def __init__(self, train_cfg):
        self.cfg = train_cfg  # warpgs.config.GuardConfig: max_nan_steps, explode_factor, explode_window, explode_patience
        self.nan_steps = 0  # consecutive skipped steps
        self.explode_steps = 0  # consecutive steps with an exploding loss
        self.max_loss_ratio = 0.0  # the largest loss / running median seen (how close a healthy run came)
        self.stat_start = 0  # losses before this step do not enter the exploding-loss statistic

    def restart(self, step: int) -> None:
        """The statistic starts again at ``step`` (a new phase, an opacity reset, a rollback)."""
        self.stat_start = step

    def exploding(self, value: float, losses: list[float]) -> str | None:
        """Why ``value`` (a finite loss) counts as exploding against ``losses`` (the run's losses so far, one
        per step, NaN for skipped ones), or None. From the phase's second step on, so that a run that blows
        up at once is caught against its first loss."""
        tc = self.cfg
        if tc.explode_factor <= 0 or tc.explode_window <= 0:
            return None
        start = max(self.stat_start, len(losses) - tc.explode_window)
        recent = [x for x in losses[start:] if math.isfinite(x)]
        if not recent:
            return None
        median = float(np.median(recent))
        if median <= 0:
            return None
        ratio = value / median
        self.max_loss_ratio = max(self.max_loss_ratio, ratio)
        if ratio > tc.explode_factor:
            return (f"the loss {value:.4g} is {ratio:.3g}x the median {median:.4g} of the "
                    f"{len(recent)} finite loss{'es' if len(recent) > 1 else ''} before it "
                    f"(guard.explode_factor={tc.explode_factor:g})")
        return None

    def exploding_on_device(self, value: torch.Tensor, window: "LossWindow") -> torch.Tensor:
        """``exploding``'s verdict for a finite ``value`` (a 0-dim tensor) against ``window`` (the losses
        ``exploding`` would take from ``losses``) as a 0-dim bool tensor on the device, without a host read.
        ``max_loss_ratio`` is not updated here: the host does that when it replays the verdict."""
        tc = self.cfg
        if tc.explode_factor <= 0 or tc.explode_window <= 0:
            return torch.zeros((), dtype=torch.bool, device=value.device)
        median = window.median()  # inf when the window is empty: never exploding, as the host has it
        return (median > 0) & (value.double() / median > tc.explode_factor)

    def step_on_device(self, tensors: list[torch.Tensor], inputs: torch.Tensor, window: "LossWindow",
                       step: int | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """A deferred step's verdict without a host read, in two Warp launches (``warpgs.kernels.guard``):
        ``tensors`` are the loss and the gradients (each must be finite), ``inputs`` the input views' loss (0-dim)
        that ``exploding_on_device`` judges against ``window``. Returns the step's record (float64: [the
        inputs' loss, one finiteness flag per tensor (1 / 0), exploding (1 / 0), 0 for the render's MSE]),
        whether its update applies (a 0-dim bool) and fused Adam's ``found_inf`` (0-dim float32); the window's
        entry for ``step`` is written (the loss, or +inf for a step without its update); ``step`` None: in the slot
        ``window.set_slot`` chose (a CUDA graph of the step, whose launches cannot take the step as a number). The
        same arithmetic as ``finite_flags`` (``warpgs.optim``), ``exploding_on_device`` and ``LossWindow.push``."""
        from warpgs import _warp
        from warpgs.kernels import guard as kg

        dev = inputs.device
        norms = inf_norms(tensors).float()
        record = torch.empty(len(tensors) + 3, dtype=torch.float64, device=dev)
        flags = torch.empty(1, dtype=torch.uint8, device=dev)
        found_inf = torch.empty(1, dtype=torch.float32, device=dev)
        tc = self.cfg
        check = int(tc.explode_factor > 0 and tc.explode_window > 0)
        wdev = _warp.device_of(window.values)
        stream = _warp.stream_of(wdev)
        if step is not None:
            window.set_slot(step)
        if check:
            _warp.fast_launch(kg.window_middle, window.size, wdev, stream, window.values, window.middle)
        _warp.fast_launch(kg.step_verdict, 1, wdev, stream, norms, inputs.reshape(1).float(),
                          window.middle, window.values, window.slot, float(tc.explode_factor), check,
                          record, flags, found_inf)
        return record, flags.view(torch.bool).reshape(()), found_inf.reshape(())

    def skipped(self) -> bool:
        """One more skipped step; True when that makes ``max_nan_steps`` in a row."""
        self.nan_steps += 1
        return self.nan_steps >= self.cfg.max_nan_steps

    def exploded(self) -> bool:
        """One more exploding step; True when that makes ``explode_patience`` in a row."""
        self.explode_steps += 1
        return self.explode_steps >= self.cfg.explode_patience

    def healthy(self) -> None:
        self.nan_steps = self.explode_steps = 0


class LossWindow:
    """The guard's statistic kept on the device: the losses of the last ``size`` steps in a ring (slot
    ``step % size``), +inf for skipped steps and for steps before the phase's ``stat_start`` (any value that
    is not finite is left out), in float64 (the host's ``np.median`` works on Python floats). Filled from
    the host list (``rebuild``) after a host read, then one entry per step (``push``) without one."""

    def __init__(self, size: int, device):
        self.size = max(int(size), 1)
        self.values = torch.full((self.size,), float("inf"), dtype=torch.float64, device=device)
        self.middle = torch.zeros(2, dtype=torch.float64, device=device)  # step_on_device's two middle values
        self.slot = torch.zeros(1, dtype=torch.int32, device=device)  # where step_on_device writes its entry
        self._pair = torch.tensor([0, 1], device=device)  # the two middle ranks: (count - 1 + [0, 1]) // 2

    def rebuild(self, losses: list[float], stat_start: int, step: int) -> None:
        """The window before ``step``: ``losses[max(stat_start, step - size):step]`` (the host's statistic);
        an empty window (a new phase) needs no copy from the host."""
        self.values.fill_(float("inf"))
        lo = max(stat_start, step - self.size, 0)
        if lo < step:
            if len(losses) < step:
                raise ValueError(f"LossWindow.rebuild: {len(losses)} losses on the host, the window needs {step}")
            idx = torch.tensor([j % self.size for j in range(lo, step)], device=self.values.device)
            kept = [x if math.isfinite(x) else math.inf for x in losses[lo:step]]
            self.values[idx] = torch.tensor(kept, dtype=torch.float64).to(self.values.device)

    def set_slot(self, step: int) -> None:
        """Step ``step``'s slot, where ``DivergenceGuard.step_on_device`` writes its entry (one fill on the device)."""
        self.slot.fill_(step % self.size)

    def push(self, step: int, value) -> None:
        """Step ``step``'s entry: a float (a step the host judged) or a 0-dim tensor (not finite: a skipped
        step)."""
        slot = self.values[step % self.size]
        if isinstance(value, torch.Tensor):  # the trainer's: finite, or +inf for a skipped step
            slot.copy_(value.reshape(()))
        else:
            slot.fill_(value if math.isfinite(value) else math.inf)

    def median(self) -> torch.Tensor:
        """The median of the finite entries (a 0-dim tensor) as ``np.median`` has it: the mean of the two
        middle values for an even count (their sum halved: the same rounding); +inf when there are none."""
        count = torch.isfinite(self.values).sum()  # what is not finite is +inf here: sorted last
        ranks = ((count - 1 + self._pair) // 2).clamp(0, self.size - 1)
        return torch.sort(self.values).values.index_select(0, ranks).mean()
