"""Co-Adaptation's opacity noise (Chen et al., NeurIPS 2025; ``regularizers.opacity_noise``): each training
render's opacities x (1 + eps), eps ~ N(0, sigma^2) clipped to [-sigma, sigma] as in the authors' code, drawn
from the trainer's ``drop_gen`` after the dropout's mask. The rasterizer caps alpha at ``alpha_max`` where a
factor above 1 would pass it."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs.regularizers.base import Regularizer


@dataclass
class OpacityNoiseConfig:
    sigma: float = 0.0  # each training render's opacities x (1 + eps), eps ~ N(0, sigma^2) clipped to [-sigma, sigma];
    #   composes with the dropout; 0: off. Their scripts name 0.8, 0.4, 0.2 and 0.05, and find it less robust than
    #   dropout

    LIMITS = {"sigma": "[0, 1]"}
    LEGACY = {"opacity_noise": "sigma"}  # train.<key> of earlier versions


CONFIG = OpacityNoiseConfig  # the section regularizers.<name> of the run's config


class OpacityNoise(Regularizer):
    name = "opacity_noise"

    def __init__(self, sigma: float, device):
        self.sigma, self.device = sigma, device

    def opacity_factor(self, ctx, step: int, n: int, generator: torch.Generator) -> torch.Tensor | None:
        sigma = self.sigma
        eps = torch.randn(n, device=self.device, generator=generator) * sigma
        return 1.0 + eps.clamp(-sigma, sigma)

    def factor_bound(self, ctx, step: int) -> float | None:
        return 1.0 + self.sigma


def build(cfg, ctx) -> OpacityNoise | None:
    sigma = cfg.regularizers.opacity_noise.sigma
    if not 0.0 <= sigma <= 1.0:  # a factor 1 + eps with |eps| <= sigma stays >= 0
        raise ValueError(f"regularizers.opacity_noise.sigma must be in [0, 1], got {sigma}")
    return OpacityNoise(sigma, ctx.device) if sigma > 0 else None
