"""Binocular3DGS's opacity decay (Han et al., NeurIPS 2024; ``regularizers.opacity_decay``): after each update from
``strategy.refine_start_iter`` on, every opacity x (1 - rate), on the logits the model holds."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs.regularizers.base import Regularizer


@dataclass
class OpacityDecayConfig:
    rate: float = 0.0  # from strategy.refine_start_iter on, every step multiplies each opacity by (1 - rate) after the
    #   update, so what the inputs' gradients do not hold up fades and is pruned (theirs: 0.005 a step); 0: off

    LIMITS = {"rate": "[0, 1)"}
    LEGACY = {"opacity_decay": "rate"}  # train.<key> of earlier versions


CONFIG = OpacityDecayConfig  # the section regularizers.<name> of the run's config


class OpacityDecay(Regularizer):
    name = "opacity_decay"

    def __init__(self, rate: float):
        self.rate = rate

    def active(self, ctx, step: int) -> bool:
        return step >= ctx.strategy.refine_start_iter

    def after_update(self, ctx, step: int) -> None:
        if not self.active(ctx, step):
            return
        with torch.no_grad():  # device ops only: a CUDA graph of the step holds them
            o = ctx.model.params["opacities"]
            o.copy_(torch.logit(torch.sigmoid(o) * (1.0 - self.rate), eps=1e-6))

    def graph_key(self, ctx, step: int):
        return self.active(ctx, step)


def build(cfg, ctx) -> OpacityDecay | None:
    rate = cfg.regularizers.opacity_decay.rate
    return OpacityDecay(rate) if rate > 0 else None
