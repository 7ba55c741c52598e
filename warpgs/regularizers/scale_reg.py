"""``train.scale_reg``: PhysGaussian's anisotropy prior on the scales (Xie et al., CVPR 2024), weight x the mean
over the Gaussians of max(max(s) / min(s), r) - r with r = ``train.scale_reg_ratio``. A prior on the parameters:
the divergence guard's ``inputs`` part leaves it out."""

from __future__ import annotations

import torch

from warpgs import losses
from warpgs.regularizers.base import Regularizer


class ScaleReg(Regularizer):
    name = "scale_reg"

    def __init__(self, weight: float, ratio: float):
        self.weight, self.ratio = weight, ratio

    def model_term(self, model, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        sr = losses.scale_anisotropy_loss(model.params["scales"], self.ratio)
        loss = loss + self.weight * sr
        parts["scale_reg"] = sr
        return loss


def build(cfg, ctx) -> ScaleReg | None:
    tc = cfg.train
    return ScaleReg(tc.scale_reg, tc.scale_reg_ratio) if tc.scale_reg > 0 else None
