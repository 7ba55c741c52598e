"""Evaluation metrics: PSNR, SSIM, LPIPS (optional), render speed, memory.

Images are [H, W, 3] in [0, 1]. SSIM is the standard form (11x11 Gaussian window, sigma 1.5,
K1 = 0.01, K2 = 0.03) averaged over the 'valid' window positions, as mip-NeRF / RegNeRF and the
sparse-view papers after them compute it.

Masked evaluation (DTU's protocol, RegNeRF): both images are set to black outside the object mask and
the whole image is scored. LPIPS is reported only when its weights are present; otherwise the
result says it is missing and why, and no number is made up.
"""

from __future__ import annotations

import math
import resource
import sys
import time
from typing import Callable

import torch


def apply_mask(pred: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor | None):
    if mask is None:
        return pred, gt
    m = mask.to(pred.dtype)[..., None]
    return pred * m, gt * m


def psnr(pred: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor | None = None) -> float:
    """10 log10(1 / MSE) over the whole image (after masking, if a mask is given)."""
    p, g = apply_mask(pred.float().clamp(0, 1), gt.float(), mask)
    mse = float(((p - g) ** 2).mean())
    return float("inf") if mse == 0 else -10.0 * math.log10(mse)


def ssim(pred: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor | None = None) -> float:
    from kornia.metrics import ssim as kssim

    p, g = apply_mask(pred.float().clamp(0, 1), gt.float(), mask)
    a, b = p.permute(2, 0, 1)[None], g.permute(2, 0, 1)[None]
    return float(kssim(a, b, 11, max_val=1.0, eps=0.0, padding="valid").mean())


class LPIPSMetric:
    """LPIPS if it can run here, else ``value`` returns None and ``missing`` says why."""

    def __init__(self, weights=None, device="cpu"):
        self.model, self.missing = None, None
        try:
            from warpgs.losses import LPIPS

            self.model = LPIPS(weights).to(device)
        except Exception as e:  # LPIPSUnavailable, or a broken install: report, never invent
            self.missing = str(e)

    def value(self, pred, gt, mask=None) -> float | None:
        if self.model is None:
            return None
        p, g = apply_mask(pred.float().clamp(0, 1), gt.float(), mask)
        with torch.no_grad():
            return float(self.model(p, g))


def mean_or_none(values):
    vals = [v for v in values if v is not None]
    return None if not vals or len(vals) != len(values) else float(sum(vals) / len(vals))


def render_fps(render_fn: Callable[[int], object], n_views: int, repeats: int = 3, device="cpu") -> float:
    """Frames per second of ``render_fn(i)`` over ``n_views`` views, ``repeats`` passes after a warm-up."""
    if n_views == 0:
        return float("nan")
    sync = torch.cuda.synchronize if str(device).startswith("cuda") else (lambda: None)
    with torch.no_grad():
        render_fn(0)
        sync()
        t0 = time.perf_counter()
        for _ in range(repeats):
            for i in range(n_views):
                render_fn(i)
        sync()
    return repeats * n_views / (time.perf_counter() - t0)


def peak_memory_mb(device="cpu") -> dict[str, float]:
    """Peak memory so far: the process's resident set (always) and torch's CUDA allocations (on cuda)."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rss_mb = rss / (1024 * 1024) if sys.platform == "darwin" else rss / 1024
    out = {"peak_rss_mb": round(rss_mb, 1)}
    if str(device).startswith("cuda") and torch.cuda.is_available():
        out["peak_cuda_allocated_mb"] = round(torch.cuda.max_memory_allocated() / 2**20, 1)
    return out
