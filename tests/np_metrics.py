"""Plain-numpy references for the metric tests (independent of kornia and torch)."""

import numpy as np


def gaussian_window(size=11, sigma=1.5):
    x = np.arange(size) - (size - 1) / 2
    g = np.exp(-(x ** 2) / (2 * sigma ** 2))
    return g / g.sum()


def _filter_valid(a, w):
    """Separable 'valid' correlation of a 2D array with the 1D window ``w`` along both axes."""
    k = len(w)
    rows = np.lib.stride_tricks.sliding_window_view(a, k, axis=0) @ w  # (H-k+1, W)
    return np.lib.stride_tricks.sliding_window_view(rows, k, axis=1) @ w


def ssim_map(x, y, size=11, sigma=1.5, pad=None):
    """SSIM map of two 2D float64 arrays in [0, 1] (C1 = 0.01^2, C2 = 0.03^2); ``pad='reflect'`` keeps the size."""
    if pad is not None:
        x, y = np.pad(x, size // 2, mode=pad), np.pad(y, size // 2, mode=pad)
    w = gaussian_window(size, sigma)
    mx, my = _filter_valid(x, w), _filter_valid(y, w)
    sxx = _filter_valid(x * x, w) - mx ** 2
    syy = _filter_valid(y * y, w) - my ** 2
    sxy = _filter_valid(x * y, w) - mx * my
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2))


def ssim(img_a, img_b, pad=None):
    """Mean SSIM over channels of (H, W, 3) images."""
    a, b = np.asarray(img_a, np.float64), np.asarray(img_b, np.float64)
    return float(np.mean([ssim_map(a[..., c], b[..., c], pad=pad).mean() for c in range(a.shape[2])]))
