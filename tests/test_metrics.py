"""Metrics: PSNR / SSIM against hand-computed values and a numpy SSIM, masking, LPIPS reporting."""

import math

import torch

from np_metrics import ssim as np_ssim
from warpgs import metrics


def test_psnr_hand_computed():
    gt = torch.full((8, 8, 3), 0.5)
    assert math.isclose(metrics.psnr(gt + 0.1, gt), 20.0, rel_tol=1e-5)  # MSE 0.01
    pred = gt.clone()
    pred[0, 0, 0] -= 0.4  # one error of 0.4 in 192 values: MSE 0.16 / 192
    assert math.isclose(metrics.psnr(pred, gt), -10 * math.log10(0.16 / 192), rel_tol=1e-5)
    assert metrics.psnr(gt, gt) == float("inf")
    # predictions are clamped to [0, 1] first, as images are
    assert math.isclose(metrics.psnr(torch.full((4, 4, 3), 1.7), torch.ones(4, 4, 3)), float("inf"))


def test_masked_metrics_black_out_the_background():
    g = torch.Generator().manual_seed(0)
    gt = torch.rand(24, 24, 3, generator=g)
    pred = gt.clone()
    mask = torch.zeros(24, 24, dtype=torch.bool)
    mask[6:18, 6:18] = True
    pred[~mask] = 1 - pred[~mask]  # wrong only outside the object
    assert metrics.psnr(pred, gt, mask) == float("inf")
    assert metrics.ssim(pred, gt, mask) > 0.999
    assert metrics.psnr(pred, gt) < 15
    pred[8, 8] += 0.3  # an error inside: the whole image is the denominator (RegNeRF's protocol)
    want = -10 * math.log10(float(((pred.clamp(0, 1)[8, 8] - gt[8, 8]) ** 2).sum()) / (24 * 24 * 3))
    assert math.isclose(metrics.psnr(pred, gt, mask), want, rel_tol=1e-5)


def test_ssim_against_numpy_reference():
    g = torch.Generator().manual_seed(3)
    a = torch.rand(40, 36, 3, generator=g)
    b = (a + 0.15 * torch.randn(40, 36, 3, generator=g)).clamp(0, 1)
    assert abs(metrics.ssim(a, b) - np_ssim(a.numpy(), b.numpy())) < 1e-5
    assert abs(metrics.ssim(a, a) - 1.0) < 1e-6
    c = torch.rand(40, 36, 3, generator=g)
    assert metrics.ssim(a, c) < 0.2


def test_lpips_metric_reports_missing_instead_of_a_number(tmp_path):
    lp = metrics.LPIPSMetric(tmp_path / "absent.pth")
    assert lp.value(torch.rand(8, 8, 3), torch.rand(8, 8, 3)) is None
    assert "absent.pth" in lp.missing
    assert metrics.mean_or_none([None, None]) is None
    assert metrics.mean_or_none([1.0, None]) is None  # never a mean over part of the views
    assert metrics.mean_or_none([1.0, 2.0]) == 1.5


def test_fps_and_memory():
    calls = []
    fps = metrics.render_fps(lambda i: calls.append(i), n_views=3, repeats=2)
    assert calls == [0, 0, 1, 2, 0, 1, 2] and fps > 0
    mem = metrics.peak_memory_mb("cpu")
    assert mem["peak_rss_mb"] > 10
