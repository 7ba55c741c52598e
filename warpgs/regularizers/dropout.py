"""DropGaussian (Park et al., CVPR 2025; ``regularizers.dropout``): each training render drops Gaussians at the
rate ``rate`` x step / iterations and scales the others by 1 / (1 - rate). Evaluation renders use all of them.

The mask is drawn from the trainer's ``drop_gen`` (the context's generator; the co-regularised partner's own),
before the opacity noise's draw (``opacity_noise``), so a run without noise draws exactly what it drew before.
The rate is read from the device (``rate_tensors``; in float32, as a Python number would be: the same factors),
so that a CUDA graph of the step draws at each replay's rate."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs.regularizers.base import Regularizer


@dataclass
class DropoutConfig:
    rate: float = 0.0  # the rate rising linearly from 0 to this at the last step, the rest's opacity x 1 / (1 - rate);
    #   0: off. The paper: 0.2

    LIMITS = {"rate": "[0, 1)"}
    LEGACY = {"drop_rate": "rate"}  # train.<key> of earlier versions


CONFIG = DropoutConfig  # the section regularizers.<name> of the run's config


class Dropout(Regularizer):
    name = "dropout"

    def __init__(self, rate: float, device):
        if not 0.0 <= rate < 1.0:
            raise ValueError(f"regularizers.dropout.rate must be in [0, 1), got {rate}")
        self.rate = rate  # the final rate (the full method may set its own, full.drop_rate)
        self.device = device
        self._t = (torch.zeros((), device=device), torch.zeros((), device=device))  # (rate, 1 - rate)

    def rate_at(self, ctx, step: int) -> float:
        """The rate at ``step``: ``rate`` x step / iterations."""
        return self.rate * min(step / max(ctx.total_steps, 1), 1.0)

    def rate_tensors(self, ctx, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(rate, 1 - rate) at ``step`` as float32 scalars on the device, which the dropout reads: filled here,
        except while a CUDA graph records (its replays read what ``StepGraph.step`` filled before each one)."""
        if not (self.device.type == "cuda" and torch.cuda.is_current_stream_capturing()):
            rate = self.rate_at(ctx, step)
            self._t[0].fill_(rate)
            self._t[1].fill_(1.0 - rate)
        return self._t

    def opacity_factor(self, ctx, step: int, n: int, generator: torch.Generator) -> torch.Tensor | None:
        """0 for a dropped Gaussian, 1 / (1 - rate) for the others; None at rate 0."""
        if self.rate_at(ctx, step) <= 0:
            return None
        rate, keep_fraction = self.rate_tensors(ctx, step)
        keep = torch.rand(n, device=self.device, generator=generator) >= rate
        return keep.float() / keep_fraction

    def factor_bound(self, ctx, step: int) -> float | None:
        rate = self.rate_at(ctx, step)
        return None if rate <= 0 else 1.0 / (1.0 - rate)

    def graph_tensors(self) -> list[torch.Tensor]:
        return list(self._t)


def build(cfg, ctx) -> Dropout:
    """Always built (the full method may turn it on with its own rate)."""
    return Dropout(cfg.regularizers.dropout.rate, ctx.device)
