"""``regularizers.scale_reg``: PhysGaussian's anisotropy prior on the scales (Xie et al., CVPR 2024), weight x the mean
over the Gaussians of max(max(s) / min(s), r) - r with r = ``ratio``. A prior on the parameters:
the divergence guard's ``inputs`` part leaves it out."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs import losses
from warpgs.regularizers.base import Regularizer


@dataclass
class ScaleRegConfig:
    weight: float = 0.0  # weight of the anisotropy prior: mean over the Gaussians of max(max(s)/min(s), r) - r; 0: off
    ratio: float = 10.0  # r: the largest axis ratio a Gaussian keeps without penalty

    LIMITS = {"weight": ">= 0", "ratio": ">= 1"}
    LEGACY = {"scale_reg": "weight", "scale_reg_ratio": "ratio"}  # train.<key> of earlier versions


CONFIG = ScaleRegConfig  # the section regularizers.<name> of the run's config


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
    c = cfg.regularizers.scale_reg
    return ScaleReg(c.weight, c.ratio) if c.weight > 0 else None
