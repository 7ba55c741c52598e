"""``train.alpha_binary``: weight x mean(alpha (1 - alpha)) over each input render, which pushes every pixel to
be either covered or empty (no half-transparent haze)."""

from __future__ import annotations

import torch

from warpgs.regularizers.base import Regularizer


class AlphaBinary(Regularizer):
    name = "alpha_binary"

    def __init__(self, weight: float):
        self.weight = weight

    def input_term(self, out, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        ab = (out.alpha * (1 - out.alpha)).mean()
        parts["alpha_binary"] = ab
        return loss + self.weight * ab


def build(cfg, ctx) -> AlphaBinary | None:
    return AlphaBinary(cfg.train.alpha_binary) if cfg.train.alpha_binary > 0 else None
