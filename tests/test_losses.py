"""Losses: L1, D-SSIM, Pearson depth, LPIPS loading (random backbone weights, never downloaded)."""

import importlib.util
import os

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from np_metrics import ssim as np_ssim
from warpgs import losses


def _images(seed=0, h=24, w=32):
    g = torch.Generator().manual_seed(seed)
    a = torch.rand(h, w, 3, generator=g)
    b = (a + 0.2 * torch.randn(h, w, 3, generator=g)).clamp(0, 1)
    return a, b


def test_l1_matches_numpy_and_masks():
    a, b = _images()
    assert abs(float(losses.l1(a, b)) - float(np.abs(a.numpy() - b.numpy()).mean())) < 1e-6
    m = torch.zeros(24, 32, dtype=torch.bool)
    m[5:10, 3:20] = True
    want = np.abs(a.numpy() - b.numpy())[m.numpy()].mean()
    assert abs(float(losses.l1(a, b, m)) - want) < 1e-6


def test_dssim_against_numpy_reference():
    a, b = _images(1)
    assert abs(float(losses.dssim(a, a))) < 1e-5
    want = 1.0 - np_ssim(a.numpy(), b.numpy(), pad="reflect")  # kornia's 'same' pads by reflection
    assert abs(float(losses.dssim(a, b)) - want) < 1e-4
    # batch layout gives the same value; gradients flow
    x = b.clone().requires_grad_(True)
    losses.dssim(x.permute(2, 0, 1)[None], a.permute(2, 0, 1)[None]).backward()
    assert x.grad is not None and bool(torch.isfinite(x.grad).all()) and float(x.grad.abs().sum()) > 0


def test_pearson_analytic_cases():
    g = torch.Generator().manual_seed(0)
    d = 1 + 4 * torch.rand(20, 30, generator=g)
    assert abs(float(losses.pearson_depth_loss(d, 3.0 * d + 7.0))) < 1e-6  # any positive affine map: 0
    assert abs(float(losses.pearson_depth_loss(d, 10.0 - d)) - 2.0) < 1e-6  # anti-correlated: the maximum, 2
    noise = torch.rand(20, 30, generator=g) + 0.1
    v = float(losses.pearson_depth_loss(d, noise))
    x, y = d.flatten().double().numpy(), noise.flatten().double().numpy()
    assert abs(v - (1 - np.corrcoef(x, y)[0, 1])) < 1e-5  # numpy's correlation coefficient
    # pixels where the prior is 0 (unknown) are ignored; an explicit mask too
    prior = 2 * d + 1
    prior[:5] = 0.0
    d2 = d.clone()
    d2[:5] = torch.rand(5, 30, generator=g) * 100  # garbage where the prior is unknown
    assert abs(float(losses.pearson_depth_loss(d2, prior))) < 1e-6
    mask = torch.ones(20, 30, dtype=torch.bool)
    mask[:5] = False
    assert abs(float(losses.pearson_depth_loss(d2, 2 * d + 1, mask))) < 1e-6
    # gradient pushes towards correlation
    x = noise.clone().requires_grad_(True)
    loss = losses.pearson_depth_loss(x, d)
    loss.backward()
    with torch.no_grad():
        assert float(losses.pearson_depth_loss(x - 0.1 * x.grad / x.grad.norm(), d)) < float(loss)
    with pytest.raises(ValueError, match="differ"):
        losses.pearson_depth_loss(d, d[:-1])


def test_masked_terms_ignore_what_lies_outside_the_mask():
    """The masked L1 and Pearson terms sum over the whole image with the outside set to 0 (no host read): a NaN or
    an Inf outside the mask changes neither the value nor the gradient, and under two pixels (Pearson) or none
    (L1) the term is 0 with a finite, zero gradient."""
    g = torch.Generator().manual_seed(1)
    d = 1 + torch.rand(12, 16, generator=g)
    prior = 2 + torch.rand(12, 16, generator=g)
    mask = torch.rand(12, 16, generator=g) > 0.4
    sel_x, sel_y = d[mask].double().numpy(), prior[mask].double().numpy()
    bad = d.clone()
    bad[~mask] = float("nan")
    bad[0, 0] = float("inf") if not mask[0, 0] else bad[0, 0]
    x = bad.clone().requires_grad_(True)
    v = losses.pearson_depth_loss(x, prior, mask)
    v.backward()
    assert abs(float(v) - (1 - np.corrcoef(sel_x, sel_y)[0, 1])) < 1e-5  # numpy on the selected pixels
    assert bool(torch.isfinite(x.grad).all()) and float(x.grad[~mask].abs().sum()) == 0.0
    img, target = torch.rand(12, 16, 3, generator=g), torch.rand(12, 16, 3, generator=g)
    want = (img - target).abs()[mask].mean()
    noisy = img.clone()
    noisy[~mask] = float("nan")
    assert abs(float(losses.l1(noisy, target, mask)) - float(want)) < 1e-6
    for few in (torch.zeros_like(mask), torch.zeros_like(mask).index_put_((torch.tensor([3]), torch.tensor([4])),
                                                                          torch.tensor(True))):
        x = d.clone().requires_grad_(True)
        v = losses.pearson_depth_loss(x, prior, few)
        v.backward()
        assert float(v) == 0.0 and bool(torch.isfinite(x.grad).all()) and float(x.grad.abs().sum()) == 0.0
    y = img.clone().requires_grad_(True)
    v = losses.l1(y, target, torch.zeros_like(mask))
    v.backward()
    assert float(v) == 0.0 and float(y.grad.abs().sum()) == 0.0


# ----------------------------------------------------------------------------------------------
# LPIPS

needs_lpips = pytest.mark.skipif(importlib.util.find_spec("lpips") is None,
                                 reason="the lpips package is not installed (pip install --no-deps lpips scipy)")


def _random_backbone(path, seed=0):
    torch.manual_seed(seed)
    feats = losses._alexnet_features()
    for m in feats:
        if isinstance(m, torch.nn.Conv2d):
            torch.nn.init.normal_(m.weight, 0, 0.05)
            torch.nn.init.normal_(m.bias, 0, 0.05)
    sd = {f"features.{k}": v for k, v in feats.state_dict().items()}
    sd["classifier.1.weight"] = torch.zeros(4, 4)  # a torchvision file also holds the classifier
    torch.save(sd, path)
    return feats


def _lpips_by_hand(feats, a, b):
    """LPIPS v0.1 written out: scaling layer, AlexNet relu1..relu5, unit-normalise channels, squared
    difference, the package's linear heads, spatial mean, sum over layers."""
    d = os.path.dirname(importlib.util.find_spec("lpips").origin)
    lins = torch.load(os.path.join(d, "weights", "v0.1", "alex.pth"), map_location="cpu")
    shift = torch.tensor([-0.030, -0.088, -0.188])[None, :, None, None]
    scale = torch.tensor([0.458, 0.448, 0.450])[None, :, None, None]

    def taps(x):
        h = (x.permute(2, 0, 1)[None] * 2 - 1 - shift) / scale
        out = []
        for i, layer in enumerate(feats):
            h = layer(h)
            if i in (1, 4, 7, 9, 11):
                out.append(h)
        return out

    total = 0.0
    for k, (fa, fb) in enumerate(zip(taps(a), taps(b))):
        na = fa / (fa.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
        nb = fb / (fb.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
        total = total + F.conv2d((na - nb) ** 2, lins[f"lin{k}.model.1.weight"]).mean()
    return float(total)


@needs_lpips
def test_lpips_loads_local_weights_and_matches_the_formula(tmp_path):
    path = tmp_path / "alexnet-random.pth"
    feats = _random_backbone(path)
    lp = losses.LPIPS(path)
    a, b = _images(2, 64, 64)
    assert abs(float(lp(a, a))) < 1e-7
    got = float(lp(a, b))
    with torch.no_grad():
        want = _lpips_by_hand(feats.eval(), a, b)
    assert got > 0 and abs(got - want) < 1e-5 * max(1.0, want)
    # another backbone gives another value: the file's weights are really used
    _random_backbone(tmp_path / "other.pth", seed=1)
    assert abs(float(losses.LPIPS(tmp_path / "other.pth")(a, b)) - got) > 1e-6


@needs_lpips
def test_lpips_weights_from_the_environment(tmp_path, monkeypatch):
    path = tmp_path / "w.pth"
    _random_backbone(path)
    monkeypatch.setenv(losses.LPIPS_ENV, str(path))
    assert losses.LPIPS().weights_path == path


def test_lpips_missing_weights_says_where_to_get_them(tmp_path, monkeypatch):
    monkeypatch.delenv(losses.LPIPS_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "torch"))
    with pytest.raises(losses.LPIPSUnavailable) as e:
        losses.LPIPS()
    msg = str(e.value)
    assert losses.ALEXNET_URL in msg and losses.LPIPS_ENV in msg
    assert str(tmp_path / "cache" / "warpgs" / "weights" / losses.ALEXNET_FILE) in msg
    with pytest.raises(losses.LPIPSUnavailable, match="no-such.pth"):
        losses.LPIPS(tmp_path / "no-such.pth")


@needs_lpips
def test_lpips_rejects_a_wrong_file(tmp_path):
    bad = tmp_path / "bad.pth"
    torch.save({"something.else": torch.zeros(1)}, bad)
    with pytest.raises(losses.LPIPSUnavailable, match="not a torchvision AlexNet"):
        losses.LPIPS(bad)
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(losses.LPIPSUnavailable, match="cannot read"):
        losses.LPIPS(junk)


def test_lpips_unavailable_message_fits_one_line(tmp_path):
    """The summary line says what is missing and how to get it, without the searched paths."""
    import pytest

    from warpgs import losses

    with pytest.raises(losses.LPIPSUnavailable) as e:
        losses.LPIPS(tmp_path / "none.pth")
    line = losses.one_line(e.value)
    assert "\n" not in line and "alexnet-owt-7be5be79.pth" in line and "download" in line
    assert "WARPGS_LPIPS_WEIGHTS" in line and len(line) < 120
    assert str(tmp_path) not in line and "looked at" not in line
