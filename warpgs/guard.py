"""The divergence guard: decides, step by step, whether training is healthy, skips a bad step, or has
diverged. It only judges; the trainer acts on its verdicts (skip the update, or roll back to the last good
state with lower learning rates; ``warpgs.train``).

    guard = DivergenceGuard(cfg.train)
    guard.restart(step)                       # a new phase: its losses make their own statistic
    why = guard.exploding(value, losses)      # None, or why this finite loss counts as exploding
    guard.skipped() / guard.exploded()        # True when that many in a row make a divergence
    guard.healthy()                           # a good step: the counts in a row start again

A step is skipped when its loss or gradients are not finite, or when its loss explodes: above
``explode_factor`` x the median of the last ``explode_window`` finite losses of the phase. A divergence is
``max_nan_steps`` skipped steps in a row, or ``explode_patience`` exploding ones in a row (one high loss
alone costs one step, never the run).
"""

from __future__ import annotations

import math

import numpy as np


class DivergenceGuard:
    def __init__(self, train_cfg):
        self.cfg = train_cfg  # warpgs.config.TrainConfig: max_nan_steps, explode_factor, explode_window, explode_patience
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
                    f"(train.explode_factor={tc.explode_factor:g})")
        return None

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
