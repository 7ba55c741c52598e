"""The Warp rasterizer against the slow torch oracle (tests/reference.py), finite differences and
analytic facts. Runs on the CPU, and on CUDA too when a GPU is present."""

import math

import pytest
import torch

import reference as ref
from warpgs.kernels.rasterize import tile_size_for
from warpgs.render import eval_sh, means2d_grad_norm, rasterize

from devices import DEVICES  # noqa: E402 (tests/devices.py: WARPGS_TEST_DEVICES restricts them)


def look_at_viewmat(eye, target, up=(0.0, -1.0, 0.0)):
    """World-to-camera matrix (OpenCV axes) of a camera at ``eye`` looking at ``target``."""
    eye, target, up = (torch.tensor(v, dtype=torch.float64) for v in (eye, target, up))
    z = target - eye
    z = z / z.norm()
    x = torch.linalg.cross(up, z)
    x = x / x.norm()
    y = torch.linalg.cross(z, x)
    R = torch.stack([x, y, z])
    V = torch.eye(4, dtype=torch.float64)
    V[:3, :3] = R
    V[:3, 3] = -R @ eye
    return V


def make_scene(n=10, width=40, height=28, seed=0, sh_degree=None, scale_range=(0.03, 0.25), spread=0.7,
               opacity_range=(0.1, 0.95)):
    g = torch.Generator().manual_seed(seed)
    V = look_at_viewmat((0.3, -0.2, -3.0), (0.0, 0.0, 0.0))
    means = (torch.rand(n, 3, generator=g, dtype=torch.float64) - 0.5) * 2 * spread
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    lo, hi = scale_range
    scales = lo + (hi - lo) * torch.rand(n, 3, generator=g, dtype=torch.float64)
    lo, hi = opacity_range
    opacities = lo + (hi - lo) * torch.rand(n, generator=g, dtype=torch.float64)
    if sh_degree is None:
        colors = torch.rand(n, 3, generator=g, dtype=torch.float64)
    else:
        colors = 0.3 * torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g, dtype=torch.float64)
        colors[:, 0] += 0.8
    f = 0.9 * width
    K = torch.tensor([[f, 0, width / 2 + 0.7], [0, f * 1.05, height / 2 - 0.4], [0, 0, 1]], dtype=torch.float64)
    return dict(means=means, quats=quats, scales=scales, opacities=opacities, colors=colors, viewmat=V, K=K,
                width=width, height=height)


def run_warp(scene, device, grad=False, **kw):
    names = ["means", "quats", "scales", "opacities", "colors"]
    ins = {k: scene[k].float().to(device).requires_grad_(grad) for k in names}
    out = rasterize(**ins, viewmat=scene["viewmat"].float().to(device), K=scene["K"].float().to(device),
                    width=scene["width"], height=scene["height"], **kw)
    return out, ins


def run_ref(scene, grad=False, **kw):
    names = ["means", "quats", "scales", "opacities", "colors"]
    ins = {k: scene[k].clone().requires_grad_(grad) for k in names}
    kw = dict(kw)
    if "near_plane" in kw:
        kw["near"] = kw.pop("near_plane")
    if kw.get("background") is not None:
        kw["background"] = kw["background"].double()
    out = ref.render(**ins, viewmat=scene["viewmat"], K=scene["K"], width=scene["width"], height=scene["height"], **kw)
    return out, ins


def assert_close(a, b, atol, rtol=0.0, what=""):
    a = a.detach().double().cpu()
    b = b.detach().double().cpu()
    err = (a - b).abs()
    bound = atol + rtol * b.abs()
    assert bool((err <= bound).all()), f"{what}: max abs error {err.max().item():.3g} (worst excess {(err - bound).max().item():.3g})"


def assert_grads_close(ins, rins, atol_of_max, rtol):
    """Every input's gradient against the oracle's, within ``atol_of_max`` times the largest reference value."""
    for name in ins:
        g, gr = ins[name].grad, rins[name].grad
        scale = float(gr.abs().max())
        assert scale > 0, f"reference gradient of {name} is zero: the case tests nothing"
        assert_close(g, gr, atol_of_max * scale, rtol=rtol, what=f"d/d{name}")


# ----------------------------------------------------------------------------------------------------
# forward


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(
    "case",
    [
        dict(seed=0),
        dict(seed=1, n=25, background=(0.2, 0.5, 0.9)),
        dict(seed=2, antialiased=True),
        dict(seed=3, alpha_max=0.999, n=30, scale_range=(0.1, 0.5)),
        dict(seed=4, sh_degree=0),
        dict(seed=5, sh_degree=1),
        dict(seed=6, sh_degree=2),
        dict(seed=7, sh_degree=3, width=35, height=33),
        # DropGaussian's survivors (opacity x 1 / (1 - p)) and opacity noise exceed 1: pairs past SIGMA_SKIP whose
        # alpha is still >= 1/255 are skipped by both passes (a forward that composited them while its backward did
        # not: without the rule 673 pixels here differ by up to 0.008). alpha_max 0.999: at 0.99 many alphas hit the
        # clamp, and T = 0.01 x 0.01 lands on T_MIN itself, where float32 and the float64 reference round apart
        dict(seed=8, n=30, opacity_range=(1.0, 1.6), scale_range=(0.1, 0.4), alpha_max=0.999),
    ],
)
def test_forward_matches_reference(device, case):
    case = dict(case)
    kw = {k: case.pop(k) for k in ("antialiased", "alpha_max") if k in case}
    if "background" in case:
        kw["background"] = torch.tensor(case.pop("background"))
    scene = make_scene(**case)
    if case.get("sh_degree") is not None:
        kw["sh_degree"] = case["sh_degree"]
    out, _ = run_warp(scene, device, **{k: (v.to(device) if torch.is_tensor(v) else v) for k, v in kw.items()})
    (img, depth, alpha, m2), _ = run_ref(scene, **kw)
    assert out.n_intersections > 0
    assert_close(out.image, img, 1e-5, what="image")
    assert_close(out.alpha, alpha, 1e-5, what="alpha")
    assert_close(out.depth, depth, 1e-5, rtol=1e-5, what="depth")
    assert_close(out.means2d, m2, 1e-4, rtol=1e-6, what="means2d")
    # the render is not trivially the background
    assert float(alpha.max()) > 0.5


# ----------------------------------------------------------------------------------------------------
# gradients


def weighted_loss(image, depth, alpha, seed=123):
    g = torch.Generator().manual_seed(seed)
    h, w = alpha.shape
    wi = torch.rand(h, w, 3, generator=g, dtype=torch.float64).to(image.device, image.dtype)
    wd = torch.rand(h, w, generator=g, dtype=torch.float64).to(image.device, image.dtype)
    wa = torch.rand(h, w, generator=g, dtype=torch.float64).to(image.device, image.dtype)
    return (image * wi).sum() + 0.3 * (depth * wd).sum() + (alpha * wa).sum()


GRAD_CASES = [
    dict(seed=10),
    dict(seed=11, antialiased=True),
    dict(seed=12, sh_degree=3),
    dict(seed=13, sh_degree=1, background=(0.3, 0.1, 0.7), n=20),
    dict(seed=14, n=20, opacity_range=(0.9, 1.6), scale_range=(0.1, 0.4), alpha_max=0.999),  # opacities above 1
]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("case", GRAD_CASES)
def test_gradients_match_reference_autograd(device, case):
    case = dict(case)
    kw = {k: case.pop(k) for k in ("antialiased", "alpha_max") if k in case}
    if "background" in case:
        kw["background"] = torch.tensor(case.pop("background"))
    scene = make_scene(**case)
    if case.get("sh_degree") is not None:
        kw["sh_degree"] = case["sh_degree"]
    out, ins = run_warp(scene, device, grad=True, **{k: (v.to(device) if torch.is_tensor(v) else v) for k, v in kw.items()})
    weighted_loss(out.image, out.depth, out.alpha).backward()
    (img, depth, alpha, m2), rins = run_ref(scene, grad=True, **kw)
    m2.retain_grad()
    weighted_loss(img, depth, alpha).backward()
    assert_grads_close(ins, rins, 2e-4, 1e-3)
    assert_close(out.means2d.grad, m2.grad, 2e-4 * float(m2.grad.abs().max()), rtol=1e-3, what="d/dmeans2d")
    norm = means2d_grad_norm(out, scene["width"], scene["height"])
    expect = (m2.grad * torch.tensor([scene["width"] / 2, scene["height"] / 2], dtype=torch.float64)).norm(dim=-1)
    assert_close(norm, expect, 1e-3 * float(expect.max()), rtol=1e-3, what="means2d grad norm")


@pytest.mark.parametrize("device", DEVICES)
def test_fixed_point_gradients_match_reference_and_repeat_exactly(device):
    """The deterministic (fixed-point) backward: the oracle's gradients, and bit-identical on a rerun."""
    scene = make_scene(n=40, seed=21, sh_degree=2, width=48, height=40)
    grads = []
    for _ in range(2):
        out, ins = run_warp(scene, device, grad=True, sh_degree=2, deterministic="fixed")
        weighted_loss(out.image, out.depth, out.alpha).backward()
        grads.append({k: v.grad.detach().clone() for k, v in ins.items()})
    (img, depth, alpha, _m2), rins = run_ref(scene, grad=True, sh_degree=2)
    weighted_loss(img, depth, alpha).backward()
    for name in rins:
        gr = rins[name].grad
        assert_close(grads[0][name], gr, 2e-4 * float(gr.abs().max()), rtol=1e-3, what=f"fixed-point d/d{name}")
        assert torch.equal(grads[0][name], grads[1][name]), f"d/d{name} differs between two identical runs"


def test_reference_gradients_match_finite_differences():
    """The oracle itself: torch.autograd.gradcheck in float64 on a tiny smooth case."""
    scene = make_scene(n=4, width=18, height=17, seed=21, sh_degree=2, scale_range=(0.15, 0.3), spread=0.3)

    def f(means, quats, scales, opacities, colors):
        img, depth, alpha, _ = ref.render(means, quats, scales, opacities, colors, scene["viewmat"], scene["K"],
                                          scene["width"], scene["height"], sh_degree=2, antialiased=True)
        return weighted_loss(img, depth, alpha)

    ins = tuple(scene[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors"))
    assert torch.autograd.gradcheck(f, ins, eps=1e-6, atol=1e-4, rtol=1e-3)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("sh_degree", [None, 3])
def test_kernel_gradients_match_finite_differences(device, sh_degree):
    """Directional derivatives of the Warp forward (central differences, float32) against its backward.

    The render is only piecewise smooth (a pixel drops a Gaussian where its alpha falls below 1/255), so
    a direction is used only where differences at h and 2h agree, i.e. no cut-off lies within 2h; each
    parameter needs two such directions. The loss uses accumulated depth (depth * alpha): expected depth
    jumps where a pixel's alpha leaves 0."""
    scene = make_scene(n=6, width=24, height=20, seed=31, sh_degree=sh_degree, scale_range=(0.12, 0.3), spread=0.35)
    kw = dict(sh_degree=sh_degree, antialiased=True)
    out, ins = run_warp(scene, device, grad=True, **kw)
    weighted_loss(out.image, out.depth * out.alpha, out.alpha).backward()

    def loss_at(name, delta):
        pert = {k: t.detach().cpu().double() for k, t in ins.items()}
        pert[name] = pert[name] + delta
        o, _ = run_warp(dict(scene, **pert), device, **kw)
        return float(weighted_loss(o.image.double(), (o.depth * o.alpha).double(), o.alpha.double()))

    g = torch.Generator().manual_seed(5)
    h = 1e-4
    noise = 0.05  # float32 rounding of a ~500-pixel loss, divided by 2h
    for name in ins:
        used = 0
        for _ in range(8):
            v = torch.randn(ins[name].shape, generator=g, dtype=torch.float64)
            v = v / v.norm()
            fd1 = (loss_at(name, h * v) - loss_at(name, -h * v)) / (2 * h)
            fd2 = (loss_at(name, 2 * h * v) - loss_at(name, -2 * h * v)) / (4 * h)
            if abs(fd1 - fd2) > noise + 0.01 * abs(fd1):
                continue  # a cut-off lies within 2h along v
            an = float((ins[name].grad.cpu().double() * v).sum())
            assert abs(fd1 - an) <= noise + 0.01 * abs(an), f"d/d{name}: finite difference {fd1:.5g} vs backward {an:.5g}"
            used += 1
            if used == 2:
                break
        assert used == 2, f"d/d{name}: no smooth direction found"


# ----------------------------------------------------------------------------------------------------
# edge cases


@pytest.mark.parametrize("device", DEVICES)
def test_gaussians_behind_camera_render_background_and_get_zero_gradients(device):
    scene = make_scene(n=8, seed=40)
    V = scene["viewmat"]
    cam_pos = -(V[:3, :3].T @ V[:3, 3])
    forward = V[2, :3]
    scene["means"] = cam_pos - 2.0 * forward + 0.1 * torch.randn(8, 3, dtype=torch.float64)
    bg = torch.tensor([0.25, 0.5, 0.75], device=device)
    out, ins = run_warp(scene, device, grad=True, background=bg)
    assert out.n_intersections == 0
    assert bool((out.radii == 0).all())
    assert_close(out.image, bg.expand_as(out.image), 0.0, what="image")
    assert float(out.alpha.abs().max()) == 0.0
    weighted_loss(out.image, out.depth, out.alpha).backward()
    for name, t in ins.items():
        assert float(t.grad.abs().max()) == 0.0, name


@pytest.mark.parametrize("device", DEVICES)
def test_all_offscreen(device):
    scene = make_scene(n=8, seed=41)
    scene["means"] = scene["means"] + torch.tensor([30.0, 0.0, 0.0], dtype=torch.float64)
    out, ins = run_warp(scene, device, grad=True)
    assert out.n_intersections == 0 and float(out.alpha.max()) == 0.0
    out.image.sum().backward()
    assert float(ins["means"].grad.abs().max()) == 0.0


@pytest.mark.parametrize("device", DEVICES)
def test_zero_gaussians(device):
    scene = make_scene(n=0, seed=42)
    bg = torch.tensor([0.1, 0.2, 0.3], device=device)
    out, ins = run_warp(scene, device, grad=True, background=bg)
    assert out.image.shape == (scene["height"], scene["width"], 3)
    assert_close(out.image, bg.expand_as(out.image), 0.0, what="image")
    out.image.sum().backward()
    assert ins["means"].grad.shape == (0, 3)


@pytest.mark.parametrize("device", DEVICES)
def test_one_gaussian_covering_the_whole_image(device):
    scene = make_scene(n=1, seed=43, width=48, height=40)
    scene["means"] = torch.zeros(1, 3, dtype=torch.float64)
    scene["scales"] = torch.tensor([[3.0, 2.0, 1.4]], dtype=torch.float64)
    scene["opacities"] = torch.tensor([0.95], dtype=torch.float64)
    out, ins = run_warp(scene, device, grad=True)
    (img, depth, alpha, _), rins = run_ref(scene, grad=True)
    assert float(out.alpha.min()) > 0.5  # every pixel is covered
    ts = tile_size_for(device)  # one intersection per tile of the device's tiling
    assert out.n_intersections == math.ceil(48 / ts) * math.ceil(40 / ts)
    assert_close(out.image, img, 1e-5, what="image")
    weighted_loss(out.image, out.depth, out.alpha).backward()
    weighted_loss(img, depth, alpha).backward()
    for name in ins:
        assert_close(ins[name].grad, rins[name].grad, 1e-4 * float(rins[name].grad.abs().max()) + 1e-7,
                     rtol=1e-3, what=name)


@pytest.mark.parametrize("device", DEVICES)
def test_zero_scales_are_finite_and_match_reference(device):
    scene = make_scene(n=6, seed=44)
    scene["scales"][:3] = 0.0
    out, ins = run_warp(scene, device, grad=True)
    (img, depth, alpha, _), _ = run_ref(scene)
    assert_close(out.image, img, 1e-5, what="image")
    weighted_loss(out.image, out.depth, out.alpha).backward()
    for name, t in ins.items():
        assert bool(torch.isfinite(t.grad).all()), name
    # with antialiasing a zero-area Gaussian has zero effective opacity and vanishes
    out_aa, _ = run_warp(scene, device, antialiased=True)
    assert bool((out_aa.radii[:3] == 0).all())


@pytest.mark.parametrize("device", DEVICES)
def test_unnormalised_quaternions(device):
    scene = make_scene(n=10, seed=45)
    scene["quats"] = scene["quats"] / scene["quats"].norm(dim=-1, keepdim=True)
    base, _ = run_warp(scene, device)
    scaled = dict(scene, quats=scene["quats"] * torch.linspace(0.2, 7.0, 10, dtype=torch.float64)[:, None])
    out, ins = run_warp(scaled, device, grad=True)
    assert_close(out.image, base.image, 2e-6, what="image")
    weighted_loss(out.image, out.depth, out.alpha).backward()
    # the loss does not change along q itself, so its gradient is orthogonal to q
    radial = (ins["quats"].grad * ins["quats"].detach()).sum(-1)
    assert float(radial.abs().max()) < 1e-4 * float(ins["quats"].grad.abs().max() * 7.0)


@pytest.mark.parametrize("device", DEVICES)
def test_sh_basis_is_orthonormal(device):
    """Monte Carlo over the sphere: (1/4pi) integral Y_k Y_l = delta_kl / (4 pi), via the Warp SH kernel."""
    g = torch.Generator().manual_seed(0)
    dirs = torch.randn(200_000, 3, generator=g).to(device)
    ys = []
    for k in range(16):
        coeffs = torch.zeros(dirs.shape[0], 16, 3, device=device)
        coeffs[:, k, 0] = 0.5  # 0.5 Y + 0.5 stays >= 0, so the clamp never acts
        ys.append(2.0 * (eval_sh(coeffs, dirs, 3)[:, 0] - 0.5))
    Y = torch.stack(ys, 1).double().cpu()
    gram = 4 * math.pi * (Y.T @ Y) / dirs.shape[0]
    assert_close(gram, torch.eye(16, dtype=torch.float64), 0.03, what="SH Gram matrix")


# ----------------------------------------------------------------------------------------------------
# bad inputs


@pytest.mark.parametrize(
    "name,mutate,message",
    [
        ("means", lambda s: s["means"].__setitem__((0, 0), float("nan")), "means"),
        ("scales", lambda s: s["scales"].__setitem__((1, 2), float("inf")), "scales"),
        ("opacities", lambda s: s["opacities"].__setitem__(2, float("nan")), "opacities"),
        ("colors", lambda s: s["colors"].__setitem__((0, 1), float("-inf")), "colors"),
        ("viewmat", lambda s: s["viewmat"].__setitem__((0, 3), float("nan")), "viewmat"),
    ],
)
def test_non_finite_inputs_name_the_argument(name, mutate, message):
    scene = make_scene(n=5, seed=50)
    mutate(scene)
    with pytest.raises(ValueError, match=f"'{message}'.*NaN or Inf"):
        run_warp(scene, "cpu")


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("quats", torch.ones(5, 3), "'quats' must have shape \\[5, 4\\]"),
        ("means", torch.ones(5, 2), "'means' must have shape"),
        ("opacities", torch.ones(5, 1), "'opacities' must have shape \\[5\\]"),
        ("colors", torch.ones(4, 3), "'colors' must have shape \\[5, 3\\]"),
        ("viewmat", torch.eye(3), "'viewmat' must have shape \\[4, 4\\]"),
        ("K", torch.eye(4), "'K' must have shape \\[3, 3\\]"),
        ("scales", -torch.ones(5, 3), "'scales' must be >= 0"),
        ("quats", torch.zeros(5, 4), "'quats' contains a zero quaternion"),
        ("means", torch.ones(5, 3, dtype=torch.int64), "'means' must be a floating-point"),
    ],
)
def test_malformed_inputs_name_the_argument(field, value, message):
    scene = make_scene(n=5, seed=51)
    args = dict(means=scene["means"].float(), quats=scene["quats"].float(), scales=scene["scales"].float(),
                opacities=scene["opacities"].float(), colors=scene["colors"].float(), viewmat=scene["viewmat"].float(),
                K=scene["K"].float(), width=scene["width"], height=scene["height"])
    args[field] = value
    with pytest.raises(ValueError, match=message):
        rasterize(**args)


def test_bad_sizes_and_sh_degree():
    s = make_scene(n=3, seed=52)
    base = dict(means=s["means"].float(), quats=s["quats"].float(), scales=s["scales"].float(),
                opacities=s["opacities"].float(), viewmat=s["viewmat"].float(), K=s["K"].float())
    with pytest.raises(ValueError, match="'width' must be a positive int"):
        rasterize(**base, colors=s["colors"].float(), width=0, height=8)
    with pytest.raises(ValueError, match="'sh_degree' must be 0, 1, 2 or 3"):
        rasterize(**base, colors=torch.zeros(3, 25, 3), width=8, height=8, sh_degree=4)
    with pytest.raises(ValueError, match="'colors' needs at least 16 SH coefficients"):
        rasterize(**base, colors=torch.zeros(3, 9, 3), width=8, height=8, sh_degree=3)


def test_cpu_row_kernels_match_the_per_pixel_kernels(monkeypatch):
    """The CPU composites a tile row per thread (``rasterize_*_cpu``); the per-pixel kernels (the CUDA
    kernels' logic without shared memory) must give the same images, bit for bit, and the same gradients up
    to the order of float additions. Edges: a width and height that are no multiple of the tile, saturated
    pixels (many opaque Gaussians), a coloured background."""
    import warpgs.kernels.rasterize as kr
    import warpgs.kernels.rasterize_cpu as krc

    scene = make_scene(n=400, width=45, height=29, seed=7, scale_range=(0.05, 0.3), spread=0.9)
    scene["opacities"] = 0.5 + 0.49 * torch.rand(400, generator=torch.Generator().manual_seed(8), dtype=torch.float64)
    bg = torch.tensor([0.2, 0.5, 0.9])
    w = torch.rand(29, 45, 3, generator=torch.Generator().manual_seed(9))

    def render():
        out, ins = run_warp(scene, "cpu", grad=True, background=bg)
        ((out.image * w).sum() + out.depth.sum() * 0.1 + out.alpha.sum() * 0.3).backward()
        return out, {k: v.grad.clone() for k, v in ins.items()}

    rows, g_rows = render()
    assert float(rows.alpha.max()) > 0.999  # some pixels saturate (T <= 1e-4)
    monkeypatch.setattr(krc, "rasterize_fwd_cpu", kr.rasterize_fwd)
    monkeypatch.setattr(krc, "rasterize_bwd_cpu", kr.rasterize_bwd)
    monkeypatch.setattr(kr, "compositing_threads", lambda device, n_tiles: n_tiles * kr.TILE_SIZE_CPU ** 2)
    pixels, g_pixels = render()
    for name in ("image", "depth", "alpha"):
        assert torch.equal(getattr(rows, name), getattr(pixels, name)), name
    for k in g_rows:
        assert_close(g_rows[k], g_pixels[k], atol=1e-6, rtol=1e-4, what=f"d/d{k}")


@pytest.mark.parametrize("deterministic", [True, "fixed"])
def test_backward_without_the_depth_equals_a_zero_depth_weight(deterministic):
    """A loss that leaves the depth out gets None for its gradient and the backward kernel skips the depth
    terms (``with_depth`` = 0); the gradients must be those of the same loss plus 0 x depth (which runs the
    depth terms with dL/ddepth = 0), bit for bit, through the float and the fixed-point sums."""
    scene = make_scene(n=300, width=37, height=21, seed=3, scale_range=(0.05, 0.3), spread=0.9)
    w = torch.rand(21, 37, 3, generator=torch.Generator().manual_seed(4))
    grads = []
    for depth_weight in (None, 0.0):
        out, ins = run_warp(scene, "cpu", grad=True, deterministic=deterministic)
        loss = (out.image * w).sum() + 0.3 * out.alpha.sum()
        if depth_weight is not None:
            loss = loss + depth_weight * out.depth.sum()
        loss.backward()
        grads.append({k: v.grad.clone() for k, v in ins.items()})
    assert all(torch.equal(grads[0][k], grads[1][k]) for k in grads[0])
    assert all(float(g.abs().sum()) > 0 for g in grads[0].values())


@pytest.mark.parametrize("device", DEVICES)
def test_fixed_capacity_render_is_the_counted_one_bit_for_bit(device):
    """``rasterize(isect_capacity=...)`` (buffers of a fixed size, padded with keys past the grid, torch's
    stable sort; what a CUDA graph of a training step holds) gives the image, depth, alpha and every gradient
    of the render that counts its intersections on the host, bit for bit; ``count_intersections`` is that
    count, and a capacity of exactly the count works as well as a larger one."""
    from warpgs.render import count_intersections

    scene = make_scene(n=200, width=45, height=31, seed=8, sh_degree=2, scale_range=(0.03, 0.3), spread=0.9)
    w = torch.rand(31, 45, 3, generator=torch.Generator().manual_seed(1)).to(device)
    results = []
    for capacity in (None, "exact", "more"):
        kw = dict(sh_degree=2, background=torch.tensor([0.1, 0.4, 0.7], device=device))
        if capacity is not None:
            s = {k: scene[k].float().to(device) for k in ("means", "quats", "scales", "opacities", "viewmat", "K")}
            count = count_intersections(s["means"], s["quats"], s["scales"], s["opacities"], s["viewmat"], s["K"],
                                        scene["width"], scene["height"])
            assert count == results[0][0].n_intersections > 0
            kw["isect_capacity"] = count if capacity == "exact" else 3 * count + 17
        out, ins = run_warp(scene, device, grad=True, **kw)
        ((out.image * w).sum() + 0.5 * out.depth.sum() + 0.3 * out.alpha.sum()).backward()
        results.append((out, {k: v.grad for k, v in ins.items()}))
    base, base_grads = results[0]
    for out, grads in results[1:]:
        for k in ("image", "depth", "alpha"):
            assert torch.equal(getattr(out, k), getattr(base, k)), k
        for k, g in grads.items():
            assert torch.equal(g, base_grads[k]), k
    # what each render needed, on the device: the count (a counted render has no such record)
    assert base.needed is None and all(int(out.needed) == base.n_intersections for out, _ in results[1:])
    short, _ = run_warp(scene, device, grad=False, sh_degree=2, isect_capacity=base.n_intersections // 3)
    assert short.n_intersections == base.n_intersections // 3 and int(short.needed) == base.n_intersections


@pytest.mark.parametrize("device", DEVICES)
def test_default_background_is_a_shared_read_only_zero_and_renders_as_black(device):
    """``background=None`` reads the per-device zeros of ``_zero_input`` (no allocation per render); the render,
    and every gradient, is that of an explicit black background, bit for bit, and the shared zeros stay zero
    (also after the buffer grew for a larger shape, which hands out new views)."""
    from warpgs import render as R

    scene = make_scene(n=120, width=33, height=19, seed=6, sh_degree=1, spread=0.9)
    w = torch.rand(19, 33, 3, generator=torch.Generator().manual_seed(2)).to(device)
    results = []
    for background in (None, torch.zeros(3, device=device)):
        out, ins = run_warp(scene, device, grad=True, sh_degree=1, background=background)
        ((out.image * w).sum() + 0.2 * out.alpha.sum()).backward()  # depth left out: its zeros are read too
        results.append((out, {k: v.grad for k, v in ins.items()}))
    (o1, g1), (o2, g2) = results
    for name in ("image", "depth", "alpha"):
        assert torch.equal(getattr(o1, name), getattr(o2, name)), name
    assert all(torch.equal(g1[k], g2[k]) for k in g1)
    dev = torch.device(device) if device == "cpu" else o1.image.device
    z = R._zero_input((3,), dev)
    assert z is R._zero_input((3,), dev)  # the view is made once
    big = R._zero_input((R._ZERO_INPUTS[dev].numel() + 1,), dev)  # more than the buffer held: a new buffer, new views
    assert R._zero_input((3,), dev) is not z and not bool(big.any()) and not bool(z.any())
