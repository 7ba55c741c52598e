"""``full.reliable_weight`` (warpgs/pipelines/full.py): a pseudo view's reliable pixels (U < delta, the warped inputs)
weigh that much in its L1 and D-SSIM, the others 1. Checked against the unweighted losses on regions, analytic
scalings, and a full run that keeps the maps through a checkpoint."""

import dataclasses

import pytest
import torch

from devices import DEVICES  # tests/devices.py: WARPGS_TEST_DEVICES restricts them
from warpgs import losses


def images(h=24, w=32, seed=0):
    g = torch.Generator().manual_seed(seed)
    a = torch.rand(h, w, 3, generator=g)
    b = (a + 0.2 * torch.rand(h, w, 3, generator=g)).clamp(0, 1)
    return a, b


@pytest.mark.parametrize("device", DEVICES)
def test_weight_one_gives_the_plain_l1_and_dssim(device):
    """On the CPU through kornia's SSIM, on CUDA through losses._ssim_map (the training path there)."""
    a, b = (x.to(device) for x in images())
    one = torch.ones(a.shape[:2], device=device)
    assert torch.allclose(losses.weighted_l1(a, b, one), losses.l1(a, b), rtol=1e-6)
    assert torch.allclose(losses.weighted_dssim(a, b, one), losses.dssim(a, b), rtol=1e-5, atol=1e-7)


def test_weighted_l1_is_the_area_weighted_sum_of_the_regions_l1():
    """Weights 5 on the left third and 1 elsewhere: the plain masked L1 of each region, times its weight and its share
    of the pixels, summed."""
    a, b = images()
    left = torch.zeros(a.shape[:2], dtype=torch.bool)
    left[:, :10] = True
    w = torch.where(left, 5.0, 1.0)
    share = left.float().mean()
    want = 5.0 * share * losses.l1(a, b, left) + (1 - share) * losses.l1(a, b, ~left)
    assert torch.allclose(losses.weighted_l1(a, b, w), want, rtol=1e-5)
    # within a mask (the bottom half) the same sum over its pixels, the masked L1's normalisation
    mask = torch.zeros_like(left)
    mask[12:] = True
    share = (left & mask).float().sum() / mask.float().sum()
    want = 5.0 * share * losses.l1(a, b, left & mask) + (1 - share) * losses.l1(a, b, ~left & mask)
    assert torch.allclose(losses.weighted_l1(a, b, w, mask), want, rtol=1e-5)
    assert torch.allclose(losses.weighted_l1(a, b, torch.ones_like(w), mask), losses.l1(a, b, mask), rtol=1e-6)


def test_weighted_dssim_gradient_scales_with_the_weight_where_the_weight_is_uniform():
    """Weight 3 everywhere is 3x the D-SSIM and 3x its gradient; weight 0 on a region leaves its pixels far from the
    rest without gradient (the SSIM window is 11 pixels)."""
    a, b = images(seed=1)
    p = a.clone().requires_grad_(True)
    losses.dssim(p, b).backward()
    g1 = p.grad.clone()
    p.grad = None
    three = torch.full(a.shape[:2], 3.0)
    val = losses.weighted_dssim(p, b, three)
    val.backward()
    assert torch.allclose(val, 3 * losses.dssim(a, b), rtol=1e-5)
    assert torch.allclose(p.grad, 3 * g1, rtol=1e-4, atol=1e-7)
    p.grad = None
    w = torch.ones(a.shape[:2])
    w[:, :12] = 0.0
    losses.weighted_dssim(p, b, w).backward()
    assert p.grad[:, :6].abs().max() == 0 and p.grad[:, 20:].abs().max() > 0


def test_a_full_run_weighs_the_reliable_pixels_and_a_resumed_run_keeps_the_maps(tmp_path):
    """With 5, each pseudo view has its map U < delta; the pseudo loss (its depth term aside) is the unweighted one
    when no pixel is reliable and 5x it when every pixel is. A state round trip brings the maps back."""
    from tiny_scene import small_full_trainer

    _, tr = small_full_trainer(tmp_path / "a", "--set", "full.reliable_weight=5.0", "--set", "full.depth_weight=0")
    tr.run()
    fm = tr.method
    cams = fm.pseudo_cams
    assert cams and set(fm.pseudo_reliable) == {c.name for c in cams}
    for c in cams:
        r = fm.pseudo_reliable[c.name]
        assert r.dtype == torch.bool and tuple(r.shape) == (c.height, c.width)
    cam = cams[0]
    out = tr.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=tr.background_for(cam))
    with torch.no_grad():
        none_reliable = fm.pseudo_loss(out, cam, torch.zeros_like(fm.pseudo_reliable[cam.name]))
        all_reliable = fm.pseudo_loss(out, cam, torch.ones_like(fm.pseudo_reliable[cam.name]))
        fm.settings = dataclasses.replace(fm.settings, reliable_weight=1.0)
        unweighted = fm.pseudo_loss(out, cam)
    assert torch.allclose(none_reliable, unweighted, rtol=1e-5)
    assert torch.allclose(all_reliable, 5 * unweighted, rtol=1e-5)
    fm.settings = dataclasses.replace(fm.settings, reliable_weight=5.0)
    _, again = small_full_trainer(tmp_path / "b", "--set", "full.reliable_weight=5.0")
    again.method.load_state_dict(fm.state_dict())
    assert again.method.pseudo_reliable.keys() == fm.pseudo_reliable.keys()
    assert all(torch.equal(again.method.pseudo_reliable[k].cpu(), fm.pseudo_reliable[k].cpu())
               for k in fm.pseudo_reliable)


def test_without_it_no_maps_are_kept(tmp_path):
    """At 1 (the default) the run keeps no maps: every pseudo view takes the unweighted losses."""
    from tiny_scene import small_full_trainer

    _, tr = small_full_trainer(tmp_path)
    tr.run()
    assert tr.method.pseudo_cams and tr.method.pseudo_reliable == {}


def test_a_weight_of_zero_is_named():
    from warpgs.config import FullConfig
    from warpgs.methods.full import check_settings

    with pytest.raises(ValueError, match="reliable_weight"):
        check_settings(FullConfig(reliable_weight=0.0))
