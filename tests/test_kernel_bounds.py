"""The kernels never index out of bounds, whatever the values (warpgs/kernels/projection.py's culling,
binning.tile_rect): Gaussians at 1e30, inf or NaN, with huge or non-finite scales, quaternions or opacities, and
cameras whose focal length or principal point no real camera has, rendered forward and backward in a child
process whose Warp is built in debug mode (every array access bounds-checked; its own kernel cache). The oracle is
the render of the finite Gaussians alone: adding the bad ones changes no pixel and no gradient of a good one, and
every bad one gets radius 0 and zero gradients. Plus the torch oracle at scale (tests/reference.py): more than 256
Gaussians on one tile and saturated pixels, forward and gradients."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import torch

import reference as ref
from test_rasterizer import assert_close, assert_grads_close, make_scene, run_ref, run_warp, weighted_loss

from devices import DEVICES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

CHILD = textwrap.dedent(
    r'''
    import math, os, sys
    # one core: the render's CPU parts run one after the other (a debug build crashed now and then with the two
    # parts on two threads at once; the bounds checks do not need them parallel)
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    import warp as wp
    wp.config.mode = "debug"
    wp.config.kernel_cache_dir = sys.argv[1]
    import torch
    from warpgs.render import rasterize

    torch.manual_seed(0)
    n = 12
    V = torch.eye(4)
    V[2, 3] = 3.0
    good = dict(means=(torch.rand(n, 3) - 0.5) * 1.2, quats=torch.randn(n, 4), scales=0.05 + 0.2 * torch.rand(n, 3),
                opacities=0.2 + 0.7 * torch.rand(n), colors=torch.rand(n, 3))
    BIG, INF, NAN = 1e30, math.inf, math.nan
    bad_rows = []  # (field, value) of one bad Gaussian each, appended after the good ones
    for v in (BIG, -BIG, INF, -INF, NAN, 1e8, -1e8):  # far off screen, behind the camera or past the far plane
        bad_rows += [("means", (v, 0.1, 0.0)), ("means", (0.0, v, 0.0))]
    for v in (BIG, -BIG, INF, -INF, NAN, -1e8):
        bad_rows += [("means", (0.0, 0.0, v))]
    for v in (BIG, -BIG, INF, -INF, NAN):  # a covariance that overflows float32
        bad_rows += [("scales", (v, 0.1, 0.1)), ("scales", (0.1, 0.1, v))]
    for v in (INF, -INF, NAN):
        bad_rows += [("quats", (v, 0.0, 0.0, 0.0)), ("quats", (1.0, v, 0.0, 0.0)), ("opacities", v)]
    bad_rows += [("means", (1e-30, 1e-30, -3.0 + 1e-12))]  # at the camera centre
    def batch(rows):
        ins = {k: v.clone() for k, v in good.items()}
        for field, value in rows:
            row = good[field][:1].clone()
            row[0] = torch.tensor(value)
            for k in ins:
                ins[k] = torch.cat([ins[k], good[k][:1] if k != field else row])
        return ins
    cams = {"ordinary": (60.0, 60.0, 32.0, 24.0)}
    for name, v in (("fx 1e30", (1e30, 60.0, 32.0, 24.0)), ("fx 1e-30", (1e-30, 60.0, 32.0, 24.0)),
                    ("cx 1e30", (60.0, 60.0, 1e30, 24.0)), ("cx -1e9", (60.0, 60.0, -1e9, 24.0)),
                    ("cy 1e7", (60.0, 60.0, 32.0, 1e7)), ("cx inf", (60.0, 60.0, INF, 24.0)),
                    ("fy nan", (60.0, NAN, 32.0, 24.0)), ("fx -60", (-60.0, 60.0, 32.0, 24.0))):
        cams[name] = v
    W, H = 64, 48
    failures = []
    def render(ins, K):
        leaves = {k: v.clone().requires_grad_(True) for k, v in ins.items()}
        out = rasterize(**leaves, viewmat=V, K=K, width=W, height=H, check_finite=False)
        (out.image.sum() + 0.1 * out.depth.sum() + out.alpha.sum()).backward()
        return out, {k: v.grad for k, v in leaves.items()}
    for cam, (fx, fy, cx, cy) in cams.items():
        K = torch.tensor([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        ref_out, ref_grads = render(good, K)
        ins = batch(bad_rows)
        out, grads = render(ins, K)
        # Through the ordinary camera every bad Gaussian is culled, and the render is that of the good ones, bit
        # for bit. Through an impossible camera some "bad" ones may land on screen (fx = 1e-30 brings x = 1e30 in):
        # there everything stays finite and every culled Gaussian's gradient is 0.
        ordinary = cam == "ordinary"
        for what, a, b in (("image", out.image, ref_out.image), ("depth", out.depth, ref_out.depth),
                           ("alpha", out.alpha, ref_out.alpha)):
            if ordinary and not torch.equal(a, b):
                failures.append(f"{cam}: {what} changed by the bad Gaussians")
            if not bool(torch.isfinite(a).all()):
                failures.append(f"{cam}: {what} not finite")
        if ordinary and not float(ref_out.alpha.detach().max()) > 0.3:
            failures.append("the ordinary camera renders nothing: the case tests nothing")
        culled = (out.radii == 0).all(dim=1)
        if ordinary and not bool(culled[n:].all()):
            failures.append(f"{cam}: a bad Gaussian kept a radius: {out.radii[n:].tolist()}")
        for k, g in grads.items():
            if ordinary and not torch.equal(g[:n], ref_grads[k]):
                failures.append(f"{cam}: d/d{k} of a good Gaussian changed")
            if not bool((g[culled] == 0).all()):
                failures.append(f"{cam}: d/d{k} of a culled Gaussian is not 0")
            if not bool(torch.isfinite(g).all()):
                failures.append(f"{cam}: d/d{k} not finite")
        print(cam, "intersections", out.n_intersections, flush=True)
    # A finite Gaussian whose radius passes the int32 range (scale 1e8: about 7e9 px) covers the image like one of
    # radius 7e6 px (scale 1e5): the conic is ~0 either way, so alpha is its opacity on every pixel.
    K = torch.tensor([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])
    renders = []
    for s in (1e8, 1e5):
        ins = {k: v.clone() for k, v in good.items()}
        ins["scales"][0] = s
        ins["opacities"][0] = 0.5
        renders.append(render(ins, K)[0])
    if not int(renders[0].radii[0].min()) >= 8388608 or not torch.equal(renders[0].image, renders[1].image):
        failures.append(f"radius past int32: radii {renders[0].radii[0].tolist()}, images differ")
    print("\n".join(failures) if failures else "ALL OK")
    '''
)


def test_bad_values_render_under_warp_bounds_checks(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, str(script), str(tmp_path / "kernels")], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=1500)
    tail = (proc.stdout + proc.stderr)[-3000:]
    assert proc.returncode == 0, tail
    assert proc.stdout.strip().endswith("ALL OK"), tail


# ----------------------------------------------------------------------------------------------------
# the torch oracle at scale


@pytest.mark.parametrize("device", DEVICES)
def test_more_than_256_gaussians_per_tile_and_saturated_pixels_match_the_reference(device):
    """300 Gaussians spread over a 20 x 18 image (every one on the tile of the centre, so the CUDA loop over
    256-Gaussian batches runs twice there), low opacities so that the centre saturates (transmittance below 1e-4
    stops the pixel) while the borders do not: image, depth, alpha and every input's gradient against the oracle."""
    scene = make_scene(n=300, width=20, height=18, seed=31, spread=0.35, scale_range=(0.08, 0.3),
                       opacity_range=(0.05, 0.25))
    (img, depth, alpha, m2), rins = run_ref(scene, grad=True)
    _, _, _, _, radii = ref.project(*(scene[k] for k in ("means", "quats", "scales", "opacities", "viewmat", "K")),
                                    scene["width"], scene["height"])
    centre = ref.tile_mask(m2, radii, scene["width"], scene["height"])[:, 9, 10]
    assert int(centre.sum()) > 256, "the case tests nothing: fewer than 257 Gaussians on the centre's tile"
    T = 1.0 - alpha.detach()
    assert float(T.min()) < 2e-4 and float(T.max()) > 1e-2, "the case tests nothing: no saturated pixel, or all"
    out, ins = run_warp(scene, device, grad=True)
    assert_close(out.image, img, 2e-5, what="image")
    assert_close(out.alpha, alpha, 2e-5, what="alpha")
    assert_close(out.depth, depth, 2e-5, rtol=2e-5, what="depth")
    weighted_loss(out.image, out.depth, out.alpha).backward()
    weighted_loss(img, depth, alpha).backward()
    assert_grads_close(ins, rins, 5e-4, 2e-3)
