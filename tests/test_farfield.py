"""The far field (warpgs/farfield.py) and the rasterizer's per-pixel background: against the torch oracle
(tests/reference.py, which composites any background that broadcasts over [H, W, 3]), analytic gradients,
and scenes whose colour is a known function of elevation."""

import math

import numpy as np
import pytest
import torch

import reference as ref
from test_rasterizer import DEVICES, assert_close, look_at_viewmat, make_scene, run_warp, weighted_loss
from warpgs.farfield import ElevationFarField, make_far_field, ray_directions


def backdrop(scene, seed=7):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(scene["height"], scene["width"], 3, generator=g, dtype=torch.float64)


@pytest.mark.parametrize("device", DEVICES)
def test_per_pixel_background_matches_reference_forward_and_gradients(device):
    scene = make_scene(n=14, seed=21)
    bg = backdrop(scene)
    bg_w = bg.float().to(device).requires_grad_(True)
    out, ins = run_warp(scene, device, grad=True, background=bg_w)
    names = ["means", "quats", "scales", "opacities", "colors"]
    rins = {k: scene[k].clone().requires_grad_(True) for k in names}
    bg_r = bg.clone().requires_grad_(True)
    image, depth, alpha, _ = ref.render(**rins, viewmat=scene["viewmat"], K=scene["K"], width=scene["width"],
                                        height=scene["height"], background=bg_r)
    assert_close(out.image, image, 2e-5, what="image")
    weighted_loss(out.image, out.depth, out.alpha).backward()
    weighted_loss(image, depth, alpha).backward()
    for k in names:
        assert_close(ins[k].grad, rins[k].grad, 2e-4, 2e-3, what=f"d/d{k}")
    assert_close(bg_w.grad, bg_r.grad, 1e-5, what="d/dbackground")


@pytest.mark.parametrize("device", DEVICES)
def test_constant_per_pixel_background_equals_the_kernels_background(device):
    """A [H, W, 3] background of one colour composited after the kernels (through the alpha output's
    gradient) gives the image and Gaussian gradients of the kernels' own [3] background."""
    scene = make_scene(n=12, seed=22)
    colour = torch.tensor([0.2, 0.6, 0.9])
    a, ia = run_warp(scene, device, grad=True, background=colour.to(device))
    plane = colour.expand(scene["height"], scene["width"], 3).contiguous().to(device)
    b, ib = run_warp(scene, device, grad=True, background=plane)
    assert_close(a.image, b.image, 1e-6, what="image")
    (a.image * 1.7).sum().backward()
    (b.image * 1.7).sum().backward()
    for k in ia:
        assert_close(ia[k].grad, ib[k].grad, 1e-5, 1e-4, what=f"d/d{k}")


@pytest.mark.parametrize("device", DEVICES)
def test_background_gradient_is_transmittance(device):
    scene = make_scene(n=8, seed=23)
    bg = backdrop(scene).float().to(device).requires_grad_(True)
    out, _ = run_warp(scene, device, background=bg)
    out.image.sum().backward()
    expected = (1 - out.alpha.detach())[..., None].expand_as(bg)
    assert_close(bg.grad, expected, 1e-6, what="d image / d background")


@pytest.mark.parametrize("device", DEVICES)
def test_per_pixel_background_of_the_wrong_size_is_named(device):
    scene = make_scene(n=3, seed=24)
    with pytest.raises(ValueError, match="background"):
        run_warp(scene, device, background=torch.zeros(scene["height"] + 1, scene["width"], 3, device=device))


def test_ray_directions_are_the_analytic_pixel_rays():
    V = look_at_viewmat((1.0, 0.5, -2.0), (0.0, 0.0, 0.0)).float()
    K = torch.tensor([[30.0, 0, 16.0], [0, 32.0, 12.0], [0, 0, 1]])
    d = ray_directions(V, K, 32, 24)
    assert d.shape == (24, 32, 3)
    assert_close(d.norm(dim=-1), torch.ones(24, 32), 1e-6, what="unit length")
    R = V[:3, :3].double()
    for (i, j) in [(0, 0), (11, 15), (23, 31), (5, 20)]:
        cam = torch.tensor([(j + 0.5 - 16.0) / 30.0, (i + 0.5 - 12.0) / 32.0, 1.0], dtype=torch.float64)
        world = R.T @ cam
        assert_close(d[i, j], (world / world.norm()).float(), 1e-6, what=f"pixel {i},{j}")


class _View:
    def __init__(self, viewmat, K, width, height, image):
        self.viewmat, self.K, self.width, self.height, self.image = viewmat, K, width, height, image


def _banded_views(colour_of_band, bins, yaws, pitch_deg=0.0, size=(48, 40)):
    """Cameras at the origin turned by ``yaws`` whose images are ``colour_of_band`` of each pixel's elevation
    band (world up = +y: ``look_at_viewmat``'s cameras have their image y axis along world -y)."""
    w, h = size
    K = torch.tensor([[20.0, 0, w / 2], [0, 20.0, h / 2], [0, 0, 1]])
    views = []
    for yaw in yaws:
        a, p = math.radians(yaw), math.radians(pitch_deg)
        target = (math.sin(a) * math.cos(p), math.sin(p), math.cos(a) * math.cos(p))
        V = look_at_viewmat((0.0, 0.0, 0.0), target).float()
        e = ray_directions(V, K, w, h) @ torch.tensor([0.0, 1.0, 0.0])
        band = ((e + 1) * 0.5 * bins).long().clamp(0, bins - 1)
        views.append(_View(V, K, w, h, colour_of_band[band]))
    return views


def test_elevation_far_field_recovers_banded_colours_and_generalises_over_azimuth():
    bins = 8
    colours = torch.rand(bins, 3, generator=torch.Generator().manual_seed(3))
    train = _banded_views(colours, bins, yaws=[0, 100, 230])
    ff = ElevationFarField.fit(train, bins)
    assert_close(ff.up, torch.tensor([0.0, 1.0, 0.0]), 1e-5, what="up")
    # bands the views see (the vertical field of view is +-45 degrees: elevation sines within +-0.71)
    seen = [b for b in range(bins) if abs((b + 0.5) / bins * 2 - 1) < 0.6]
    assert len(seen) >= 4
    assert_close(ff.colors[seen], colours[seen], 1e-5, what="band colours")
    # an azimuth no input looked at: the same elevation profile, at the band centres
    test = _banded_views(colours, bins, yaws=[160])[0]
    img = ff.image(test.viewmat, test.K, test.width, test.height)
    x = ff.elevation_coordinate(ray_directions(test.viewmat, test.K, test.width, test.height))
    at_centre = (x - x.round()).abs() < 0.01  # within 1% of a band centre: at most 1% of a neighbour mixed in
    centre_band = x.round().long().clamp(0, bins - 1)
    inner = at_centre & torch.isin(centre_band, torch.tensor(seen))
    assert int(inner.sum()) > 10
    assert_close(img[inner], colours[centre_band[inner]], 0.0101, what="far field at band centres")


def test_unseen_bands_take_the_nearest_seen_band_and_sky_drops_the_ground():
    bins = 16
    colours = torch.linspace(0, 1, bins)[:, None].repeat(1, 3)
    train = _banded_views(colours, bins, yaws=[0, 90], pitch_deg=25.0, size=(40, 20))  # looking up
    ff = ElevationFarField.fit(train, bins)
    counts = np.zeros(bins)
    for v in train:
        e = (ray_directions(v.viewmat, v.K, v.width, v.height) @ ff.up).reshape(-1)
        np.add.at(counts, ((e + 1) * 0.5 * bins).long().clamp(0, bins - 1).numpy(), 1)
    seen = np.nonzero(counts)[0]
    lowest = int(seen.min())
    assert lowest > 0  # the views miss the lowest bands
    assert_close(ff.colors[:lowest], ff.colors[lowest].expand(lowest, 3), 1e-6, what="unseen bands")
    sky = make_far_field("sky", train, bins, background=torch.tensor([0.1, 0.2, 0.3]))
    centres = (torch.arange(bins) + 0.5) / bins * 2 - 1
    assert_close(sky.colors[centres < 0], torch.tensor([0.1, 0.2, 0.3]).expand(int((centres < 0).sum()), 3), 0,
                 what="below the horizon")
    assert_close(sky.colors[centres > 0], ff.colors[centres > 0], 0, what="above the horizon")
    assert make_far_field("none", train, bins) is None
    with pytest.raises(ValueError, match="far_field"):
        make_far_field("cubemap", train, bins)


def test_far_field_round_trips_through_its_json(tmp_path):
    bins = 4
    colours = torch.rand(bins, 3, generator=torch.Generator().manual_seed(5))
    ff = ElevationFarField.fit(_banded_views(colours, bins, yaws=[0, 120]), bins)
    back = ElevationFarField.from_dict(__import__("json").loads(ff.save(tmp_path / "ff.json").read_text()))
    assert_close(back.colors, ff.colors, 1e-6, what="colours")
    assert_close(back.up, ff.up, 1e-6, what="up")


@pytest.mark.skipif("cpu" not in DEVICES, reason="trains on the CPU (the GPU machine's packed Warp has no CPU compiler)")
def test_trainer_fits_the_far_field_on_training_views_only_and_resumes_exactly(tmp_path):
    import dataclasses

    from tiny_scene import make_scene, param_copy, same_params, tiny_config
    from warpgs.train import Trainer

    scene = make_scene()
    cfg = tiny_config(40, str(tmp_path / "none.pth"), far_field="elevation", far_field_bins=8)
    straight = Trainer(cfg, scene)
    assert straight.bg.components.get("far_field") is not None
    cam = straight.test_cams[0]
    bg = straight.background_for(cam)
    assert bg.shape == (cam.height, cam.width, 3)
    # the test views do not enter it
    blanked = dataclasses.replace(scene, test=[dataclasses.replace(c, image=np.ones_like(c.image)) for c in scene.test])
    assert torch.equal(Trainer(cfg, blanked).bg.components.get("far_field").field.colors,
                       straight.bg.components.get("far_field").field.colors)
    # every render of the trainer composites it
    with torch.no_grad():
        out = straight.render(cam)
        raw = straight.model.render(cam.viewmat, cam.K, cam.width, cam.height)
    assert_close(out.image, raw.image + (1 - raw.alpha)[..., None] * bg, 1e-6, what="render over the far field")
    straight.train()
    first = Trainer(cfg, scene, tmp_path)
    first.train(20)
    first.save_checkpoint()
    second = Trainer(cfg, scene, tmp_path)
    second.load_checkpoint()
    second.train()
    assert same_params(param_copy(straight), param_copy(second))
    assert straight.losses == second.losses
    # the fit's time is one of the run's per-stage timings
    stages = second.finish()["stage_times_s"]
    took = second.bg.components.get("far_field").time
    assert took > 0 and stages["far_field_s"] == round(took, 2)


def test_the_far_field_is_a_registered_background_component(tmp_path):
    """The far field is an entry of ``warpgs.backgrounds``' registry: its section ``backgrounds.far_field`` (where
    ``train.far_field`` of earlier versions loads), off by default, and when on, the image it draws behind a view and
    the far_field.json it writes are those of an ``ElevationFarField`` fitted on the same views by itself."""
    from types import SimpleNamespace

    from tiny_scene import make_scene
    from warpgs.backgrounds import REGISTRY, Backgrounds
    from warpgs.backgrounds.far_field import FarField
    from warpgs.config import Config, load_config

    assert list(REGISTRY) == ["far_field"]
    old = load_config([], ["train.far_field=sky", "train.far_field_bins=4"]).backgrounds.far_field
    assert (old.kind, old.bins) == ("sky", 4)
    cams = [c.to_torch("cpu") for c in make_scene().train]
    ctx = SimpleNamespace(cameras=SimpleNamespace(train=cams), background=SimpleNamespace(colour=torch.zeros(3)),
                          geometry=None, log=lambda msg: None)
    cfg = Config()
    assert Backgrounds.build(cfg, ctx).items == {} and Backgrounds.build(cfg, ctx).image(cams[0]) is None
    cfg.backgrounds.far_field.kind, cfg.backgrounds.far_field.bins = "elevation", 8
    comps = Backgrounds.build(cfg, ctx)
    assert isinstance(comps.get("far_field"), FarField) and list(comps.times()) == ["far_field_s"]
    alone = ElevationFarField.fit(cams, 8)
    for cam in cams:
        assert torch.equal(comps.image(cam), alone.image(cam.viewmat, cam.K, cam.width, cam.height))
    comps.save(tmp_path)
    assert_close(ElevationFarField.load(tmp_path / "far_field.json").colors, alone.colors, 1e-6, what="saved bands")


def _loo_oracle(views, up, bins, blur):
    """Leave-one-out squared error of the far field of ``blur``, pixel by pixel: each left-out pixel against
    the Gaussian-weighted mean (over band distance) of the other views' pixels, unseen bands taking the
    nearest seen band, interpolated between band centres as the far field renders it."""
    data = []
    for v in views:
        e = (ray_directions(v.viewmat, v.K, v.width, v.height) @ up).reshape(-1).double()
        data.append((((e + 1) * 0.5 * bins).long().clamp(0, bins - 1), v.image.reshape(-1, 3).double(), e))
    total = 0.0
    for i, (b_out, c_out, e_out) in enumerate(data):
        b = torch.cat([d[0] for j, d in enumerate(data) if j != i])
        c = torch.cat([d[1] for j, d in enumerate(data) if j != i])
        colours = []
        for band in range(bins):
            w = torch.exp(-0.5 * ((band - b.double()) / blur) ** 2) if blur > 0 else (b == band).double()
            colours.append((w[:, None] * c).sum(0) / w.sum() if float(w.sum()) > 1e-9 else None)
        seen = [k for k in range(bins) if colours[k] is not None]
        table = torch.stack([colours[min(seen, key=lambda s: abs(s - k))] for k in range(bins)])
        # what the far field renders: linear between band centres, the end bands' colour beyond them
        x = ((e_out + 1) * 0.5 * bins - 0.5).clamp(0, bins - 1)
        lo = x.floor().long()
        hi = (lo + 1).clamp(max=bins - 1)
        w = (x - lo.double())[:, None]
        total += float(((table[lo] * (1 - w) + table[hi] * w - c_out) ** 2).sum())
    return total


def test_auto_blur_is_the_leave_one_out_choice_of_a_pixel_oracle():
    """Views that agree on the elevation profile: the sharp far field (blur 0) predicts each from the others
    exactly. Views whose profiles are shifted in elevation against each other: a blurred one predicts better,
    and the width chosen is the one the pixel-level oracle finds best."""
    from warpgs.farfield import BLUR_CHOICES

    bins = 16
    colours = torch.rand(bins, 3, generator=torch.Generator().manual_seed(5))
    agree = _banded_views(colours, bins, yaws=[0, 120, 240], size=(32, 28))
    ff = ElevationFarField.fit(agree, bins, "auto")
    assert ff.blur == 0.0
    shifted = [_banded_views(torch.roll(colours, k, 0), bins, yaws=[y], size=(32, 28))[0]
               for k, y in zip((-2, 0, 2, 1), (0, 90, 180, 270))]
    ff = ElevationFarField.fit(shifted, bins, "auto")
    errors = {b: _loo_oracle(shifted, ff.up, bins, b) for b in BLUR_CHOICES}
    assert ff.blur == min(errors, key=errors.get)
    assert ff.blur > 0
    assert ElevationFarField.fit(shifted[:1], bins, "auto").blur == 0.0  # one view: nothing to leave out
    with pytest.raises(ValueError, match="blur"):
        ElevationFarField.fit(shifted, bins, -1.0)


def test_blurred_far_field_is_the_kernel_weighted_band_mean_and_round_trips(tmp_path):
    bins = 8
    colours = torch.rand(bins, 3, generator=torch.Generator().manual_seed(9))
    views = _banded_views(colours, bins, yaws=[0, 150], size=(24, 20))
    ff = ElevationFarField.fit(views, bins, 1.5)
    sums, counts = torch.zeros(bins, 3, dtype=torch.float64), torch.zeros(bins, dtype=torch.float64)
    for v in views:
        b = ((ray_directions(v.viewmat, v.K, v.width, v.height) @ ff.up + 1) * 0.5 * bins).long().clamp(0, bins - 1)
        for band, c in zip(b.reshape(-1).tolist(), v.image.reshape(-1, 3).double()):
            sums[band] += c
            counts[band] += 1
    for j in range(bins):
        w = torch.tensor([math.exp(-0.5 * ((j - k) / 1.5) ** 2) for k in range(bins)], dtype=torch.float64)
        assert_close(ff.colors[j].double(), (w[:, None] * sums).sum(0) / (w * counts).sum(), 1e-6, what=f"band {j}")
    ff.save(tmp_path / "ff.json")
    back = ElevationFarField.load(tmp_path / "ff.json")
    assert back.blur == 1.5
    assert_close(back.colors, ff.colors, 1e-6, what="colours after the round trip")


def test_cylinder_directions_are_the_analytic_exit_points():
    from warpgs.farfield import cylinder_directions

    up, centre = torch.tensor([0.0, 1.0, 0.0]), torch.zeros(3)
    dirs = torch.nn.functional.normalize(torch.randn(50, 3, generator=torch.Generator().manual_seed(1)), dim=-1)
    # from the centre, the exit point lies along the ray itself
    assert_close(cylinder_directions(dirs, centre, up, centre, 10.0), dirs, 1e-6, what="from the centre")
    # from (5, 0, 0), 45 degrees up towards +x: |5 + t / sqrt 2| = 10 at t = 5 sqrt 2, the point (10, 5, 0)
    d = torch.tensor([[1.0, 1.0, 0.0]]) / math.sqrt(2)
    want = torch.tensor([[10.0, 5.0, 0.0]]) / math.sqrt(125.0)
    assert_close(cylinder_directions(d, torch.tensor([5.0, 0.0, 0.0]), up, centre, 10.0), want, 1e-6, what="exit")
    # straight up: no crossing, the ray's own direction
    assert_close(cylinder_directions(torch.tensor([[0.0, 1.0, 0.0]]), torch.tensor([5.0, 0.0, 0.0]), up, centre, 10.0),
                 torch.tensor([[0.0, 1.0, 0.0]]), 0, what="vertical ray")
    # from outside, the far crossing: from (-20, 0, 0) along +x, the wall at x = +10
    assert_close(cylinder_directions(torch.tensor([[1.0, 0.0, 0.0]]), torch.tensor([-20.0, 0.0, 0.0]), up, centre, 10.0),
                 torch.tensor([[1.0, 0.0, 0.0]]), 1e-6, what="from outside")


def _walled_views(colour_of_band, bins, eyes_yaws, radius=10.0, size=(48, 40), device="cpu"):
    """Cameras at ``eyes_yaws`` ((x, z), yaw) at height 0 inside a vertical wall of ``radius`` around the origin
    (world up +y) whose colour at a point is ``colour_of_band`` of that point's elevation band seen from the
    origin: the exit points solved here in numpy, independently of ``cylinder_directions``."""
    w, h = size
    K = torch.tensor([[20.0, 0, w / 2], [0, 20.0, h / 2], [0, 0, 1]])
    views = []
    for (x, z), yaw in eyes_yaws:
        a = math.radians(yaw)
        eye = np.array([x, 0.0, z])
        V = look_at_viewmat(tuple(eye), (x + math.sin(a), 0.0, z + math.cos(a))).float()
        d = ray_directions(V, K, w, h).reshape(-1, 3).double().numpy()
        dh = d[:, [0, 2]]
        oh = eye[[0, 2]]
        A, B, C = (dh * dh).sum(1), dh @ oh, oh @ oh - radius**2
        t = (-B + np.sqrt(B * B - A * C)) / A
        p = eye + t[:, None] * d
        e = torch.from_numpy(p[:, 1] / np.linalg.norm(p, axis=1))
        band = ((e + 1) * 0.5 * bins).long().clamp(0, bins - 1)
        views.append(_View(V.to(device), K.to(device), w, h, colour_of_band[band].reshape(h, w, 3).float().to(device)))
    return views


@pytest.mark.parametrize("device", DEVICES)
def test_cylinder_proxy_is_chosen_leave_one_out_and_predicts_a_nearer_camera(device):
    """A courtyard: the views' colours are a function of the height on a wall of radius 10 around them, not of
    the ray's elevation. The leave-one-out choice among the candidate cylinders finds that wall from points on
    it, and renders a camera near the wall (where the roof line stands high) as the wall looks from there; the
    elevation of the ray alone cannot. Without points, or with ``proxy="none"``, there is no cylinder."""
    bins = 16
    colours = torch.rand(bins, 3, generator=torch.Generator().manual_seed(11), dtype=torch.float64)
    train = _walled_views(colours, bins, [((0.0, 0.0), 0), ((4.0, 2.0), 100), ((-3.0, -1.0), 200), ((1.0, 5.0), 290)],
                          device=device)
    g = np.random.default_rng(0)
    th, hgt = g.uniform(0, 2 * np.pi, 400), g.uniform(-4, 6, 400)
    points = np.stack([10 * np.cos(th), hgt, 10 * np.sin(th)], 1)
    ff = ElevationFarField.fit(train, bins, 0.0, "auto", points)
    assert ff.radius is not None and abs(ff.radius - 10.0) < 0.5, ff.describe()
    assert ff.proxy["loo_psnr"] > ff.proxy["loo_psnr_without"]
    test = _walled_views(colours, bins, [((0.0, -7.0), 180)], device=device)[0]  # 3 from the wall, facing it
    truth = test.image.double()
    assert ff.image(test.viewmat, test.K, test.width, test.height).device == test.viewmat.device
    cyl = ff.image(test.viewmat, test.K, test.width, test.height).double()
    ray = ElevationFarField.fit(train, bins).image(test.viewmat, test.K, test.width, test.height).double()
    err_cyl, err_ray = float(((cyl - truth) ** 2).mean()), float(((ray - truth) ** 2).mean())
    assert err_cyl < 0.25 * err_ray, (err_cyl, err_ray)
    assert ElevationFarField.fit(train, bins, 0.0, "none", points).radius is None
    assert ElevationFarField.fit(train, bins, 0.0, "auto", None).radius is None
    with pytest.raises(ValueError, match=r"far_field\.proxy"):
        ElevationFarField.fit(train, bins, 0.0, "sphere", points)


def test_cylinder_far_field_round_trips_through_its_json(tmp_path):
    bins = 8
    colours = torch.rand(bins, 3, generator=torch.Generator().manual_seed(12), dtype=torch.float64)
    train = _walled_views(colours, bins, [((0.0, 0.0), 0), ((4.0, 2.0), 120), ((-3.0, -1.0), 240)], size=(24, 20))
    th = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    points = np.stack([10 * np.cos(th), np.linspace(-3, 5, 60), 10 * np.sin(th)], 1)
    ff = ElevationFarField.fit(train, bins, 0.0, "auto", points)
    assert ff.radius is not None
    back = ElevationFarField.load(ff.save(tmp_path / "ff.json"))
    assert back.radius == ff.radius and back.proxy == ff.proxy
    cam = train[1]
    assert_close(back.image(cam.viewmat, cam.K, cam.width, cam.height), ff.image(cam.viewmat, cam.K, cam.width, cam.height),
                 1e-6, what="image after the round trip")


def test_the_captures_config_asks_for_the_cylinder_and_a_bad_proxy_is_named():
    from pathlib import Path

    from warpgs.config import load_config

    dl3dv = Path(__file__).resolve().parents[1] / "configs" / "datasets" / "dl3dv.yaml"
    assert load_config([dl3dv]).backgrounds.far_field.proxy == "auto"
    assert load_config().backgrounds.far_field.proxy == "none"
    with pytest.raises(ValueError, match=r"far_field\.proxy = 'sphere' \(from --set train\.far_field_proxy=sphere\)"):
        load_config(overrides=["train.far_field_proxy=sphere"])  # the key of earlier versions, named where it lives now


def test_far_field_images_are_kept_per_camera_and_recomputed_when_it_changes():
    """``FarFieldImages`` (what ``Trainer.background_for`` draws on) returns exactly the far field's image, computes
    it once per camera however often it is asked, recomputes it after the camera's pose or the band colours
    change in place, keeps at most ``max_bytes`` of images, and keeps nothing for a one-off pose."""
    from types import SimpleNamespace

    from warpgs.farfield import FarFieldImages

    up = torch.tensor([0.0, -1.0, 0.0])
    ff = ElevationFarField(up, torch.rand(8, 3, generator=torch.Generator().manual_seed(0)),
                           centre=torch.tensor([0.0, 0.0, 4.0]), radius=3.0)
    K = torch.tensor([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    cams = [SimpleNamespace(viewmat=look_at_viewmat(np.array([math.cos(a), 0.3, math.sin(a)]) * 2, np.zeros(3)),
                            K=K.clone(), width=16, height=12) for a in (0.0, 1.0, 2.0)]
    calls = []
    real = ff.image
    ff.image = lambda *a: calls.append(1) or real(*a)
    one = 16 * 12 * 3 * 4  # bytes of one float32 image
    kept = FarFieldImages(max_bytes=2 * one)
    for _ in range(3):
        for cam in cams[:2]:
            assert torch.equal(kept.image(ff, cam), real(cam.viewmat, cam.K, cam.width, cam.height))
    assert len(calls) == 2  # once per camera
    cams[0].viewmat[:3, 3] += 0.5  # the pose moved in place: recomputed
    moved = kept.image(ff, cams[0])
    assert len(calls) == 3 and torch.equal(moved, real(cams[0].viewmat, K, 16, 12))
    ff.colors.mul_(0.5)  # the bands changed in place: recomputed
    assert torch.equal(kept.image(ff, cams[0]), real(cams[0].viewmat, K, 16, 12)) and len(calls) == 4
    kept.image(ff, cams[2])  # a third camera evicts the least recently used (the second)
    kept.image(ff, cams[1])
    assert len(calls) == 6 and len(kept._kept) == 2 and kept.bytes == 2 * one
    kept.image(ff, cams[2], keep=False)  # kept already: returned without computing
    assert len(calls) == 6
    passing = SimpleNamespace(viewmat=cams[0].viewmat.clone(), K=K, width=16, height=12)
    for _ in range(2):  # a one-off pose: computed each time, and nothing kept or evicted
        kept.image(ff, passing, keep=False)
    assert len(calls) == 8 and len(kept._kept) == 2 and kept.bytes == 2 * one
