"""``regularizers.alpha_binary``: weight x mean(alpha (1 - alpha)) over each input render, which pushes every pixel to
be either covered or empty (no half-transparent haze)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs.regularizers.base import Regularizer


@dataclass
class AlphaBinaryConfig:
    weight: float = 0.0  # weight of mean(alpha (1 - alpha)) over each input render: every pixel either covered by
    #   Gaussians or showing what is behind them (with a far field, no translucent cover that a novel view sees at
    #   another angle); 0: off

    LIMITS = {"weight": ">= 0"}
    LEGACY = {"alpha_binary": "weight"}  # train.<key> of earlier versions -> this section's key


CONFIG = AlphaBinaryConfig  # the section regularizers.<name> of the run's config


class AlphaBinary(Regularizer):
    name = "alpha_binary"

    def __init__(self, weight: float):
        self.weight = weight

    def input_term(self, out, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        ab = (out.alpha * (1 - out.alpha)).mean()
        parts["alpha_binary"] = ab
        return loss + self.weight * ab


def build(cfg, ctx) -> AlphaBinary | None:
    c = cfg.regularizers.alpha_binary
    return AlphaBinary(c.weight) if c.weight > 0 else None
