"""Training losses: L1, D-SSIM (kornia), Pearson depth correlation, LPIPS (``lpips`` package, local weights),
and two weight-free priors: the Gaussians' anisotropy (``scale_anisotropy_loss``) and edge-aware depth
smoothness (``edge_aware_smoothness``).

Images are [H, W, 3] (or [B, 3, H, W]) in [0, 1]. ``dssim`` is 1 - SSIM, the form 3D-GS and gsplat train
with (weights 0.8 L1 + 0.2 D-SSIM). ``pearson_depth_loss`` is 1 - corr(rendered depth, prior) over the
valid pixels (FSGS / DNGaussian): 0 when perfectly correlated, 2 when anti-correlated; it is blind to
the prior's scale and shift, which monocular depth lacks anyway.

LPIPS uses the ``lpips`` package (its linear heads ship inside it) with the AlexNet backbone loaded from
a local file, never from the network: ``$WARPGS_LPIPS_WEIGHTS``, else
``~/.cache/warpgs/weights/alexnet-owt-7be5be79.pth``, else torch's hub cache. When torchvision is
absent (this project's CPU environment has no CPU build of it), warpgs gives ``lpips`` the
torchvision AlexNet layout itself, so the same weight file loads.
"""

from __future__ import annotations

import functools
import importlib
import os
import sys
import types
from pathlib import Path

import torch
from torch import nn

ALEXNET_FILE = "alexnet-owt-7be5be79.pth"
ALEXNET_URL = f"https://download.pytorch.org/models/{ALEXNET_FILE}"
LPIPS_ENV = "WARPGS_LPIPS_WEIGHTS"


def _bchw(x: torch.Tensor) -> torch.Tensor:
    if x.dim() == 3:  # [H, W, C]
        return x.permute(2, 0, 1)[None]
    if x.dim() == 4:
        return x
    raise ValueError(f"expected an image [H, W, C] or a batch [B, C, H, W], got shape {list(x.shape)}")


def l1(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    d = (pred - target).abs()
    if mask is None:
        return d.mean()
    m = (mask.bool()[..., None].expand_as(d) if mask.dim() == d.dim() - 1 else mask.bool())
    # a sum over the image with the rest at 0 rather than a boolean selection (a host read): ``pearson_depth_loss``
    return torch.where(m, d, d.new_zeros(())).sum() / m.sum(dtype=d.dtype).clamp_min(1.0)


def ssim(pred: torch.Tensor, target: torch.Tensor, window_size: int = 11, padding: str = "same") -> torch.Tensor:
    """Mean SSIM (Gaussian window, sigma 1.5) through kornia (``ssim_map``)."""
    return ssim_map(pred, target, window_size, padding).mean()


def ssim_map(pred: torch.Tensor, target: torch.Tensor, window_size: int = 11, padding: str = "same") -> torch.Tensor:
    """kornia's SSIM map [B, C, H, W] of two images ([H, W, C] or [B, C, H, W]). On a GPU, with float32 images and
    ``'same'`` padding, ``_ssim_map`` computes it with its window made once per device (kornia makes it on every
    call, from a copy from the host that a CUDA graph cannot hold)."""
    a, b = _bchw(pred), _bchw(target)
    if padding == "same" and a.device.type != "cpu" and a.dtype == b.dtype == torch.float32 and a.shape == b.shape:
        return _ssim_map(a, b, window_size)
    from kornia.metrics import ssim as kssim

    return kssim(a, b, window_size, max_val=1.0, padding=padding)


@functools.cache  # never evicted: a CUDA graph of a training step reads it where it is
def _ssim_window(window_size: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """kornia's SSIM window (a sampled Gaussian, sigma 1.5), as ``kornia.metrics.ssim`` makes it."""
    from kornia.filters import get_gaussian_kernel1d

    return get_gaussian_kernel1d(window_size, 1.5, device=device, dtype=dtype)


def _ssim_map(img1: torch.Tensor, img2: torch.Tensor, window_size: int) -> torch.Tensor:
    """``kornia.metrics.ssim(img1, img2, window_size, max_val=1.0)`` of two float32 [B, C, H, W] images off the CPU:
    the same operations in the same order (so the same numbers), with the window from ``_ssim_window``."""
    from kornia.filters import filter2d_separable

    kernel = _ssim_window(window_size, img1.device, img1.dtype)
    c1, c2, eps = 0.01 ** 2, 0.03 ** 2, 1e-12
    mu1 = filter2d_separable(img1, kernel, kernel)
    mu2 = filter2d_separable(img2, kernel, kernel)
    mu1_sq = mu1 ** 2
    mu2_sq = mu2 ** 2
    mu1_mu2 = mu1 * mu2
    sigma1_sq = filter2d_separable(img1 ** 2, kernel, kernel) - mu1_sq
    sigma2_sq = filter2d_separable(img2 ** 2, kernel, kernel) - mu2_sq
    sigma12 = filter2d_separable(img1 * img2, kernel, kernel) - mu1_mu2
    num = (2.0 * mu1_mu2 + c1) * (2.0 * sigma12 + c2)
    den = (mu1_sq + mu2_sq + c1) * (sigma1_sq + sigma2_sq + c2)
    return num / (den + eps)


def dssim(pred: torch.Tensor, target: torch.Tensor, window_size: int = 11) -> torch.Tensor:
    """1 - SSIM (3D-GS's D-SSIM term)."""
    return 1.0 - ssim(pred, target, window_size)


def weighted_l1(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, mask: torch.Tensor | None = None
                ) -> torch.Tensor:
    """``weight`` [H, W] x |pred - target| ([H, W, C]), averaged over the pixels and channels (those of ``mask``
    [H, W] where given): with weight 1, ``l1``."""
    d = weight[..., None] * (pred - target).abs()
    if mask is None:
        return d.mean()
    m = mask.to(d.dtype)[..., None]
    n = m.sum() * d.shape[-1]
    return (d * m).sum() / n.clamp_min(1.0)  # 0 without a pixel, and no host read (``pearson_depth_loss``)


def weighted_dssim(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, window_size: int = 11
                   ) -> torch.Tensor:
    """The mean over pixels and channels of ``weight`` [H, W] x (1 - SSIM map) of [H, W, C] images (kornia's map,
    Gaussian window, 'same' padding; ``ssim_map``): with weight 1 the D-SSIM."""
    smap = ssim_map(pred, target, window_size)
    return (weight.to(smap.dtype)[None, None] * (1.0 - smap)).mean()


def pearson_depth_loss(depth: torch.Tensor, prior: torch.Tensor, mask: torch.Tensor | None = None,
                       eps: float = 1e-8) -> torch.Tensor:
    """1 - Pearson correlation of ``depth`` and ``prior`` over ``mask`` (default: where prior > 0); 0 over fewer
    than two pixels. Sums over the whole image with the pixels outside the mask set to 0, not over the selected
    pixels: no host read (a boolean selection waits for the device to know its size), so a CUDA graph can hold
    it and the host runs ahead of the device (``warpgs.engine.graphstep``)."""
    if depth.shape != prior.shape:
        raise ValueError(f"pearson_depth_loss: depth {list(depth.shape)} and prior {list(prior.shape)} differ")
    m = (prior > 0) if mask is None else mask.bool()
    zero = depth.new_zeros(())
    n = m.sum(dtype=depth.dtype)
    k = n.clamp_min(1.0)
    x = torch.where(m, depth, zero)  # (where, not a product: a non-finite value outside the mask stays out)
    y = torch.where(m, prior.to(depth.dtype), zero)
    x = torch.where(m, x - x.sum() / k, zero)
    y = torch.where(m, y - y.sum() / k, zero)
    corr = (x * y).sum() / (x.norm() * y.norm() + eps)
    return torch.where(n >= 2, 1.0 - corr, zero)


def scale_anisotropy_loss(log_scales: torch.Tensor, max_ratio: float) -> torch.Tensor:
    """PhysGaussian's anisotropy regulariser (Xie et al., CVPR 2024): the mean over the Gaussians of
    max(max(s) / min(s), r) - r, where s are a Gaussian's three standard deviations and r = ``max_ratio``;
    0 for Gaussians no more elongated than r, growing with the axis ratio of needles and flat discs beyond
    it. ``log_scales`` [N, 3] are the model's parameters (log standard deviations): the ratio is
    exp(max - min) of them, exact without dividing by a tiny scale. 0 (with a gradient) for N = 0."""
    if log_scales.dim() != 2 or log_scales.shape[1] != 3:
        raise ValueError(f"scale_anisotropy_loss: expected log-scales [N, 3], got shape {list(log_scales.shape)}")
    if max_ratio < 1:
        raise ValueError(f"scale_anisotropy_loss: max_ratio must be >= 1 (an axis ratio), got {max_ratio}")
    if log_scales.shape[0] == 0:
        return log_scales.sum() * 0
    ratio = torch.exp(log_scales.max(dim=1).values - log_scales.min(dim=1).values)
    return torch.relu(ratio - max_ratio).mean()


def edge_aware_smoothness(depth: torch.Tensor, image: torch.Tensor, eps: float = 1e-7, normalise: bool = True
                          ) -> torch.Tensor:
    """Edge-aware smoothness of a depth map (Monodepth, Godard et al. CVPR 2017; on the mean-normalised map as
    Monodepth2): mean |d/dx D| exp(-|d/dx I|) + mean |d/dy D| exp(-|d/dy I|), with D = depth / mean(depth),
    neighbouring-pixel differences, and the image gradient averaged over its channels. Depth may change
    freely across the image's edges and is pushed to be flat inside its smooth regions; 0 on a constant
    depth, and blind to the depth's scale. ``depth`` [H, W], ``image`` [H, W, C]."""
    if depth.dim() != 2 or image.dim() != 3 or image.shape[:2] != depth.shape:
        raise ValueError(f"edge_aware_smoothness: depth [H, W] and image [H, W, C] of one size expected, got "
                         f"{list(depth.shape)} and {list(image.shape)}")
    d = depth / (depth.mean() + eps) if normalise else depth
    img = image.to(d.dtype)
    wx = torch.exp(-(img[:, 1:] - img[:, :-1]).abs().mean(-1))
    wy = torch.exp(-(img[1:] - img[:-1]).abs().mean(-1))
    return ((d[:, 1:] - d[:, :-1]).abs() * wx).mean() + ((d[1:] - d[:-1]).abs() * wy).mean()


# ----------------------------------------------------------------------------------------------
# LPIPS


class LPIPSUnavailable(RuntimeError):
    """LPIPS cannot run: the package or the backbone weights are missing (the message says what to do)."""


def input_loss(lc, out, cam) -> tuple[torch.Tensor, dict]:
    """The loss of a render ``out`` of the input view ``cam`` against it with the weights of ``lc`` (the config's
    ``loss``): w1 L1 + w2 D-SSIM, and the alpha and depth-prior terms where they are on; (loss, its parts by
    name, the whole as ``inputs``)."""
    l1_ = l1(out.image, cam.image)
    loss = lc.l1_weight * l1_
    parts = {"l1": l1_}
    if lc.ssim_weight > 0:
        ds = dssim(out.image, cam.image)
        loss = loss + lc.ssim_weight * ds
        parts["dssim"] = ds
    if lc.alpha_weight > 0 and cam.alpha is not None:
        al = (out.alpha - cam.alpha).abs().mean()
        loss = loss + lc.alpha_weight * al
        parts["alpha"] = al
    if lc.depth_weight > 0 and lc.depth_prior == "scene" and cam.depth is not None:
        dl = pearson_depth_loss(out.depth, cam.depth)
        loss = loss + lc.depth_weight * dl
        parts["depth"] = dl
    # what the divergence guard judges: the inputs' loss, which the method's terms (extra views, priors that
    # appear in a later phase) and the priors on the parameters leave out
    parts["inputs"] = loss
    return loss, parts


def default_lpips_weights() -> list[Path]:
    """Where the AlexNet backbone is looked for, in order."""
    out = []
    if os.environ.get(LPIPS_ENV):
        out.append(Path(os.environ[LPIPS_ENV]).expanduser())
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    out.append(cache / "warpgs" / "weights" / ALEXNET_FILE)
    out.append(Path(os.environ.get("TORCH_HOME") or cache / "torch") / "hub" / "checkpoints" / ALEXNET_FILE)
    return out


def _missing_weights_message(looked: list[Path]) -> str:
    where = "\n".join(f"  {p}" for p in looked)
    return (f"LPIPS needs the AlexNet backbone weights ({ALEXNET_FILE}), and none were found. warpgs looked at:\n"
            f"{where}\nDownload {ALEXNET_URL} and save it as {default_lpips_weights()[-2]} "
            f"(or anywhere, and set {LPIPS_ENV}=/path/to/{ALEXNET_FILE}).")


def one_line(message) -> str:
    """An LPIPSUnavailable message as one short line for summaries: what is missing and the one thing to
    do (the full message, with every place searched, stays in metrics.json)."""
    text = str(message)
    if text.startswith("LPIPS needs the AlexNet backbone weights"):
        return f"no AlexNet weights; download {ALEXNET_FILE} and set {LPIPS_ENV} to it (see README)"
    first = next((ln.strip() for ln in text.splitlines() if ln.strip()), "")
    return first if len(first) <= 160 else first[:157].rstrip() + "..."


def _alexnet_features() -> nn.Sequential:
    """torchvision's AlexNet ``features`` (same layer indices, so its state dict loads)."""
    return nn.Sequential(
        nn.Conv2d(3, 64, kernel_size=11, stride=4, padding=2), nn.ReLU(inplace=True),
        nn.MaxPool2d(kernel_size=3, stride=2),
        nn.Conv2d(64, 192, kernel_size=5, padding=2), nn.ReLU(inplace=True),
        nn.MaxPool2d(kernel_size=3, stride=2),
        nn.Conv2d(192, 384, kernel_size=3, padding=1), nn.ReLU(inplace=True),
        nn.Conv2d(384, 256, kernel_size=3, padding=1), nn.ReLU(inplace=True),
        nn.Conv2d(256, 256, kernel_size=3, padding=1), nn.ReLU(inplace=True),
        nn.MaxPool2d(kernel_size=3, stride=2),
    )


def _import_lpips():
    """``import lpips``; without torchvision, with a stand-in that provides only ``models.alexnet``
    (removed from ``sys.modules`` again so nothing else mistakes it for torchvision)."""
    try:
        return importlib.import_module("lpips")
    except ModuleNotFoundError as e:
        if e.name == "lpips":
            raise LPIPSUnavailable(
                "LPIPS needs the 'lpips' package: pip install --no-deps lpips scipy "
                "(--no-deps keeps your torch build; warpgs supplies the AlexNet layout if torchvision is absent)"
            ) from e
        if e.name != "torchvision":
            raise LPIPSUnavailable(f"the 'lpips' package cannot be imported: {e}") from e
    for k in [k for k in sys.modules if k == "lpips" or k.startswith("lpips.")]:
        del sys.modules[k]

    class _AlexNet(nn.Module):
        def __init__(self):
            super().__init__()
            self.features = _alexnet_features()

    def alexnet(pretrained=False, weights=None, **_):
        if pretrained or weights is not None:
            raise RuntimeError("warpgs's torchvision stand-in has no pretrained weights")
        return _AlexNet()

    tv = types.ModuleType("torchvision")
    models = types.ModuleType("torchvision.models")
    models.alexnet = alexnet
    tv.models = models
    saved = {k: sys.modules.get(k) for k in ("torchvision", "torchvision.models")}
    sys.modules.update({"torchvision": tv, "torchvision.models": models})
    try:
        return importlib.import_module("lpips")
    except ModuleNotFoundError as e:
        raise LPIPSUnavailable(f"the 'lpips' package cannot be imported: {e} (pip install scipy)") from e
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v


class LPIPS(nn.Module):
    """LPIPS (AlexNet, v0.1) on images in [0, 1]: ``LPIPS(weights)(pred, target)`` -> mean distance.

    ``weights``: the torchvision AlexNet state dict file; None searches ``default_lpips_weights()``.
    Raises ``LPIPSUnavailable`` with download instructions when the file or the package is missing.
    """

    def __init__(self, weights: str | Path | None = None):
        super().__init__()
        looked = [Path(weights).expanduser()] if weights is not None else default_lpips_weights()
        path = next((p for p in looked if p.is_file()), None)
        if path is None:
            raise LPIPSUnavailable(_missing_weights_message(looked))
        lpips = _import_lpips()
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as e:
            raise LPIPSUnavailable(f"{path}: cannot read the AlexNet weights ({e}); download {ALEXNET_URL} again") from e
        self.model = lpips.LPIPS(net="alex", pnet_rand=True, verbose=False)
        net = self.model.net
        mapped = {}
        for key in net.state_dict():
            _, idx, pname = key.split(".")  # slice{k}.{layer index}.{weight|bias}
            src = f"features.{idx}.{pname}"
            if src not in state:
                raise LPIPSUnavailable(f"{path}: not a torchvision AlexNet state dict (no '{src}')")
            mapped[key] = state[src]
        net.load_state_dict(mapped, strict=True)
        self.weights_path = path
        self.eval()
        for p in self.parameters():
            p.requires_grad_(False)

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        a, b = _bchw(pred), _bchw(target)
        return self.model(a * 2 - 1, b * 2 - 1).mean()
