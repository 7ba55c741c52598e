"""Stress scenes: the embedded synthetic room with its inputs made hard in one controlled way each.

Every case starts from the scene ``load_scene("synthetic")`` reads (the same world, seed, cameras and
test split), so the test views, the ground truth, are those of the standard split; only the inputs
change, except where the world itself is the case (``textureless``: its test views are rendered from
that world too, so they stay correct for it).

- ``views_N`` (N = 2, 3, 6, 9, ...): the standard split with N inputs (sparsity);
- ``collinear``: the inputs' centres moved onto the straight line through the first and last (the
  middle ones 1 cm off it, so nearly collinear), all looking along that line: pure forward motion,
  where the epipoles sit in the image centre and stereo and view interpolation get the least parallax;
  re-rendered with the ray tracer;
- ``wide_baseline``: the inputs on a horizontal circle around a pivot ahead of the middle input, the
  outermost 90 degrees apart as seen from the pivot, each looking at it; re-rendered;
- ``textureless``: the room's walls, floor and ceiling in one plain colour each (no pattern and no fine
  detail, only smooth shading), inputs and test views re-rendered from that world;
- ``exposure``: the inputs' intensities scaled, x0.6 on the second and x1.5 (clipped) on the third
  (as a camera's auto-exposure would between shots);
- ``wrong_pose``: the middle input's stored pose rotated by 5 degrees (about its vertical axis) and
  moved 0.2 m sideways; its image is unchanged.

``stress_scene(case)`` builds one; ``metadata["stress"]`` holds the case, what was done and the numbers
that show it (``measures``): the collinearity of the centres, the baseline angle, the share of flat
pixels, the exposure ratios, the pose error. ``downscale`` 2 gives the synthetic config's 128x96,
4 gives 64x48 (images_2 box-filtered once more), for CPU-sized runs.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace

import numpy as np

from .scene import Camera, Scene, SceneError, downsample, downsample_depth

CASES = ("views_2", "views_3", "views_6", "views_9", "collinear", "wide_baseline", "textureless", "exposure",
         "wrong_pose")
EXPOSURE_GAINS = (1.0, 0.6, 1.5)  # per input, cycled
POSE_ERROR_DEG, POSE_ERROR_M = 5.0, 0.2
COLLINEAR_OFFSET_M = 0.01
WIDE_ANGLE_DEG = 90.0
FLAT_GRADIENT = 0.01  # a pixel is "flat" when its grey-level gradient is below this (per pixel, [0, 1] images)


def stress_scene(case: str, *, views: int = 3, downscale: int = 2, seed: int = 0, kind: str = "room",
                 root=None, device: str | None = "cpu") -> Scene:
    """The synthetic scene of ``case`` (one of ``CASES``; ``views_N`` takes any N) with ``views`` inputs
    (ignored by ``views_N``) at 1/``downscale`` of the 256x192 capture; ``root``/``device`` as in
    ``load_scene`` (the ray tracer runs on ``device``)."""
    if case.startswith("views_"):
        try:
            n = int(case[len("views_"):])
        except ValueError:
            raise SceneError(f"stress case {case!r}: expected views_N with a number N, e.g. views_3") from None
        scene = base_scene(n, downscale, seed, kind, root, device)
        scene.metadata["stress"] = {"case": case, "description": f"the standard split with {n} inputs",
                                    "measures": {"views": n, **camera_measures(scene.train)}}
        return scene
    builders = {"collinear": _collinear, "wide_baseline": _wide_baseline, "textureless": _textureless,
                "exposure": _exposure, "wrong_pose": _wrong_pose}
    if case not in builders:
        raise SceneError(f"stress case {case!r} is unknown; the cases are {', '.join(CASES)} (views_N for any N)")
    if views < 2:
        raise SceneError(f"stress case {case!r} needs at least 2 inputs, asked for {views}")
    scene = base_scene(views, downscale, seed, kind, root, device)
    out = builders[case](scene, downscale, device)
    out.name = f"{scene.name}-{case}"
    return out


# ----------------------------------------------------------------------------------------------
# the standard scene and re-rendering in its world


def base_scene(views: int, downscale: int, seed: int = 0, kind: str = "room", root=None,
               device: str | None = "cpu") -> Scene:
    """``load_scene("synthetic", views=views)`` at 1/``downscale`` of the capture (1, 2, or 2 x 2^k), with
    the LLFF rule's test views (every 8th frame) rather than every frame not trained on, so that the
    ``views_N`` cases share one test set."""
    from .registry import load_scene

    if downscale < 1 or (downscale > 2 and downscale % 2):
        raise SceneError(f"downscale {downscale}: use 1, 2 or an even factor (4 = 64x48 of the 256x192 capture)")
    stored = 1 if downscale == 1 else 2
    scene = load_scene("synthetic", views=views, downscale=stored, root=root, device=device, seed=seed, kind=kind,
                       test_rest=False)
    if downscale > stored:
        f = downscale // stored
        scene.train = [shrink(c, f) for c in scene.train]
        scene.test = [shrink(c, f) for c in scene.test]
    scene.metadata["downscale"] = downscale
    return scene


def shrink(cam: Camera, f: int) -> Camera:
    """A camera at 1/``f`` of its resolution: box-filtered image, mask and depth, intrinsics scaled."""
    K = cam.K.astype(np.float64).copy()
    K[:2] /= f
    img = downsample(cam.image, f)
    return replace(cam, image=img, K=K.astype(np.float32), width=img.shape[1], height=img.shape[0],
                   mask=None if cam.mask is None else downsample(cam.mask, f),
                   depth=None if cam.depth is None else downsample_depth(cam.depth, f),
                   alpha=None if cam.alpha is None else downsample(cam.alpha, f))


def _world(scene: Scene):
    from .synthetic import build_room, build_street

    meta = scene.metadata["synthetic"]
    world, _ = (build_room if meta["kind"] == "room" else build_street)(meta["seed"])
    return world


def render_inputs(scene: Scene, world, viewmats, names, downscale: int, device) -> list[Camera]:
    """Cameras at ``viewmats`` (world-to-camera in the scene's loaded world) rendered from ``world`` as
    the capture renders its frames (full resolution, box-filtered, 8-bit as the stored PNGs), with
    ground-truth depth."""
    from .scene import make_camera
    from .synthetic import render_views

    meta = scene.metadata["synthetic"]
    W, H = meta["width"], meta["height"]
    A = scene.world_transform  # generator world -> loaded world
    f = 0.5 * W / math.tan(math.radians(meta["fov_x_deg"]) / 2)
    K_full = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    vms = np.stack([np.asarray(v, np.float64) @ A for v in viewmats])
    rgb, depth = render_views(world, vms, K_full, W, H, meta["samples_per_side"], device)
    stored = 1 if downscale == 1 else 2
    cams = []
    for k, name in enumerate(names):
        img = np.round(np.clip(downsample(rgb[k], stored), 0, 1) * 255.0) / 255.0  # as images_2/*.png
        img = downsample(img.astype(np.float32), downscale // stored)
        K = K_full.copy()
        K[:2] /= downscale
        cams.append(make_camera(name, np.linalg.inv(np.asarray(viewmats[k], np.float64)), K, img,
                                depth=downsample_depth(depth[k], downscale)))
    return cams


def look_along(center: np.ndarray, forward: np.ndarray, up: np.ndarray) -> np.ndarray:
    """World-to-camera (OpenCV axes) at ``center`` looking along ``forward`` with ``up`` as the world's up."""
    fwd = forward / np.linalg.norm(forward)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    V = np.eye(4)
    V[:3, :3] = np.stack([right, down, fwd])
    V[:3, 3] = -V[:3, :3] @ center
    return V


def _up(scene: Scene) -> np.ndarray:
    """The world's up direction in the loaded world (the generator's +z)."""
    return scene.world_transform[:3, :3] @ np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------------------------
# the cases


def _collinear(scene: Scene, downscale: int, device) -> Scene:
    centres = np.stack([c.center for c in scene.train])
    a, b = centres[0], centres[-1]
    d = (b - a) / np.linalg.norm(b - a)
    side = np.cross(d, _up(scene))
    side /= np.linalg.norm(side)
    n = len(centres)
    new = []
    for k, c in enumerate(centres):
        p = a + float((c - a) @ d) * d
        if 0 < k < n - 1:  # nearly collinear: the middle ones 1 cm off the line, alternating sides
            p = p + (COLLINEAR_OFFSET_M if k % 2 else -COLLINEAR_OFFSET_M) * side
        new.append(look_along(p, d, _up(scene)))
    before = camera_measures(scene.train)
    out = _with_inputs(scene, render_inputs(scene, _world(scene), new, [c.name for c in scene.train], downscale, device))
    out.metadata["stress"] = {
        "case": "collinear",
        "description": f"inputs on the line through the first and last input (middle ones {COLLINEAR_OFFSET_M} m off), "
                       "all looking along it (pure forward motion)",
        "measures": {**camera_measures(out.train), "collinearity_before": before["collinearity"],
                     "max_angle_to_line_deg": max_angle_to_line(out.train)},
    }
    return out


def _wide_baseline(scene: Scene, downscale: int, device) -> Scene:
    up = _up(scene)
    world = _world(scene)
    mid = scene.train[len(scene.train) // 2]
    fwd = mid.forward - (mid.forward @ up) * up  # horizontal
    fwd /= np.linalg.norm(fwd)
    depth = mid.depth
    h, w = depth.shape
    centre = depth[h * 2 // 5: h * 3 // 5, w * 2 // 5: w * 3 // 5]
    free = float(np.median(centre[centre > 0])) if (centre > 0).any() else 3.0
    radius = min(2.5, 0.6 * free)  # the pivot stays in the free space in front of the middle input
    n = len(scene.train)
    angles = np.radians(np.linspace(-WIDE_ANGLE_DEG / 2, WIDE_ANGLE_DEG / 2, n))
    names = [c.name for c in scene.train]
    for _ in range(8):  # shrink the circle until no camera sits inside or against an object
        pivot = mid.center + radius * fwd
        vms = []
        for t in angles:
            back = -(math.cos(t) * fwd + math.sin(t) * np.cross(up, fwd))  # from the pivot to the camera
            vms.append(look_along(pivot + radius * back, -back, up))
        cams = render_inputs(scene, world, vms, names, downscale, device)
        if all(np.percentile(c.depth[c.depth > 0], 1) > 0.3 for c in cams if (c.depth > 0).any()):
            break
        radius *= 0.8
    else:
        raise SceneError(f"{scene.name}: found no clear circle for the wide-baseline inputs")
    out = _with_inputs(scene, cams)
    out.metadata["stress"] = {
        "case": "wide_baseline",
        "description": f"inputs on a circle of radius {radius:.2f} m around a pivot ahead of the middle input, "
                       f"{WIDE_ANGLE_DEG:g} degrees apart at the ends, each looking at it",
        "measures": {**camera_measures(out.train), "baseline_angle_deg": baseline_angle(out.train, pivot),
                     "view_angle_deg": view_angle(out.train), "view_angle_before_deg": view_angle(scene.train),
                     "radius_m": radius},
    }
    return out


def _textureless(scene: Scene, downscale: int, device) -> Scene:
    from ..kernels.raytrace import PATTERN_PLAIN

    world = _world(scene)
    world.materials = list(world.materials)
    for i in range(6):  # the enclosing surfaces: floor, ceiling and four walls (road, sidewalk, facades)
        m = world.materials[i]
        # plain, and a scale so large that the renderer's fine detail (frequency 9 / scale) is flat too
        world.materials[i] = replace(m, color_b=m.color_a, pattern=PATTERN_PLAIN, scale=1.0e3)
    views = scene.train + scene.test
    new = render_inputs(scene, world, [c.viewmat for c in views], [c.name for c in views], downscale, device)
    # the same cameras (poses, intrinsics, depth: the geometry is unchanged), the new world's images
    train = [replace(c, image=r.image) for c, r in zip(scene.train, new)]
    test = [replace(c, image=r.image) for c, r in zip(scene.test, new[len(scene.train):])]
    before = flat_fraction(scene.train)
    out = _with_inputs(scene, train)
    out.test = test
    out.metadata["stress"] = {
        "case": "textureless",
        "description": "walls, floor and ceiling in one plain colour each (only shading varies); inputs and test "
                       "views rendered from that world",
        "measures": {"flat_fraction": flat_fraction(out.train), "flat_fraction_before": before,
                     **camera_measures(out.train)},
    }
    return out


def _exposure(scene: Scene, downscale: int, device) -> Scene:
    gains = [EXPOSURE_GAINS[k % len(EXPOSURE_GAINS)] for k in range(len(scene.train))]
    cams = []
    for c, g in zip(scene.train, gains):
        cams.append(c if g == 1.0 else replace(c, image=np.clip(c.image * g, 0, 1).astype(np.float32)))
    out = _with_inputs(scene, cams)
    out.metadata["stress"] = {
        "case": "exposure",
        "description": "input intensities scaled by " + ", ".join(f"x{g:g}" for g in gains) + " (clipped at 1)",
        "measures": {"gains": gains, "measured_ratios": [exposure_ratio(a.image, b.image)
                                                         for a, b in zip(scene.train, out.train)],
                     "clipped_fraction": [float((c.image >= 1.0).any(-1).mean()) for c in out.train]},
    }
    return out


def _wrong_pose(scene: Scene, downscale: int, device) -> Scene:
    k = len(scene.train) // 2
    cam = scene.train[k]
    c2w = cam.c2w
    up = _up(scene)
    t = math.radians(POSE_ERROR_DEG)
    # rotation about the world's up axis through the camera centre, then a sideways move
    ux, uy, uz = up
    Kx = np.array([[0, -uz, uy], [uz, 0, -ux], [-uy, ux, 0]])
    R = np.eye(3) + math.sin(t) * Kx + (1 - math.cos(t)) * Kx @ Kx
    bad = np.eye(4)
    bad[:3, :3] = R @ c2w[:3, :3]
    bad[:3, 3] = c2w[:3, 3] + POSE_ERROR_M * c2w[:3, 0]  # along the camera's x (right)
    V = np.linalg.inv(bad)
    V[3] = [0, 0, 0, 1]
    cams = list(scene.train)
    cams[k] = replace(cam, viewmat=V.astype(np.float32))
    out = _with_inputs(scene, cams)
    rot, trans = pose_error(cam.viewmat, cams[k].viewmat)
    out.metadata["stress"] = {
        "case": "wrong_pose",
        "description": f"input {cam.name}'s pose rotated {POSE_ERROR_DEG:g} degrees about the vertical and moved "
                       f"{POSE_ERROR_M:g} m sideways (image unchanged)",
        "measures": {"view": cam.name, "rotation_error_deg": rot, "translation_error_m": trans,
                     "true_viewmat": cam.viewmat.tolist(), **camera_measures(out.train)},
    }
    return out


def _with_inputs(scene: Scene, train: list[Camera]) -> Scene:
    out = copy.copy(scene)
    out.train = train
    out.test = list(scene.test)
    out.metadata = dict(scene.metadata)
    return out


# ----------------------------------------------------------------------------------------------
# measures (what each case claims, checked by tests/test_stability.py)


def camera_measures(cams: list[Camera]) -> dict:
    centres = np.stack([c.center for c in cams])
    spread = float(np.linalg.norm(centres - centres.mean(0), axis=1).max())
    return {"collinearity": collinearity(cams), "centre_spread_m": spread}


def collinearity(cams: list[Camera]) -> float:
    """Second over first singular value of the centred camera centres: 0 when they lie on one line."""
    c = np.stack([cam.center for cam in cams])
    s = np.linalg.svd(c - c.mean(0), compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def max_angle_to_line(cams: list[Camera]) -> float:
    """Largest angle (degrees) between a camera's viewing direction and the line through the first and last centre."""
    d = cams[-1].center - cams[0].center
    d /= np.linalg.norm(d)
    return float(max(math.degrees(math.acos(min(1.0, abs(float(c.forward @ d))))) for c in cams))


def baseline_angle(cams: list[Camera], point: np.ndarray) -> float:
    """Largest angle (degrees) between two cameras' centres as seen from ``point``."""
    dirs = [(c.center - point) / np.linalg.norm(c.center - point) for c in cams]
    return float(max(math.degrees(math.acos(np.clip(a @ b, -1, 1))) for a in dirs for b in dirs))


def view_angle(cams: list[Camera]) -> float:
    """Largest angle (degrees) between two cameras' viewing directions."""
    return float(max(math.degrees(math.acos(np.clip(a.forward @ b.forward, -1, 1))) for a in cams for b in cams))


def flat_fraction(cams: list[Camera], threshold: float = FLAT_GRADIENT) -> float:
    """Share of input pixels whose grey-level gradient (central differences) is below ``threshold``."""
    fr = []
    for c in cams:
        g = c.image.mean(-1)
        gy, gx = np.gradient(g)
        fr.append(float((np.hypot(gx, gy) < threshold).mean()))
    return float(np.mean(fr))


def exposure_ratio(original: np.ndarray, scaled: np.ndarray) -> float:
    """Median ratio scaled / original over pixels neither near black nor clipped in either image."""
    ok = (original > 0.05) & (original < 0.6) & (scaled < 0.99)
    return float(np.median(scaled[ok] / original[ok])) if ok.any() else float("nan")


def pose_error(true_viewmat: np.ndarray, viewmat: np.ndarray) -> tuple[float, float]:
    """(rotation angle in degrees, centre distance) between two world-to-camera matrices."""
    A, B = np.asarray(true_viewmat, np.float64), np.asarray(viewmat, np.float64)
    R = A[:3, :3] @ B[:3, :3].T
    rot = math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    ca, cb = -A[:3, :3].T @ A[:3, 3], -B[:3, :3].T @ B[:3, 3]
    return rot, float(np.linalg.norm(ca - cb))
