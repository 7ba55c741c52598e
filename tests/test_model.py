"""GaussianModel: initialisation, activations, rendering."""

import math

import numpy as np
import pytest
import torch

from warpgs.model import SH_C0, GaussianModel, knn_mean_distance, rgb_to_sh, sh_to_rgb
from warpgs.render import rasterize


def test_knn_mean_distance_on_a_lattice():
    # unit grid: interior points have 6 neighbours at distance 1, so the 3 nearest are all at 1
    g = torch.stack(torch.meshgrid(*[torch.arange(5.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    d = knn_mean_distance(g, chunk_elems=1000)  # small chunks: several passes
    assert torch.allclose(d, torch.ones_like(d))
    # two points: each one's nearest is the other
    d2 = knn_mean_distance(torch.tensor([[0.0, 0, 0], [0.0, 3.0, 4.0]]))
    assert torch.allclose(d2, torch.tensor([5.0, 5.0]))


def test_from_points_parameters():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], np.float32)
    rgb = np.array([[255, 0, 0]] * 5, np.uint8)  # 8-bit colours are rescaled
    m = GaussianModel.from_points(pts, rgb, sh_degree=2, init_opacity=0.1, init_scale=0.5)
    assert len(m) == 5 and m.max_sh_degree == 2
    assert m.params["shN"].shape == (5, 8, 3) and bool((m.params["shN"] == 0).all())
    assert torch.allclose(m.opacities, torch.full((5,), 0.1))
    assert torch.allclose(m.quats, torch.tensor([1.0, 0, 0, 0]).expand(5, 4))
    # point 0's three nearest are at distance 1 -> scale 0.5 on every axis
    assert torch.allclose(m.scales[0], torch.full((3,), 0.5), atol=1e-6)
    assert torch.allclose(sh_to_rgb(m.params["sh0"][:, 0]), torch.tensor([1.0, 0, 0]).expand(5, 3), atol=1e-6)
    assert abs(float(rgb_to_sh(torch.tensor(0.5 + SH_C0)) - 1.0)) < 1e-6


def test_random_box_and_frustum_stay_inside():
    g = torch.Generator().manual_seed(0)
    m = GaussianModel.random_box(500, [-1, -2, -3], [1, 2, 3], generator=g)
    lo, hi = m.means.min(0).values, m.means.max(0).values
    assert bool((lo >= torch.tensor([-1.0, -2, -3])).all()) and bool((hi <= torch.tensor([1.0, 2, 3])).all())
    assert float(hi[2] - lo[2]) > 5.0  # spread over the box, not collapsed
    # frustum: every point projects inside its image at a depth in [near, far] for some camera
    V = np.eye(4, dtype=np.float32)
    K = np.array([[50, 0, 32], [0, 50, 24], [0, 0, 1]], np.float32)
    m = GaussianModel.random_frustum(400, [V], [K], [(64, 48)], 2.0, 6.0, generator=g)
    p = m.means.detach().numpy().astype(np.float64)
    z = p[:, 2]
    uv = p @ K.T.astype(np.float64)
    uv = uv[:, :2] / uv[:, 2:]
    assert z.min() >= 2.0 - 1e-5 and z.max() <= 6.0 + 1e-5
    assert (uv[:, 0] >= -1e-3).all() and (uv[:, 0] <= 64 + 1e-3).all()
    assert (uv[:, 1] >= -1e-3).all() and (uv[:, 1] <= 48 + 1e-3).all()


def test_random_hull_lies_inside_every_silhouette():
    """Silhouettes of a ball (radius 0.6) from three cameras that see the whole box: every initial point projects onto the ball's
    silhouette in each view, and the points fill the hull (they reach the ball's centre and its rim)."""
    from tiny_scene import look_at_c2w

    w = h = 40
    K = np.array([[40.0, 0, 20], [0, 40.0, 20], [0, 0, 1]])
    viewmats, alphas = [], []
    for eye in ((0, 0, -4.0), (4.0, 0, 0), (0, -4.0, 0.01)):
        V = np.linalg.inv(look_at_c2w(eye))
        # the ball's silhouette: pixels whose ray passes within 0.6 of the origin
        u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        rays = np.stack([(u - 20) / 40, (v - 20) / 40, np.ones_like(u)], -1)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        centre = V[:3, 3]  # the origin in camera coordinates
        dist = np.linalg.norm(np.cross(rays, centre), axis=-1)
        viewmats.append(V)
        alphas.append((dist < 0.6).astype(np.float32))
    g = torch.Generator().manual_seed(0)
    m = GaussianModel.random_hull(500, [-1.0] * 3, [1.0] * 3, viewmats, [K] * 3, alphas, dilate=0, generator=g)
    assert len(m) == 500
    pts = m.means.detach().numpy().astype(np.float64)
    for V, a in zip(viewmats, alphas):
        pc = pts @ V[:3, :3].T + V[:3, 3]
        uv = pc @ K.T
        u, v = np.floor(uv[:, 0] / uv[:, 2]).astype(int), np.floor(uv[:, 1] / uv[:, 2]).astype(int)
        assert (a[v, u] > 0.5).all()
    r = np.linalg.norm(pts, axis=1)
    assert r.max() < 0.6 * 1.5 and r.min() < 0.2 and r.max() > 0.55
    with pytest.raises(ValueError, match="no point"):
        GaussianModel.random_hull(10, [2.0] * 3, [3.0] * 3, viewmats, [K] * 3, alphas, generator=g)


def test_from_points_rejects_bad_input():
    with pytest.raises(ValueError, match="non-empty"):
        GaussianModel.from_points(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="NaN"):
        GaussianModel.from_points(np.array([[0, 0, np.nan], [1, 1, 1]]))
    with pytest.raises(ValueError, match="colors"):
        GaussianModel.from_points(np.zeros((3, 3)) + np.arange(3)[:, None], np.zeros((2, 3)))


def test_render_matches_rasterize_with_activations():
    g = torch.Generator().manual_seed(1)
    m = GaussianModel.random_box(60, [-1, -1, 3], [1, 1, 5], generator=g, sh_degree=1)
    with torch.no_grad():
        m.params["shN"].normal_(0, 0.2, generator=g)
        m.params["quats"].normal_(generator=g)
    m.active_sh_degree = 1
    V, K = torch.eye(4), torch.tensor([[40.0, 0, 24], [0, 40.0, 16], [0, 0, 1]])
    out = m.render(V, K, 48, 32, background=torch.ones(3))
    ref = rasterize(m.params["means"], m.params["quats"], torch.exp(m.params["scales"]),
                    torch.sigmoid(m.params["opacities"]),
                    torch.cat([m.params["sh0"], m.params["shN"]], 1), V, K, 48, 32, sh_degree=1,
                    background=torch.ones(3))
    assert torch.equal(out.image, ref.image)
    # gradients reach every raw parameter (explicit output gradients: see the next test)
    torch.autograd.backward([out.image, out.depth, out.alpha],
                            [torch.ones_like(out.image), torch.zeros_like(out.depth), torch.zeros_like(out.alpha)])
    for name, p in m.params.items():
        assert p.grad is not None and bool(torch.isfinite(p.grad).all()), name
    assert float(m.params["shN"].grad.abs().sum()) > 0


def test_render_degree_zero_ignores_higher_bands():
    g = torch.Generator().manual_seed(2)
    m = GaussianModel.random_box(30, [-1, -1, 3], [1, 1, 5], generator=g)
    V, K = torch.eye(4), torch.tensor([[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]])
    a = m.render(V, K, 32, 32, sh_degree=0).image
    with torch.no_grad():
        m.params["shN"].normal_(generator=g)
    b = m.render(V, K, 32, 32, sh_degree=0).image
    c = m.render(V, K, 32, 32, sh_degree=3).image
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    assert math.isclose(m.max_sh_degree, 3)


def test_backward_with_implicit_output_gradients_is_repeatable():
    """``image.sum().backward()`` hands the rasterizer an expanded colour gradient and no depth / alpha
    gradient; the result must equal the one with explicit dense gradients, every time. (Fails while
    warpgs/render.py passes temporaries to ``arg()`` that are freed before the kernel reads them.)"""
    V, K = torch.eye(4), torch.tensor([[40.0, 0, 24], [0, 40.0, 16], [0, 0, 1]])
    args = (torch.tensor([[1.0, 0, 0, 0]]), torch.full((1, 3), 0.5956), torch.tensor([0.1]),
            torch.tensor([[0.3, 0.6, 0.9]]), V, K, 48, 32)

    def grad(implicit: bool):
        means = torch.tensor([[-0.9111, -0.9508, 3.5177]], requires_grad=True)  # a large splat at a corner
        out = rasterize(means, *args)
        if implicit:
            out.image.sum().backward()
        else:
            torch.autograd.backward([out.image, out.depth, out.alpha], [torch.ones_like(out.image),
                                    torch.zeros_like(out.depth), torch.zeros_like(out.alpha)])
        return means.grad.clone()

    want = grad(False)
    for _ in range(4):
        assert torch.allclose(grad(True), want, rtol=1e-5, atol=1e-6)
