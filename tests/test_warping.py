"""Warped guidance and cross-view uncertainty (warpgs/kernels/warping.py via warpgs/pseudo/guidance.py).

References are independent: a plane's homography and its depth in closed form (numpy, float64), the
identity warp at an input's own pose, the ray-traced synthetic scene's ground-truth depth with a
numpy visibility test, and a Mann-Whitney ROC AUC written out in numpy.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

import warpgs.pseudo.guidance as guidance_mod
from warpgs.data import SyntheticConfig, generate_capture
from warpgs.pseudo.guidance import (
    PosedViews,
    UncertaintyConfig,
    effective_s1,
    guidance_and_uncertainty,
    uncertainty_map,
    warp_guidance,
)
from warpgs.render import rasterize


from devices import DEVICES  # noqa: E402 (tests/devices.py: WARPGS_TEST_DEVICES restricts them)


@pytest.fixture(params=DEVICES)
def device(request):
    return request.param


def t32(a, device="cpu"):
    return torch.as_tensor(np.asarray(a), dtype=torch.float32, device=device)


def views(V, K, images=None, depths=None, device="cpu") -> PosedViews:
    """PosedViews of float32 tensors on ``device`` from numpy arrays (None stays None)."""
    return PosedViews(*(None if a is None else t32(a, device) for a in (V, K, images, depths)))


# ----------------------------------------------------------------------------------------------
# a plane seen by two pinhole cameras, in closed form

H, W = 30, 40
K_DST = np.array([[38.0, 0, 20.3], [0, 36.0, 14.8], [0, 0, 1]])
K_SRC = np.array([[41.0, 0, 19.6], [0, 40.0, 15.5], [0, 0, 1]])
N_PLANE = np.array([0.15, -0.1, 1.0]) / np.linalg.norm([0.15, -0.1, 1.0])  # n . X = d in the dst camera
D_PLANE = 4.0
R_REL = Rotation.from_rotvec([0.02, -0.05, 0.03]).as_matrix()  # X_src = R X_dst + t
T_REL = np.array([0.25, -0.1, 0.15])
A_COLOR = np.array([[0.01, 0.004, 0.2], [-0.006, 0.012, 0.5], [0.003, -0.005, 0.6]])  # rgb = A @ (x, y, 1)


def _pixels(h, w):
    i, j = np.mgrid[0:h, 0:w]
    return np.stack([j + 0.5, i + 0.5, np.ones((h, w))], -1)


def _plane_depth(K, n, d):
    """z-depth of the plane n . X = d at every pixel centre of a camera with intrinsics K."""
    rays = _pixels(H, W) @ np.linalg.inv(K).T
    return d / (rays @ n)


def _plane_setup(src_depth_scale=1.0, t=T_REL):
    V_dst = np.eye(4)
    V_src = np.eye(4)
    V_src[:3, :3], V_src[:3, 3] = R_REL, t
    n_src = R_REL @ N_PLANE
    d_src = D_PLANE + n_src @ t
    depth_dst = _plane_depth(K_DST, N_PLANE, D_PLANE)
    depth_src = _plane_depth(K_SRC, n_src, d_src) * src_depth_scale
    img_src = _pixels(H, W) @ A_COLOR.T
    Hmat = K_SRC @ (R_REL + np.outer(t, N_PLANE) / D_PLANE) @ np.linalg.inv(K_DST)  # q ~ H p
    return V_dst, V_src, depth_dst, depth_src, img_src, Hmat


def _apply_h(Hmat, pts):
    q = pts @ Hmat.T
    return q[..., :2] / q[..., 2:3]


def test_plane_warp_matches_homography(device):
    V_dst, V_src, depth_dst, depth_src, img_src, Hmat = _plane_setup()
    g, q, valid = warp_guidance(views(V_src, K_SRC, images=img_src, device=device),
                                views(V_dst, K_DST, depths=depth_dst, device=device))
    q_ref = _apply_h(Hmat, _pixels(H, W))
    inside = (q_ref[..., 0] >= 0) & (q_ref[..., 1] >= 0) & (q_ref[..., 0] < W) & (q_ref[..., 1] < H)
    assert inside.mean() > 0.6 and (~inside).sum() > 20  # both cases occur
    q, valid, g = q.cpu().numpy(), valid.cpu().numpy(), g.cpu().numpy()
    assert np.array_equal(valid, inside)
    assert np.abs(q[inside] - q_ref[inside]).max() < 2e-3
    # an affine texture is reproduced exactly by bilinear sampling away from the clamped border
    interior = inside & (q_ref[..., 0] > 0.5) & (q_ref[..., 1] > 0.5) & (q_ref[..., 0] < W - 0.5) & (q_ref[..., 1] < H - 0.5)
    g_ref = np.concatenate([q_ref, np.ones((H, W, 1))], -1) @ A_COLOR.T
    assert np.abs(g[interior] - g_ref[interior]).max() < 1e-4
    assert np.all(g[~inside] == 0) and np.all(q[~inside] == -1)


def test_plane_round_trip_and_uncertainty_terms(device):
    V_dst, V_src, depth_dst, depth_src, img_src, Hmat = _plane_setup()
    src = views(V_src, K_SRC, img_src, depth_src, device)
    dst = views(V_dst, K_DST, np.zeros((H, W, 3)), depth_dst, device)
    r = guidance_and_uncertainty(src, dst, cfg=UncertaintyConfig(photometric=False, reference_width=None))
    v = r.valid.cpu().numpy()
    p = _pixels(H, W)[..., :2]
    q = _apply_h(Hmat, _pixels(H, W))
    interior = v & (q[..., 0] > 0.5) & (q[..., 1] > 0.5) & (q[..., 0] < W - 0.5) & (q[..., 1] < H - 0.5)
    # with the plane's true depth at both views the backward projection returns to p (inverse depth
    # interpolates exactly on a plane; at the border the clamped taps are off by a few 1e-3 px), so the
    # geometric term vanishes
    err = np.abs(r.reprojected.cpu().numpy() - p).max(-1)
    assert err[interior].max() < 1e-3 and err[v].max() < 1e-2
    assert r.uncertainty.cpu().numpy()[interior].max() < 1e-6
    assert np.all(r.uncertainty.cpu().numpy()[~v] == 1.0)
    # the photometric term alone: U = 1 - exp(-|I_gs - I_inp(q)|^2 / s2), |.| over RGB
    dst = dst._replace(images=r.guidance + torch.tensor([0.1, -0.2, 0.05], device=device))
    U, _ = uncertainty_map(r.coords, r.valid, src, dst, guidance=r.guidance,
                           cfg=UncertaintyConfig(geometric=False, s2=0.25))
    expected = 1 - np.exp(-(0.01 + 0.04 + 0.0025) / 0.25)
    assert np.allclose(U.cpu().numpy()[v], expected, atol=1e-6)
    # both terms add in the exponent
    U2, _ = uncertainty_map(r.coords, r.valid, src, dst, guidance=r.guidance,
                            cfg=UncertaintyConfig(s1=100.0, reference_width=None, s2=0.25))
    assert torch.allclose(U2, U, atol=1e-6)


def test_geometric_term_with_wrong_input_depth(device):
    """Input depth scaled by 2: p' moves along the epipolar line; compare with the closed form."""
    scale = 2.0
    V_dst, V_src, depth_dst, depth_src, img_src, Hmat = _plane_setup(src_depth_scale=scale)
    q_ref = _apply_h(Hmat, _pixels(H, W))
    z_true = _plane_depth(K_SRC, R_REL @ N_PLANE, D_PLANE + (R_REL @ N_PLANE) @ T_REL)
    # true depth at q on the plane, times the scale; back to the dst camera and project
    rays_q = np.concatenate([q_ref, np.ones((H, W, 1))], -1) @ np.linalg.inv(K_SRC).T
    n_src, d_src = R_REL @ N_PLANE, D_PLANE + (R_REL @ N_PLANE) @ T_REL
    Xs = rays_q * (scale * d_src / (rays_q @ n_src))[..., None]
    Xd = (Xs - T_REL) @ R_REL  # R^T (Xs - t)
    p2_ref = (Xd @ K_DST.T)[..., :2] / (Xd @ K_DST.T)[..., 2:3]
    r = guidance_and_uncertainty(views(V_src, K_SRC, img_src, depth_src, device),
                                 views(V_dst, K_DST, depths=depth_dst, device=device),
                                 cfg=UncertaintyConfig(photometric=False, s1=100.0, reference_width=None))
    ok = r.valid.cpu().numpy()
    ok &= (q_ref[..., 0] > 1) & (q_ref[..., 1] > 1) & (q_ref[..., 0] < W - 1) & (q_ref[..., 1] < H - 1)
    p2 = r.reprojected.cpu().numpy()
    assert np.abs(p2[ok] - p2_ref[ok]).max() < 5e-3
    e2 = ((p2_ref - _pixels(H, W)[..., :2]) ** 2).sum(-1)
    assert e2[ok].min() > 0.1 and np.median(e2[ok]) > 1.0  # a real error, not rounding
    assert np.allclose(r.uncertainty.cpu().numpy()[ok], 1 - np.exp(-e2[ok] / 100.0), atol=1e-4)
    assert z_true.min() > 0


def test_effective_s1_scales_with_width():
    cfg = UncertaintyConfig()
    assert effective_s1(cfg, 1024) == pytest.approx(100.0)
    assert effective_s1(cfg, 256) == pytest.approx(100.0 / 16)
    assert effective_s1(UncertaintyConfig(reference_width=None), 256) == 100.0


def test_missing_view_fields_are_named():
    V_dst, V_src, depth_dst, depth_src, img_src, _ = _plane_setup()
    src, dst = views(V_src, K_SRC, img_src, depth_src), views(V_dst, K_DST, depths=depth_dst)
    with pytest.raises(ValueError, match=r"src\.images"):
        warp_guidance(src._replace(images=None), dst)
    with pytest.raises(ValueError, match=r"dst\.depths"):
        warp_guidance(src, dst._replace(depths=None))
    with pytest.raises(ValueError, match=r"src\.depths"):
        guidance_and_uncertainty(src._replace(depths=None), dst, cfg=UncertaintyConfig(photometric=False))
    with pytest.raises(ValueError, match=r"dst\.images"):  # the photometric term compares with the renders
        guidance_and_uncertainty(src, dst)
    r = guidance_and_uncertainty(src, dst, cfg=UncertaintyConfig(photometric=False))
    assert r.uncertainty.shape == (H, W)


def test_no_depth_and_behind_camera_are_invalid(device):
    V_dst, V_src, depth_dst, depth_src, img_src, _ = _plane_setup()
    depth_dst = depth_dst.copy()
    depth_dst[:5] = 0.0  # nothing rendered there
    dst = views(V_dst, K_DST, np.zeros((H, W, 3)), depth_dst, device)
    r = guidance_and_uncertainty(views(V_src, K_SRC, img_src, depth_src, device), dst)
    assert not r.valid[:5].any() and torch.all(r.uncertainty[:5] == 1)
    V_back = np.diag([1.0, 1.0, -1.0, 1.0]) @ np.diag([-1.0, 1.0, 1.0, 1.0])  # camera turned around (rotation)
    r = guidance_and_uncertainty(views(V_back, K_SRC, img_src, depth_src, device), dst)
    assert not r.valid.any() and torch.all(r.uncertainty == 1)


def test_batched_frames_equal_single_calls(device):
    rng = np.random.default_rng(0)
    V_dst, V_src, depth_dst, depth_src, img_src, _ = _plane_setup()
    V_src2 = V_src.copy()
    V_src2[:3, 3] = [-0.2, 0.05, 0.1]
    n_src2 = R_REL @ N_PLANE
    depth_src2 = _plane_depth(K_SRC, n_src2, D_PLANE + n_src2 @ V_src2[:3, 3])
    src_img = np.stack([img_src, rng.random((H, W, 3))])
    src_dep = np.stack([depth_src, depth_src2])
    src_V = np.stack([V_src, V_src2])
    dst_V = np.stack([V_dst, V_dst, V_dst])
    dst_dep = np.stack([depth_dst, depth_dst * 1.1, depth_dst])
    renders = rng.random((3, H, W, 3))
    idx = [1, 0, 1]
    cfg = UncertaintyConfig()
    batch = guidance_and_uncertainty(views(src_V, K_SRC, src_img, src_dep, device),
                                     views(dst_V, K_DST, renders, dst_dep, device), idx, cfg=cfg)
    for f, s in enumerate(idx):
        one = guidance_and_uncertainty(views(src_V[s], K_SRC, src_img[s], src_dep[s], device),
                                       views(dst_V[f], K_DST, renders[f], dst_dep[f], device), cfg=cfg)
        for a, b in zip(batch, one):
            assert torch.equal(a[f], b)


def test_kernels_get_the_tensors_without_copies(monkeypatch):
    """float32 contiguous inputs and the outputs are handed to Warp by pointer (warpgs._warp.arg)."""
    seen = []
    real = guidance_mod.launch

    def spy(kernel, dim, inputs, device, stream=None):
        seen.append({getattr(a, "data", None) for a in inputs})
        real(kernel, dim, inputs, device, stream)

    monkeypatch.setattr(guidance_mod, "launch", spy)
    V_dst, V_src, depth_dst, depth_src, img_src, _ = _plane_setup()
    img, dd, ds = t32(img_src), t32(depth_dst), t32(depth_src)
    r = guidance_and_uncertainty(PosedViews(t32(V_src), t32(K_SRC), img, ds),
                                 PosedViews(t32(V_dst), t32(K_DST), torch.zeros(H, W, 3), dd))
    assert len(seen) == 2
    assert {img.data_ptr(), dd.data_ptr(), r.guidance.data_ptr(), r.coords.data_ptr()} <= seen[0]
    assert {ds.data_ptr(), r.uncertainty.data_ptr(), r.reprojected.data_ptr()} <= seen[1]


# ----------------------------------------------------------------------------------------------
# the synthetic scene with ground-truth depth


@pytest.fixture(scope="module")
def capture():
    return generate_capture(SyntheticConfig(seed=0, width=80, height=60, frames=24, samples_per_side=2), device="cpu")


def visible_from(cap, dst: int, depth_dst, src: int, tol=0.02):
    """numpy: pixels of view dst whose surface point view src sees (inside, in front, depth agrees)."""
    K = cap.K
    h, w = depth_dst.shape
    z = depth_dst.astype(np.float64)
    X = (_pix(h, w) @ np.linalg.inv(K).T) * z[..., None]
    c2w = np.linalg.inv(cap.viewmats[dst])
    Xw = X @ c2w[:3, :3].T + c2w[:3, 3]
    V = cap.viewmats[src]
    p = Xw @ V[:3, :3].T + V[:3, 3]
    uv = p @ K.T
    with np.errstate(all="ignore"):
        u, v = uv[..., 0] / uv[..., 2], uv[..., 1] / uv[..., 2]
    ok = (z > 0) & (p[..., 2] > 1e-3) & (u >= 0) & (v >= 0) & (u < w) & (v < h)
    ds = cap.depths[src][np.clip(v.astype(int), 0, h - 1), np.clip(u.astype(int), 0, w - 1)]
    return ok & (np.abs(ds - p[..., 2]) < tol * p[..., 2])


def _pix(h, w):
    i, j = np.mgrid[0:h, 0:w]
    return np.stack([j + 0.5, i + 0.5, np.ones((h, w))], -1)


def roc_auc(scores, labels):
    """Mann-Whitney U / (n_pos n_neg), ties counted one half (average ranks)."""
    scores = np.asarray(scores, np.float64)
    labels = np.asarray(labels, bool)
    order = np.argsort(scores, kind="mergesort")
    s = scores[order]
    ranks = np.empty(len(s))
    i = 0
    while i < len(s):
        j = i
        while j + 1 < len(s) and s[j + 1] == s[i]:
            j += 1
        ranks[order[i:j + 1]] = 0.5 * (i + j) + 1.0
        i = j + 1
    n_pos, n_neg = labels.sum(), (~labels).sum()
    return (ranks[labels].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg)


def test_roc_auc_reference():
    assert roc_auc([0.1, 0.2, 0.3, 0.4], [0, 0, 1, 1]) == 1.0
    assert roc_auc([0.4, 0.3, 0.2, 0.1], [0, 0, 1, 1]) == 0.0
    assert roc_auc([0.5, 0.5, 0.5, 0.5], [0, 1, 0, 1]) == 0.5
    assert roc_auc([0.1, 0.35, 0.4, 0.8], [0, 1, 0, 1]) == 0.75


def _splat_render(cap, src: int, dst: int):
    """A stand-in for a 3D-GS render: one small Gaussian per input pixel at its true depth, rasterized."""
    K = cap.K
    z = cap.depths[src]
    m = z > 0
    X = (_pix(*z.shape) @ np.linalg.inv(K).T * z[..., None])[m]
    c2w = np.linalg.inv(cap.viewmats[src])
    means = t32(X @ c2w[:3, :3].T + c2w[:3, 3])
    n = len(means)
    scales = t32(z[m] / K[0, 0])[:, None].repeat(1, 3)
    out = rasterize(means, torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1), scales, torch.full((n,), 0.8),
                    t32(cap.images[src][m]), t32(cap.viewmats[dst]), t32(K), z.shape[1], z.shape[0])
    return out.image


def test_identity_warp_reproduces_the_input(capture, device):
    cap = capture
    k = 5
    img, dep = t32(cap.images[k], device), t32(cap.depths[k], device)
    V, K = t32(cap.viewmats[k], device), t32(cap.K, device)
    same = PosedViews(V, K, img, dep)
    r = guidance_and_uncertainty(same, same)
    has = dep > 0
    assert torch.equal(r.valid, has)
    mse = float(((r.guidance - img) ** 2)[has].mean())
    psnr = 10 * np.log10(1.0 / max(mse, 1e-20))
    assert psnr >= 40.0, psnr
    assert float(r.uncertainty[has].max()) < 1e-3
    p = torch.as_tensor(_pix(*dep.shape)[..., :2], dtype=torch.float32, device=device)
    assert float((r.reprojected - p)[has].abs().max()) < 1e-3


def test_uncertainty_separates_corrupted_depth(capture):
    """Depth at the guidance pose is corrupted by +20% in a block; U should rank those pixels above the
    clean ones visible from the input (ROC AUC >= 0.9)."""
    cap = capture
    src, dst = 4, 6
    depth = cap.depths[dst]
    corrupt = np.zeros(depth.shape, bool)
    corrupt[15:45, 20:55] = True  # includes the image centre: forward motion's epipole, the hardest place
    bad = depth.copy()
    bad[corrupt] *= 1.2
    vis = visible_from(cap, dst, depth, src)
    render = _splat_render(cap, src, dst)
    inputs = views(cap.viewmats[src], cap.K, cap.images[src], cap.depths[src])
    frames = PosedViews(t32(cap.viewmats[dst]), t32(cap.K), render, t32(bad))
    aucs = {}
    for name, geo, pho in (("full", True, True), ("geometric", True, False), ("photometric", False, True)):
        U = guidance_and_uncertainty(inputs, frames, cfg=UncertaintyConfig(geometric=geo, photometric=pho))
        u = U.uncertainty.numpy()
        aucs[name] = roc_auc(u[vis], corrupt[vis])
    assert (corrupt & vis).sum() > 300 and (~corrupt & vis).sum() > 1000
    assert aucs["full"] >= 0.9, aucs
    assert aucs["geometric"] >= 0.9, aucs


def test_match_colour_recovers_each_sources_gain_and_offset_from_the_masked_pixels():
    """pseudo.trajectory.guidance_colour=affine: a warp whose colours are a per-channel gain and offset of the
    render's (one source input darker, the other with a colour cast) comes back to the render's colours, fitted on
    the mask only (pixels outside it, where the warp is wrong, do not bias the fit); a source with too few masked
    pixels is left as it is; the result stays in [0, 1]."""
    from warpgs.pseudo.guidance import match_colour

    g = torch.Generator().manual_seed(0)
    render = torch.rand(2, 16, 16, 3, generator=g) * 0.8 + 0.1
    sources = torch.zeros(2, 16, 16, dtype=torch.long)
    sources[:, :, 8:] = 1  # the right half of each frame warped from input 1
    gain = torch.tensor([[0.7, 0.7, 0.7], [1.2, 1.0, 0.8]])
    offset = torch.tensor([[0.05, 0.05, 0.05], [-0.02, 0.0, 0.06]])
    inv = (render - offset[sources]) / gain[sources]  # warp = (render - offset) / gain: the fit must undo it
    mask = torch.ones(2, 16, 16, dtype=torch.bool)
    mask[:, :4] = False
    warp = inv.clone()
    warp[:, :4] = 0.0  # wrong outside the mask: must not move the fit
    out = match_colour(warp, render, mask, sources, min_pixels=8)
    assert torch.allclose(out[:, 4:], render[:, 4:], atol=1e-5)
    assert out.min() >= 0 and out.max() <= 1
    few = mask.clone()
    few[1, :, 8:] = False
    few[1, 15, 15] = True  # one masked pixel of source 1 in frame 1: too few to fit
    kept = match_colour(warp, render, few, sources, min_pixels=8)
    assert torch.equal(kept[1, :, 8:], warp[1, :, 8:])
    assert torch.allclose(kept[1, 4:, :8], render[1, 4:, :8], atol=1e-5)
    # a gain beyond the allowed range is held at its bound
    flat = match_colour(render * 0.1, render, mask, None, min_pixels=8, gain_range=(0.5, 2.0))
    assert not torch.allclose(flat[:, 4:], render[:, 4:], atol=1e-2)


def test_affine_guidance_colour_changes_only_the_guidance(tmp_path):
    """generate_pseudo_views with guidance_colour=affine on a capture whose second input is darker: its guidance
    (the warped input where reliable) moves towards the render, the raw warp and the uncertainty stay the same."""
    from warpgs.data.scene import CameraTensors
    from warpgs.pseudo.views import PseudoConfig, generate_pseudo_views

    H = W = 24
    K = torch.tensor([[20.0, 0, 12], [0, 20.0, 12], [0, 0, 1]])
    yy, xx = torch.meshgrid(torch.linspace(0, 1, H), torch.linspace(0, 1, W), indexing="ij")
    tex = torch.stack([xx, yy, 0.5 * (xx + yy)], -1) * 0.8 + 0.1

    def pose(x):
        V = torch.eye(4)
        V[0, 3] = -x
        return V

    def render_fn(viewmat, K_, w, h):  # a fronto-parallel plane at depth 2 with the texture of the first input
        return tex.clone(), torch.full((h, w), 2.0)

    cams = [CameraTensors(name=f"{i}", viewmat=pose(0.05 * i), K=K, width=W, height=H,
                          image=(tex * (1.0 if i == 0 else 0.6)).clamp(0, 1)) for i in range(2)]
    raw = generate_pseudo_views(render_fn, cams, PseudoConfig.load(overrides=["trajectory.n_frames=5",
                                                                             "uncertainty.photometric=false"]))[0]
    aff = generate_pseudo_views(render_fn, cams, PseudoConfig.load(overrides=[
        "trajectory.n_frames=5", "uncertainty.photometric=false", "trajectory.guidance_colour=affine"]))[0]
    assert torch.equal(raw.warped, aff.warped) and torch.equal(raw.uncertainty, aff.uncertainty)
    rel = aff.uncertainty < 0.5
    assert rel.float().mean() > 0.3
    err_raw = ((raw.guidance - raw.renders) ** 2).mean(-1)[rel].mean()
    err_aff = ((aff.guidance - aff.renders) ** 2).mean(-1)[rel].mean()
    assert err_aff < 0.25 * err_raw
