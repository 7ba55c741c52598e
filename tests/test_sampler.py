"""The uncertainty-modulated sampler on toy backends whose x0 is known, the default backend's exact
Gaussian denoiser, and the default backend's pseudo views on the synthetic scene with true depth."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from warpgs.pseudo.backends import DefaultBackendConfig, GaussianVideoBackend, dct_matrix
from warpgs.pseudo.sampler import (
    SamplerConfig,
    blend_weights,
    euler_step,
    fuse,
    guidance_stop,
    guidance_weights,
    karras_sigmas,
    pool_uncertainty,
    sample_video,
)


class ToyBackend:
    """Latents = frames [N, 3, H/f, W/f] (average-pooled by f); x0 from a user function."""

    default_noise_scale = 1.0

    def __init__(self, x0_fn, sigmas, factor=1, mean=0.0):
        self.x0_fn, self._sigmas, self.f, self.mean = x0_fn, torch.as_tensor(sigmas, dtype=torch.float32), factor, mean
        self.calls = []

    def sigmas(self, steps, device):
        assert len(self._sigmas) == steps + 1
        return self._sigmas

    def init_noise_sigma(self, sigmas):
        return float(sigmas[0])

    def prior_mean(self, cond):
        return self.mean

    def latent_shape(self, h, w):
        return 3, h // self.f, w // self.f

    def encode(self, frames):
        return torch.nn.functional.avg_pool2d(frames.permute(0, 3, 1, 2), self.f)

    def decode(self, latents, size):
        return torch.nn.functional.interpolate(latents, size=size, mode="nearest").permute(0, 2, 3, 1)

    def condition(self, image, n, prior=None, generator=None):
        return float(image.mean())

    def denoise(self, x, sigma, cond):
        self.calls.append((sigma, cond))
        return self.x0_fn(x, sigma, cond)


def test_karras_sigmas():
    s = karras_sigmas(10, 0.002, 80.0)
    assert s.shape == (11,) and s[-1] == 0 and s[0] == pytest.approx(80.0) and s[-2] == pytest.approx(0.002)
    assert torch.all(s[1:] < s[:-1])
    rho = 7.0
    i = 4
    ref = (80.0 ** (1 / rho) + i / 9 * (0.002 ** (1 / rho) - 80.0 ** (1 / rho))) ** rho
    assert float(s[i]) == pytest.approx(ref, rel=1e-6)


def test_equations():
    x, x0 = torch.tensor([2.0]), torch.tensor([0.5])
    assert float(euler_step(x, x0, 3.0, 1.0)) == pytest.approx(2.0 + (2.0 - 0.5) / 3.0 * (1.0 - 3.0))
    assert float(euler_step(x, x0, 3.0, 0.0)) == pytest.approx(0.5)  # to sigma 0: lands on x0_hat
    g, gam = torch.tensor([1.5]), torch.tensor([4.0])
    assert float(fuse(x0, g, gam)) == pytest.approx((0.5 + 4 * 1.5) / 5)
    # fusion is the minimiser of |x - x0|^2 + gamma |x - g|^2
    xs = torch.linspace(-1, 3, 40001)
    assert float(xs[torch.argmin((xs - 0.5) ** 2 + 4 * (xs - 1.5) ** 2)]) == pytest.approx(float(fuse(x0, g, gam)), abs=1e-4)
    U = torch.tensor([0.0, 0.1, 0.49, 0.5, 0.9])
    assert torch.allclose(guidance_weights(U, 0.5, 1e-3), torch.tensor([1 / 1e-3, 1 / 0.101, 1 / 0.491, 0.0, 0.0]))
    assert blend_weights(5).tolist() == [1.0, 0.75, 0.5, 0.25, 0.0]
    Um = torch.tensor([[[0.0, 1.0], [1.0, 0.0]], [[1.0, 1.0], [1.0, 1.0]]])  # means 0.5 and 1
    assert torch.allclose(guidance_stop(Um, 0.2, 0.1), torch.tensor([0.2, 0.3]))
    # SYN3R's curve: u = mean / max(max U, 0.5)
    u = torch.tensor([0.5, 1.0])
    assert torch.allclose(guidance_stop(Um, 0, 0, "syn3r"), -0.157 * u**2 + 0.377 * u + 0.2)


def test_pooling_to_latent_resolution():
    U = torch.zeros(1, 4, 4)
    U[0, :2, :2] = torch.tensor([[0.0, 0.2], [0.4, 0.6]])
    U[0, 2:, 2:] = 1.0
    pooled = pool_uncertainty(U, (2, 2))
    assert torch.allclose(pooled[0, 0], torch.tensor([[0.3, 0.0], [0.0, 1.0]]))


def test_one_step_fusion_per_pixel_and_thresholds():
    """One Euler step to sigma 0 returns the fused x0: (x0_hat + gamma g)/(1 + gamma) with gamma from
    the pooled U (0 where U >= delta), on frames whose tau has not passed."""
    N, H, W = 3, 4, 4
    c = 0.3
    be = ToyBackend(lambda x, s, cond: torch.full_like(x, c), [5.0, 0.0], factor=2)
    g = torch.rand(N, H, W, 3, generator=torch.Generator().manual_seed(0))
    U = torch.zeros(N, H, W)
    U[:, :2, :2] = 0.2  # pooled block (0, 0): 0.2
    U[:, :2, 2:] = 0.7  # above delta: unguided
    U[:, 2:, :2] = torch.tensor([[0.0, 0.2], [0.4, 0.6]])  # pools to 0.3
    U[2] = 1.0  # a frame with no reliable pixel
    cfg = SamplerConfig(steps=1, bidirectional=False, k=0.0, b=0.5)  # t_0 = 1 > tau = 0.5: guidance on
    out = sample_video(be, torch.zeros(H, W, 3), guidance=g, uncertainty=U, cfg=cfg)
    g_lat = torch.nn.functional.avg_pool2d(g.permute(0, 3, 1, 2), 2)
    Up = torch.tensor([[0.2, 0.7], [0.3, 0.0]])
    gam = torch.where(Up < 0.5, 1 / (Up + 1e-3), torch.zeros(()))
    for f in range(2):
        expected = (c + gam * g_lat[f]) / (1 + gam)
        assert torch.allclose(out.latents[f], expected, atol=1e-6)
    assert torch.allclose(out.latents[2], torch.full_like(out.latents[2], c))
    assert out.guided_steps.tolist() == [1, 1, 0]
    # tau past the first step: no fusion at all
    late = sample_video(be, torch.zeros(H, W, 3), guidance=g, uncertainty=U,
                        cfg=SamplerConfig(steps=1, bidirectional=False, k=0.0, b=1.0))
    assert torch.allclose(late.latents, torch.full_like(late.latents, c))


def test_guidance_stops_at_tau_per_frame():
    steps = 10
    be = ToyBackend(lambda x, s, cond: torch.zeros_like(x), karras_sigmas(steps, 0.01, 10.0))
    N, H, W = 4, 2, 2
    U = torch.stack([torch.full((H, W), u) for u in (0.0, 0.1, 0.3, 0.45)])
    cfg = SamplerConfig(steps=steps, bidirectional=False, k=1.0, b=0.15)
    out = sample_video(be, torch.zeros(H, W, 3), guidance=torch.ones(N, H, W, 3), uncertainty=U, cfg=cfg)
    tau = 1.0 * U.mean((1, 2)) + 0.15
    expected = [sum(1 for i in range(steps) if 1 - i / steps > float(t)) for t in tau]
    assert out.guided_steps.tolist() == expected
    assert expected == [9, 8, 6, 4]


def test_gaussian_toy_matches_the_probability_flow_solution():
    """x0 ~ N(mu, s^2) per element: the optimal denoiser is mu + s^2/(s^2 + sigma^2)(x - mu) and the
    probability-flow ODE from sigma_max maps x_T to mu + (x_T - mu) s / sqrt(s^2 + sigma_max^2) at 0.
    Euler is first order: the error to that solution halves when the steps double."""
    mu, s2, smax = 0.3, 0.2**2, 20.0
    N, H, W = 2, 8, 8
    noise = torch.randn(N, 3, H, W, generator=torch.Generator().manual_seed(0))
    exact = mu + smax * noise * math.sqrt(s2) / math.sqrt(s2 + smax**2)
    errors = {}
    for steps in (100, 200, 400):
        be = ToyBackend(lambda x, s, cond: mu + s2 / (s2 + s * s) * (x - mu), karras_sigmas(steps, 0.002, smax), mean=mu)
        out = sample_video(be, torch.zeros(H, W, 3), n_frames=N, noise=noise,
                           cfg=SamplerConfig(steps=steps, bidirectional=False, guided=False))
        errors[steps] = float((out.latents - exact).abs().max())
    assert 1.8 < errors[100] / errors[200] < 2.2 and 1.8 < errors[200] / errors[400] < 2.2, errors
    assert errors[400] < 0.03 * math.sqrt(s2), errors
    assert float(out.latents.std()) == pytest.approx(math.sqrt(s2), rel=0.15)


def test_gaussian_toy_guided_pixels_converge_to_guidance():
    mu, s2 = 0.3, 0.2**2
    steps = 60
    sig = karras_sigmas(steps, 0.002, 20.0)
    be = ToyBackend(lambda x, s, cond: mu + s2 / (s2 + s * s) * (x - mu), sig, mean=mu)
    N, H, W = 2, 6, 6
    g = torch.rand(N, H, W, 3, generator=torch.Generator().manual_seed(1))
    U = torch.zeros(N, H, W)
    U[:, :, 3:] = 0.8
    noise = torch.randn(N, 3, H, W, generator=torch.Generator().manual_seed(2))
    common = dict(n_frames=N, noise=noise)
    guided = sample_video(be, torch.zeros(H, W, 3), guidance=g, uncertainty=U,
                          cfg=SamplerConfig(steps=steps, bidirectional=False, b=-1.0, k=0.0), **common)
    free = sample_video(be, torch.zeros(H, W, 3), cfg=SamplerConfig(steps=steps, bidirectional=False, guided=False),
                        **common)
    gl = g.permute(0, 3, 1, 2)
    assert torch.allclose(guided.latents[..., :3], gl[..., :3], atol=1e-3)  # U = 0: onto the guidance
    assert torch.equal(guided.latents[..., 3:], free.latents[..., 3:])  # U > delta: untouched, per pixel
    assert (free.latents[..., :3] - gl[..., :3]).abs().mean() > 0.05


def test_bidirectional_blend():
    """Denoiser x0 = (value of the pass's condition) + (frame index in the pass's order): one step to
    sigma 0 gives beta_i (A + i) + (1 - beta_i)(B + N - 1 - i)."""
    N, H, W = 5, 2, 2
    be = ToyBackend(lambda x, s, cond: cond + torch.arange(x.shape[0], dtype=x.dtype).view(-1, 1, 1, 1)
                    .expand_as(x), [3.0, 0.0])
    A, B = 10.0, 100.0
    out = sample_video(be, torch.full((H, W, 3), A), torch.full((H, W, 3), B), n_frames=N,
                       cfg=SamplerConfig(steps=1, guided=False))
    i = torch.arange(N, dtype=torch.float32)
    beta = (N - 1 - i) / (N - 1)
    expected = beta * (A + i) + (1 - beta) * (B + (N - 1 - i))
    assert torch.allclose(out.latents[:, 0, 0, 0], expected)
    assert sorted(c for _, c in be.calls) == [A, B]
    with pytest.raises(ValueError):
        sample_video(be, torch.zeros(H, W, 3), n_frames=N, cfg=SamplerConfig(steps=1))  # no end image


def test_bidirectional_state_is_shared_between_passes():
    """Two steps: the backward pass continues from the blended state, reversed."""
    N, H, W = 3, 1, 1
    seen = []

    def x0(x, s, cond):
        seen.append((s, cond, x[:, 0, 0, 0].clone()))
        return torch.full_like(x, cond)

    be = ToyBackend(x0, [4.0, 2.0, 0.0])
    noise = torch.tensor([1.0, 2.0, 3.0]).view(N, 1, 1, 1).expand(N, 3, 1, 1).contiguous()
    sample_video(be, torch.zeros(H, W, 3), torch.ones(H, W, 3), n_frames=N, noise=noise,
                 cfg=SamplerConfig(steps=2, guided=False))
    x = noise[:, 0, 0, 0] * 4.0
    assert torch.allclose(seen[0][2], x) and torch.allclose(seen[1][2], x.flip(0))
    beta = torch.tensor([1.0, 0.5, 0.0])
    fwd = euler_step(x, torch.zeros(N), 4.0, 2.0)
    bwd = euler_step(x.flip(0), torch.ones(N), 4.0, 2.0)
    blended = beta * fwd + (1 - beta) * bwd.flip(0)
    assert torch.allclose(seen[2][2], blended) and torch.allclose(seen[3][2], blended.flip(0))


def test_pin_end_frames():
    N, H, W = 4, 2, 2
    be = ToyBackend(lambda x, s, cond: torch.zeros_like(x), [2.0, 1.0, 0.0])
    out = sample_video(be, torch.full((H, W, 3), 0.25), torch.full((H, W, 3), 0.75), n_frames=N,
                       cfg=SamplerConfig(steps=2, guided=False, pin_end_frames=True, eps=1e-6))
    assert torch.allclose(out.latents[0], torch.full((3, H, W), 0.25), atol=1e-5)
    assert torch.allclose(out.latents[-1], torch.full((3, H, W), 0.75), atol=1e-5)
    assert torch.allclose(out.latents[1:-1], torch.zeros(2, 3, H, W))


# ----------------------------------------------------------------------------------------------
# the default backend


def test_dct_is_orthonormal():
    D = dct_matrix(7)
    assert torch.allclose(D @ D.T, torch.eye(7, dtype=D.dtype), atol=1e-12)


def test_default_backend_denoiser_is_the_exact_mmse():
    """x0_hat = m + C (C + sigma^2 I)^-1 (x - m) with C the prior covariance, built explicitly."""
    be = GaussianVideoBackend(DefaultBackendConfig(prior_std=0.2, detail_std=0.05, length=0.3, length_frames=1.5))
    n, h, w = 3, 4, 5
    Dt, Dy, Dx = (dct_matrix(k) for k in (n, h, w))
    S = be.spectrum(n, h, w, "cpu")[:, 0].double()  # [n, h, w]
    D = torch.kron(torch.kron(Dt, Dy), Dx)  # coefficient index (t, y, x), row-major
    C = D.T @ torch.diag(S.reshape(-1)) @ D
    g = torch.Generator().manual_seed(0)
    m = torch.rand(n, 3, h, w, generator=g)
    x = m + 0.3 * torch.randn(n, 3, h, w, generator=g)
    sigma = 0.17
    ours = be.denoise(x, sigma, m)
    A = C @ torch.linalg.inv(C + sigma**2 * torch.eye(n * h * w, dtype=C.dtype))
    r = (x - m).double().permute(1, 0, 2, 3).reshape(3, -1)  # per channel, (t, y, x) flattened
    ref = m.double() + (r @ A.T).reshape(3, n, h, w).permute(1, 0, 2, 3)
    assert torch.allclose(ours.double(), ref, atol=1e-5)
    # mean variance per pixel is prior_std^2 + detail_std^2
    assert float(torch.diag(C).mean()) == pytest.approx(0.2**2 + 0.05**2, rel=1e-6)


def test_default_backend_condition_and_mean():
    be = GaussianVideoBackend()
    prior = torch.rand(4, 3, 5, 3)
    img = torch.zeros(3, 5, 3)
    m = be.condition(img, 4, prior)
    assert torch.equal(m[0], img.permute(2, 0, 1)) and torch.equal(m[1:], prior[1:].permute(0, 3, 1, 2))
    assert torch.equal(be.prior_mean(m), m)
    # without guidance and noise, one pass's deterministic path stays on the prior mean
    out = sample_video(be, img, prior=prior, cfg=SamplerConfig(steps=8, bidirectional=False))
    assert torch.allclose(out.frames, m.permute(0, 2, 3, 1), atol=1e-6)


# ----------------------------------------------------------------------------------------------
# default-backend pseudo views on the synthetic scene (ground-truth depth)


def _pix(h, w):
    i, j = np.mgrid[0:h, 0:w]
    return np.stack([j + 0.5, i + 0.5, np.ones((h, w))], -1)


def _visible(cap, depth, V_dst, src_ids, tol=0.02):
    """numpy: pixels whose true surface point one of the inputs sees (inside, in front, depth agrees)."""
    K = cap.K
    h, w = depth.shape
    X = _pix(h, w) @ np.linalg.inv(K).T * depth[..., None].astype(np.float64)
    c2w = np.linalg.inv(V_dst)
    Xw = X @ c2w[:3, :3].T + c2w[:3, 3]
    vis = np.zeros((h, w), bool)
    for s in src_ids:
        V = cap.viewmats[s]
        p = Xw @ V[:3, :3].T + V[:3, 3]
        uv = p @ K.T
        with np.errstate(all="ignore"):
            u, v = uv[..., 0] / uv[..., 2], uv[..., 1] / uv[..., 2]
        ok = (depth > 0) & (p[..., 2] > 1e-3) & (u >= 0) & (v >= 0) & (u < w) & (v < h)
        ds = cap.depths[s][np.clip(v.astype(int), 0, h - 1), np.clip(u.astype(int), 0, w - 1)]
        vis |= ok & (np.abs(ds - p[..., 2]) < tol * p[..., 2])
    return vis


def _stand_in_model():
    """Frames 4, 7, 10 of the ray-traced walk as inputs, and a stand-in "3D-GS": one small Gaussian per input pixel
    at its true depth, rasterized (colour I_gs); depth everywhere is the ray-traced truth -> (cap, ids, inputs,
    render_fn, input depths)."""
    from warpgs.data import SyntheticConfig, generate_capture
    from warpgs.data.scene import Camera
    from warpgs.data.synthetic import render_views
    from warpgs.render import rasterize

    cap = generate_capture(SyntheticConfig(seed=0, width=80, height=60, frames=24, samples_per_side=2), device="cpu")
    ids = [4, 7, 10]
    h, w = cap.depths.shape[1:]
    inputs = [Camera(f"in{i}", cap.viewmats[i].astype(np.float32), cap.K.astype(np.float32), w, h, cap.images[i],
                     depth=cap.depths[i]) for i in ids]
    means, colors, scales = [], [], []
    for i in ids:
        z = cap.depths[i]
        m = z > 0
        X = (_pix(h, w) @ np.linalg.inv(cap.K).T * z[..., None])[m]
        c2w = np.linalg.inv(cap.viewmats[i])
        means.append(X @ c2w[:3, :3].T + c2w[:3, 3])
        colors.append(cap.images[i][m])
        scales.append(z[m] / cap.K[0, 0])
    t = lambda a: torch.tensor(np.concatenate(a), dtype=torch.float32)  # noqa: E731
    n = sum(len(a) for a in means)
    gauss = (t(means), torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1), t(scales)[:, None].repeat(1, 3),
             torch.full((n,), 0.8), t(colors))

    def render_fn(viewmat, K, width, height):
        image = rasterize(*gauss, viewmat.float(), K.float(), width, height, check_finite=False).image
        _, depth = render_views(cap.world, viewmat.double().numpy()[None], K.double().numpy(), width, height, 1, "cpu")
        return image, torch.from_numpy(depth[0])

    return cap, ids, inputs, render_fn, [torch.from_numpy(c.depth) for c in inputs]


def _visible_psnr(cap, ids, seqs, w, h):
    """PSNR of the pseudo views' interior frames and of the renders there against ray-traced ground truth, on the
    pixels one of the trajectory's two inputs sees."""
    from warpgs.data.synthetic import render_views

    se = se_render = count = 0.0
    for s in seqs:
        V = s.viewmats.double().numpy()
        gt, gt_depth = render_views(cap.world, V, cap.K, w, h, 2, "cpu")
        for i in range(1, len(s) - 1):
            vis = _visible(cap, gt_depth[i], V[i], [ids[s.start], ids[s.end]])
            se += float((((s.frames[i].numpy() - gt[i]) ** 2).mean(-1))[vis].sum())
            se_render += float((((s.renders[i].numpy() - gt[i]) ** 2).mean(-1))[vis].sum())
            count += vis.sum()
    return 10 * np.log10(count / se), 10 * np.log10(count / se_render)


def test_default_backend_pseudo_views_on_the_synthetic_scene(tmp_path):
    """Pseudo views at the interpolated poses between the stand-in's inputs (``_stand_in_model``) are compared
    with ray-traced ground truth on pixels that an input of the trajectory sees."""
    from warpgs.pseudo.views import PseudoConfig, generate_pseudo_views

    cap, ids, inputs, render_fn, depths_in = _stand_in_model()
    h, w = cap.depths.shape[1:]
    results = {}
    for guided in (True, False):
        cfg = PseudoConfig.load(overrides=["trajectory.n_frames=9", "sampler.steps=20",
                                           f"sampler.guided={str(guided).lower()}"])
        seqs = generate_pseudo_views(render_fn, inputs, cfg, input_depths=depths_in,
                                     out_dir=tmp_path / "pseudo" if guided else None)
        results[guided] = _visible_psnr(cap, ids, seqs, w, h)
    (psnr_guided, psnr_render), (psnr_unguided, _) = results[True], results[False]
    print(f"\ndefault backend, visible pixels: guided {psnr_guided:.2f} dB, unguided {psnr_unguided:.2f} dB, "
          f"3D-GS stand-in render {psnr_render:.2f} dB")
    assert psnr_guided >= 25.0, results
    assert psnr_guided > psnr_unguided + 1.0, results
    # the saved images are there and readable
    from PIL import Image

    d = tmp_path / "pseudo" / "seq_000_001"
    for kind in ("pseudo", "guidance", "warped", "uncertainty", "render"):
        im = np.asarray(Image.open(d / f"{kind}_004.png"))
        assert im.shape[:2] == (h, w)
    assert (d / "poses.npz").is_file()


def test_offset_paths_give_pseudo_views_off_the_path_that_match_the_truth(tmp_path):
    """``trajectory.offsets``: copies of the path moved up and down. Their pseudo views, at poses no input or path
    frame has, are compared with ray-traced ground truth as above: guided they are good and better than unguided
    sampling; each copy lies at its offset from the path (an offset of 0, the path itself, adds none); names and saved
    folders of the copies are their own."""
    from warpgs.pseudo.views import PseudoConfig, generate_pseudo_views

    cap, ids, inputs, render_fn, depths_in = _stand_in_model()
    h, w = cap.depths.shape[1:]
    results, seqs = {}, None
    for guided in (True, False):
        cfg = PseudoConfig.load(overrides=["trajectory.n_frames=7", "sampler.steps=20", "trajectory.offsets=[-0.3, 0, 0.3]",
                                           f"sampler.guided={str(guided).lower()}"])
        seqs = generate_pseudo_views(render_fn, inputs, cfg, input_depths=depths_in,
                                     out_dir=tmp_path / "pseudo" if guided else None)
        assert [s.offset for s in seqs] == [0.0] * 2 + [-0.3] * 2 + [0.3] * 2
        results[guided] = _visible_psnr(cap, ids, [s for s in seqs if s.offset != 0], w, h)
    (psnr_guided, _), (psnr_unguided, _) = results[True], results[False]
    print(f"\noff the path, visible pixels: guided {psnr_guided:.2f} dB, unguided {psnr_unguided:.2f} dB")
    assert psnr_guided >= 24.0, results
    assert psnr_guided > psnr_unguided + 1.0, results
    on, up = seqs[0], seqs[4]
    chord = float((on.viewmats[-1, :3, :3].T @ on.viewmats[-1, :3, 3] - on.viewmats[0, :3, :3].T @ on.viewmats[0, :3, 3]).norm())
    centres = lambda v: -(v[:, :3, :3].transpose(1, 2) @ v[:, :3, 3:])[..., 0]  # noqa: E731
    assert torch.allclose((centres(up.viewmats) - centres(on.viewmats)).norm(dim=1), torch.tensor(0.3 * chord), rtol=1e-3)
    names = [c.name for s in seqs for c in s.pseudo_cameras()]
    assert len(names) == len(set(names)) == 6 * 5
    assert {p.name for p in (tmp_path / "pseudo").iterdir()} == {
        "seq_000_001", "seq_001_002", "seq_o-0.3_000_001", "seq_o-0.3_001_002", "seq_o+0.3_000_001", "seq_o+0.3_001_002"}


def test_pseudo_config_file_and_overrides(tmp_path):
    from warpgs.pseudo.views import PseudoConfig

    cfg = PseudoConfig.load()
    assert (cfg.uncertainty.s1, cfg.uncertainty.s2, cfg.sampler.delta) == (100.0, 0.25, 0.5)
    assert cfg.trajectory.n_frames == 25 and cfg.backend == "auto"
    cfg = PseudoConfig.load(overrides=["sampler.steps=7", "svd.path=/x", "uncertainty.reference_width=null"])
    assert cfg.sampler.steps == 7 and cfg.svd.path == "/x" and cfg.uncertainty.reference_width is None
    with pytest.raises(ValueError, match="valid"):
        PseudoConfig.load(overrides=["sampler.stepz=7"])
    with pytest.raises(ValueError):
        PseudoConfig.load(overrides=["sampler.steps=seven"])
    bad = tmp_path / "bad.yaml"
    bad.write_text("trajectory:\n  n_frame: 3\n")
    with pytest.raises(ValueError, match="n_frame"):
        PseudoConfig.load(bad)
    with pytest.raises(ValueError, match="not found"):  # a missing file is named, not skipped
        PseudoConfig.load(tmp_path / "none.yaml")
