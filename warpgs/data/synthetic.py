"""The embedded default scene: a procedurally built room (or street) walked through by a camera.

``generate_capture`` builds the world with trimesh (a room with textured walls, floor and ceiling,
pillars, crates, balls and wall panels as occluders, lit by ceiling lamps; or a street with
buildings, poles and parked cars under a sun), moves a camera forward through it along a gently
curving path with slight turns of the head and a small step bob (a hand-held walk like a DL3DV
capture, not an orbit), and renders colour and ground-truth depth with Warp ray tracing
(``warpgs.kernels.raytrace``). Everything follows from the seed.

``write_dl3dv`` stores it in DL3DV's layout (nerfstudio ``transforms.json`` with an
``applied_transform``, ``images/`` and ``images_2/``, ``colmap/sparse/0`` whose points are sampled
from the depth maps, and ``depths/*.npy``), and ``load_synthetic`` reads it back through the DL3DV
loader, so the default run exercises the same path as real data.

Depth is the z-depth along the camera's optical axis (not the distance along the ray), in world
units (metres), float32; 0 marks pixels with no surface (the street's sky).

World frames: the generator's world is z-up (metres). The stored poses are in nerfstudio's frame
``A @ world`` with A the ``applied_transform`` that ``ns-process-data`` writes ((x, y, z) ->
(x, z, -y)); the COLMAP model is in the generator's world, and the loaded ``Scene.world_transform``
is A.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import colmap as colmap_io
from .scene import Scene, SceneError

FORMAT_VERSION = 1
# nerfstudio's applied_transform for COLMAP input (rows of eye(3) reordered (0, 2, 1), last negated)
APPLIED_TRANSFORM = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])


@dataclass
class SyntheticConfig:
    seed: int = 0
    width: int = 256
    height: int = 192
    frames: int = 24
    kind: str = "room"  # "room" or "street"
    fov_x_deg: float = 70.0
    samples_per_side: int = 2  # anti-aliasing: ns x ns colour rays per pixel
    num_points: int = 4000  # COLMAP-like points sampled from the depth maps

    def dirname(self) -> str:
        return f"{self.kind}_seed{self.seed}_{self.width}x{self.height}_{self.frames}f_aa{self.samples_per_side}_v{FORMAT_VERSION}"


@dataclass
class Material:
    color_a: tuple[float, float, float]
    color_b: tuple[float, float, float]
    pattern: int  # raytrace.PATTERN_*
    scale: float  # metres per pattern period


@dataclass
class SyntheticWorld:
    vertices: np.ndarray  # (V, 3) float32
    faces: np.ndarray  # (F, 3) int32
    face_material: np.ndarray  # (F,) int32
    materials: list[Material]
    light_pos: np.ndarray  # (L, 3)
    light_power: np.ndarray  # (L, 3)
    sun_dir: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sun_color: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ambient: np.ndarray = field(default_factory=lambda: np.full(3, 0.2))
    sky_zenith: np.ndarray = field(default_factory=lambda: np.array([0.35, 0.55, 0.9]))
    sky_horizon: np.ndarray = field(default_factory=lambda: np.array([0.8, 0.87, 0.95]))
    seed: int = 0


@dataclass
class SyntheticCapture:
    """A rendered walk-through, in the generator's world (z-up, metres)."""

    config: SyntheticConfig
    world: SyntheticWorld
    names: list[str]
    viewmats: np.ndarray  # (N, 4, 4) float64, world -> camera, OpenCV axes
    K: np.ndarray  # (3, 3) float64
    images: np.ndarray  # (N, H, W, 3) float32 in [0, 1] (what the renderer produced)
    depths: np.ndarray  # (N, H, W) float32 z-depth, 0 = nothing hit


# ----------------------------------------------------------------------------------------------
# world building


class _Builder:
    def __init__(self):
        self.meshes, self.mats, self.materials = [], [], []

    def material(self, m: Material) -> int:
        self.materials.append(m)
        return len(self.materials) - 1

    def add(self, mesh, material: int | np.ndarray):
        self.meshes.append(mesh)
        self.mats.append(np.broadcast_to(np.asarray(material, np.int32), (len(mesh.faces),)).copy())

    def build(self, **kw) -> SyntheticWorld:
        offs, verts, faces = 0, [], []
        for m in self.meshes:
            verts.append(np.asarray(m.vertices))
            faces.append(np.asarray(m.faces) + offs)
            offs += len(m.vertices)
        return SyntheticWorld(
            vertices=np.concatenate(verts).astype(np.float32),
            faces=np.concatenate(faces).astype(np.int32),
            face_material=np.concatenate(self.mats).astype(np.int32),
            materials=self.materials,
            **kw,
        )


def _color(rng, lo=0.15, hi=0.95):
    return tuple(float(x) for x in rng.uniform(lo, hi, 3))


def _random_material(rng, patterns=(0, 1, 2, 3), scale=(0.15, 0.6)) -> Material:
    a = np.array(_color(rng, 0.35, 0.95))
    b = a * rng.uniform(0.2, 0.6) + rng.uniform(0, 0.15, 3)
    return Material(tuple(a), tuple(float(x) for x in np.clip(b, 0, 1)), int(rng.choice(patterns)), float(rng.uniform(*scale)))


def _path(rng, x0: float, x1: float):
    """A gently curving walking line y(x) and the clearance test for objects near it."""
    amp, period, phase = rng.uniform(0.25, 0.6), rng.uniform(7.0, 11.0), rng.uniform(0, 2 * np.pi)

    def y_of(x):
        return amp * np.sin(2 * np.pi * x / period + phase)

    def clear(x, y, r, margin):
        xs = np.linspace(x0 - 1.0, x1 + 1.0, 200)
        return np.min(np.hypot(xs - x, y_of(xs) - y)) > r + margin

    return y_of, clear


def _place(rng, n, sample, clear, placed, tries=200):
    out = []
    for _ in range(tries):
        if len(out) >= n:
            break
        x, y, r = sample()
        if not clear(x, y, r):
            continue
        if any(np.hypot(x - px, y - py) < r + pr + 0.25 for px, py, pr in placed):
            continue
        placed.append((x, y, r))
        out.append((x, y, r))
    return out


def build_room(seed: int) -> tuple[SyntheticWorld, tuple]:
    """A 12 x 7 x 3 m room with textured surfaces, pillars, crates, balls and panels; z-up."""
    import trimesh

    rng = np.random.default_rng(seed)
    Lx, Ly, H = 12.0, 7.0, 3.0
    b = _Builder()
    floor = b.material(Material(_color(rng, 0.5, 0.9), _color(rng, 0.1, 0.4), int(rng.choice([0, 2])), float(rng.uniform(0.4, 0.8))))
    ceiling = b.material(Material((0.9, 0.9, 0.88), (0.7, 0.7, 0.68), 0, 1.0))
    walls = [b.material(_random_material(rng, (1, 2, 3), (0.3, 0.8))) for _ in range(4)]
    room = trimesh.creation.box(extents=(Lx, Ly, H))
    room.apply_translation((0, 0, H / 2))
    room.invert()  # normals point inside
    tri = np.asarray(room.vertices)[np.asarray(room.faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    fm = np.empty(len(room.faces), np.int32)
    fm[n[:, 2] > 0.5] = floor
    fm[n[:, 2] < -0.5] = ceiling
    fm[n[:, 0] < -0.5] = walls[0]  # wall at +x (faces -x)
    fm[n[:, 0] > 0.5] = walls[1]
    fm[n[:, 1] < -0.5] = walls[2]
    fm[n[:, 1] > 0.5] = walls[3]
    b.add(room, fm)

    x0, x1 = -4.6, 3.6
    y_of, near_path = _path(rng, x0, x1)
    placed: list = []

    def inside(x, y, r):
        return abs(x) < Lx / 2 - r - 0.1 and abs(y) < Ly / 2 - r - 0.1

    def clear(x, y, r):
        return inside(x, y, r) and near_path(x, y, r, 0.9)

    pillar_mats = [b.material(_random_material(rng)) for _ in range(2)]
    for x, y, r in _place(rng, int(rng.integers(4, 7)), lambda: (rng.uniform(-5.4, 5.4), rng.uniform(-3.2, 3.2), rng.uniform(0.18, 0.32)), clear, placed):
        cyl = trimesh.creation.cylinder(radius=r, height=H, sections=20)
        cyl.apply_translation((x, y, H / 2))
        b.add(cyl, pillar_mats[int(rng.integers(2))])

    crate_mats = [b.material(_random_material(rng)) for _ in range(3)]
    crates = []
    for x, y, r in _place(rng, int(rng.integers(6, 10)), lambda: (rng.uniform(-5.4, 5.4), rng.uniform(-3.2, 3.2), rng.uniform(0.3, 0.6)), clear, placed):
        ex = rng.uniform(0.6, 1.0, 2) * r  # half-diagonal of the rotated box stays below r
        hz = rng.uniform(0.35, 1.2)
        box = trimesh.creation.box(extents=(ex[0] * 1.4, ex[1] * 1.4, hz))
        box.apply_transform(trimesh.transformations.rotation_matrix(rng.uniform(0, np.pi), (0, 0, 1)))
        box.apply_translation((x, y, hz / 2))
        b.add(box, crate_mats[int(rng.integers(3))])
        crates.append((x, y, hz, r))
    ball_mat = b.material(_random_material(rng, (0, 3), (0.08, 0.2)))
    for x, y, hz, r in crates[:3]:
        rad = min(0.3, 0.6 * r)
        s = trimesh.creation.icosphere(subdivisions=2, radius=rad)
        s.apply_translation((x, y, hz + rad))
        b.add(s, ball_mat)

    panel_mats = [b.material(_random_material(rng, (0, 3), (0.1, 0.3))) for _ in range(3)]
    for k in range(int(rng.integers(4, 7))):
        side = 1 if k % 2 else -1
        w, h = rng.uniform(0.6, 1.5), rng.uniform(0.5, 1.0)
        px = rng.uniform(-Lx / 2 + 1, Lx / 2 - 1)
        panel = trimesh.creation.box(extents=(w, 0.04, h))
        panel.apply_translation((px, side * (Ly / 2 - 0.03), rng.uniform(1.1, 2.0)))
        b.add(panel, panel_mats[k % 3])
    end_panel = trimesh.creation.box(extents=(0.04, 2.0, 1.2))
    end_panel.apply_translation((Lx / 2 - 0.03, rng.uniform(-1.5, 1.5), 1.5))
    b.add(end_panel, panel_mats[0])

    lamps = np.array([[x, y_of(x) + rng.uniform(-0.8, 0.8), H - 0.25] for x in np.linspace(-4.5, 4.5, 3)])
    power = np.tile(rng.uniform(2.2, 2.8, (len(lamps), 1)), (1, 3)) * np.array([1.0, 0.95, 0.85])
    world = b.build(light_pos=lamps, light_power=power, ambient=np.full(3, 0.16), seed=seed)
    return world, (x0, x1, y_of, 1.5)


def build_street(seed: int) -> tuple[SyntheticWorld, tuple]:
    """A street between rows of buildings, with poles and parked cars, under a sun; z-up."""
    import trimesh

    rng = np.random.default_rng(seed)
    b = _Builder()
    road = b.material(Material((0.35, 0.35, 0.37), (0.2, 0.2, 0.22), 3, 2.0))
    walk = b.material(Material((0.7, 0.68, 0.62), (0.5, 0.48, 0.44), 0, 0.6))
    ground = trimesh.creation.box(extents=(80, 40, 0.2))
    ground.apply_translation((0, 0, -0.1))
    b.add(ground, road)
    for side in (-1, 1):
        sw = trimesh.creation.box(extents=(80, 3.0, 0.15))
        sw.apply_translation((0, side * 6.5, 0.075))
        b.add(sw, walk)
    facade = [b.material(_random_material(rng, (0, 2), (0.4, 1.2))) for _ in range(4)]
    for side in (-1, 1):
        x = -30.0
        while x < 30.0:
            w = rng.uniform(4, 9)
            d, h = rng.uniform(5, 10), rng.uniform(5, 16)
            bl = trimesh.creation.box(extents=(w - 0.3, d, h))
            bl.apply_translation((x + w / 2, side * (8.0 + d / 2), h / 2))
            b.add(bl, facade[int(rng.integers(4))])
            x += w
    pole = b.material(Material((0.25, 0.27, 0.3), (0.4, 0.4, 0.42), 1, 0.3))
    for side in (-1, 1):
        for x in np.arange(-24, 25, rng.uniform(5, 8)):
            c = trimesh.creation.cylinder(radius=0.09, height=4.0, sections=12)
            c.apply_translation((x + rng.uniform(-0.5, 0.5), side * 5.3, 2.0))
            b.add(c, pole)
    car_mats = [b.material(_random_material(rng, (1, 3), (0.2, 0.5))) for _ in range(4)]
    for side in (-1, 1):
        for x in np.arange(-20, 21, 7.0):
            if rng.uniform() < 0.35:
                continue
            body = trimesh.creation.box(extents=(4.0, 1.8, 0.9))
            body.apply_translation((x + rng.uniform(-1, 1), side * 3.6, 0.65))
            top = trimesh.creation.box(extents=(2.2, 1.6, 0.6))
            top.apply_translation((body.centroid[0] - 0.3, side * 3.6, 1.4))
            m = car_mats[int(rng.integers(4))]
            b.add(body, m)
            b.add(top, m)
    x0, x1 = -12.0, 12.0
    y_of, _ = _path(rng, x0, x1)
    sun = np.array([0.45, -0.35, 0.82])
    world = b.build(
        light_pos=np.zeros((0, 3)), light_power=np.zeros((0, 3)),
        sun_dir=sun / np.linalg.norm(sun), sun_color=np.array([1.3, 1.25, 1.1]), ambient=np.array([0.32, 0.34, 0.4]), seed=seed,
    )
    return world, (x0, x1, y_of, 1.6)


def walk_cameras(rng, n: int, x0: float, x1: float, y_of, eye: float) -> np.ndarray:
    """World-to-camera matrices (OpenCV) along the walking line, looking ahead with slight turns."""
    yaw_amp, yaw_f, yaw_ph = rng.uniform(0.12, 0.3), rng.uniform(0.8, 1.6), rng.uniform(0, 2 * np.pi)
    out = np.zeros((n, 4, 4))
    for k, s in enumerate(np.linspace(0.0, 1.0, n)):
        x = x0 + (x1 - x0) * s
        y = y_of(x)
        z = eye + 0.025 * np.sin(2 * np.pi * 7 * s)
        heading = math.atan2(y_of(x + 0.05) - y_of(x - 0.05), 0.1) + yaw_amp * np.sin(2 * np.pi * yaw_f * s + yaw_ph)
        pitch = -0.06 + 0.04 * np.sin(2 * np.pi * 1.7 * s)
        fwd = np.array([math.cos(heading) * math.cos(pitch), math.sin(heading) * math.cos(pitch), math.sin(pitch)])
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        R = np.stack([right, down, fwd])  # rows: camera axes in world
        out[k, :3, :3] = R
        out[k, :3, 3] = -R @ np.array([x, y, z])
        out[k, 3, 3] = 1.0
    return out


# ----------------------------------------------------------------------------------------------
# rendering


def render_views(
    world: SyntheticWorld,
    viewmats: np.ndarray,
    Ks: np.ndarray,
    width: int,
    height: int,
    samples_per_side: int = 2,
    device: str | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Ray-traces N views -> (rgb (N, H, W, 3) float32 in [0, 1], z-depth (N, H, W) float32, 0 = miss)."""
    import warp as wp

    from .._warp import init
    from ..kernels import raytrace

    init()  # wp.init without the no-driver line on a machine without CUDA
    dev = wp.get_device(device) if device is not None else wp.get_preferred_device()
    viewmats = np.asarray(viewmats, np.float64).reshape(-1, 4, 4)
    n = len(viewmats)
    Ks = np.broadcast_to(np.asarray(Ks, np.float64), (n, 3, 3))
    c2w = np.linalg.inv(viewmats)
    with wp.ScopedDevice(dev):
        mesh = wp.Mesh(points=wp.array(world.vertices, dtype=wp.vec3), indices=wp.array(world.faces.reshape(-1), dtype=wp.int32))
        mats = world.materials
        rgb = wp.zeros((n, height, width), dtype=wp.vec3)
        depth = wp.zeros((n, height, width), dtype=float)
        wp.launch(
            raytrace.render_mesh,
            dim=(n, height, width),
            inputs=[
                mesh.id,
                wp.array(world.face_material, dtype=wp.int32),
                wp.array(np.array([m.color_a for m in mats], np.float32), dtype=wp.vec3),
                wp.array(np.array([m.color_b for m in mats], np.float32), dtype=wp.vec3),
                wp.array(np.array([m.pattern for m in mats], np.int32), dtype=wp.int32),
                wp.array(np.array([m.scale for m in mats], np.float32), dtype=float),
                wp.array(np.asarray(world.light_pos, np.float32).reshape(-1, 3), dtype=wp.vec3),
                wp.array(np.asarray(world.light_power, np.float32).reshape(-1, 3), dtype=wp.vec3),
                wp.vec3(*map(float, world.sun_dir)),
                wp.vec3(*map(float, world.sun_color)),
                wp.vec3(*map(float, world.ambient)),
                wp.vec3(*map(float, world.sky_zenith)),
                wp.vec3(*map(float, world.sky_horizon)),
                wp.array(c2w[:, :3, :3].astype(np.float32), dtype=wp.mat33),
                wp.array(c2w[:, :3, 3].astype(np.float32), dtype=wp.vec3),
                wp.array(np.stack([Ks[:, 0, 0], Ks[:, 1, 1], Ks[:, 0, 2], Ks[:, 1, 2]], 1).astype(np.float32), dtype=wp.vec4),
                int(samples_per_side),
                int(world.seed) & 0x7FFFFFFF,
                1.0e4,
            ],
            outputs=[rgb, depth],
        )
        return rgb.numpy().astype(np.float32), depth.numpy().astype(np.float32)


def generate_capture(config: SyntheticConfig | None = None, device: str | None = None) -> SyntheticCapture:
    """Builds the world, walks the camera and renders every frame (in memory; see ``write_dl3dv``)."""
    cfg = config or SyntheticConfig()
    if cfg.kind not in ("room", "street"):
        raise SceneError(f"synthetic scene kind {cfg.kind!r} is unknown (use 'room' or 'street')")
    if cfg.frames < 2 or cfg.width < 8 or cfg.height < 8:
        raise SceneError(f"synthetic scene needs at least 2 frames of 8x8 pixels, got {cfg.frames} of {cfg.width}x{cfg.height}")
    world, (x0, x1, y_of, eye) = (build_room if cfg.kind == "room" else build_street)(cfg.seed)
    rng = np.random.default_rng([cfg.seed, 1])
    viewmats = walk_cameras(rng, cfg.frames, x0, x1, y_of, eye)
    f = 0.5 * cfg.width / math.tan(math.radians(cfg.fov_x_deg) / 2)
    K = np.array([[f, 0, cfg.width / 2], [0, f, cfg.height / 2], [0, 0, 1.0]])
    rgb, depth = render_views(world, viewmats, K, cfg.width, cfg.height, cfg.samples_per_side, device)
    names = [f"frame_{k + 1:05d}" for k in range(cfg.frames)]
    return SyntheticCapture(cfg, world, names, viewmats, K, rgb, depth)


# ----------------------------------------------------------------------------------------------
# DL3DV layout


def _to_png(a: np.ndarray) -> np.ndarray:
    return np.clip(np.round(a * 255.0), 0, 255).astype(np.uint8)


def write_dl3dv(capture: SyntheticCapture, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Writes a capture in DL3DV's layout into ``out_dir`` (which warpgs creates; written atomically)."""
    from PIL import Image

    from .scene import downsample

    out = Path(out_dir)
    cfg = capture.config
    stamp = _stamp_of(cfg)
    if out.exists() and _stamp(out) == stamp:  # this very scene (a parallel run wrote it first)
        return out
    if out.exists() and not overwrite:
        raise SceneError(f"{out}: already exists; refusing to write a synthetic scene over it")
    tmp = out.with_name(out.name + f".tmp{os.getpid()}")
    if tmp.exists():
        shutil.rmtree(tmp)
    K = capture.K
    for sub in ("images", "images_2", "depths", "colmap/sparse/0"):
        (tmp / sub).mkdir(parents=True)
    frames = []
    A = APPLIED_TRANSFORM
    for k, name in enumerate(capture.names):
        Image.fromarray(_to_png(capture.images[k])).save(tmp / "images" / f"{name}.png")
        Image.fromarray(_to_png(downsample(capture.images[k], 2))).save(tmp / "images_2" / f"{name}.png")
        np.save(tmp / "depths" / f"{name}.npy", capture.depths[k].astype(np.float32))
        c2w = A @ np.linalg.inv(capture.viewmats[k])
        c2w[:3, 1:3] *= -1.0  # OpenCV -> OpenGL camera axes
        frames.append(
            {
                "file_path": f"images/{name}.png",
                "transform_matrix": c2w.tolist(),
                "depth_file_path": f"depths/{name}.npy",
                "colmap_im_id": k + 1,
            }
        )
    meta = {
        "w": cfg.width,
        "h": cfg.height,
        "fl_x": float(K[0, 0]),
        "fl_y": float(K[1, 1]),
        "cx": float(K[0, 2]),
        "cy": float(K[1, 2]),
        "k1": 0.0,
        "k2": 0.0,
        "p1": 0.0,
        "p2": 0.0,
        "camera_model": "OPENCV",
        "frames": frames,
        "applied_transform": A[:3].tolist(),
    }
    (tmp / "transforms.json").write_text(json.dumps(meta, indent=1))

    # COLMAP model in the generator's world, with points sampled from the depth maps (like SfM points)
    cams = {1: colmap_io.ColmapCamera(1, "PINHOLE", cfg.width, cfg.height, np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))}
    imgs = {}
    for k, name in enumerate(capture.names):
        vm = capture.viewmats[k]
        imgs[k + 1] = colmap_io.ColmapImage(k + 1, colmap_io.rotmat_to_qvec(vm[:3, :3]), vm[:3, 3].copy(), 1, f"{name}.png")
    xyz, rgb = sample_points(capture, cfg.num_points, np.random.default_rng([cfg.seed, 2]))
    pts = colmap_io.ColmapPoints(np.arange(1, len(xyz) + 1), xyz, _to_png(rgb), np.full(len(xyz), 0.5), np.zeros(len(xyz), np.int64))
    colmap_io.write_model(tmp / "colmap" / "sparse" / "0", cams, imgs, pts, binary=True)
    (tmp / "synthetic.json").write_text(json.dumps(stamp, indent=1))
    # parallel runs on a fresh machine each generate the scene: the first to finish puts its copy in place and
    # the others keep it, and a copy some run may be reading is never removed (only an outdated one is replaced)
    old = None
    try:
        if out.exists():
            if _stamp(out) == stamp:
                return out
            old = out.with_name(out.name + f".old{os.getpid()}")
            os.replace(out, old)
        try:
            os.replace(tmp, out)
        except OSError:
            if _stamp(out) != stamp:  # not a parallel run's copy of the same scene
                raise
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def _stamp_of(cfg: SyntheticConfig) -> dict:
    """What ``synthetic.json`` holds for a scene of ``cfg`` (its format version and every setting)."""
    return {"format_version": FORMAT_VERSION, **asdict(cfg)}


def _stamp(folder: Path) -> dict | None:
    """The ``synthetic.json`` of a scene folder warpgs wrote (None when there is none or it is unreadable)."""
    try:
        return json.loads((Path(folder) / "synthetic.json").read_text())
    except (OSError, ValueError):
        return None


def sample_points(capture: SyntheticCapture, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """``n`` world points (and colours) unprojected from random valid pixels of all frames."""
    N, H, W = capture.depths.shape
    valid = np.argwhere(capture.depths > 0)
    if len(valid) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    pick = valid[rng.choice(len(valid), size=min(n, len(valid)), replace=False)]
    k, i, j = pick.T
    z = capture.depths[k, i, j].astype(np.float64)
    Kinv = np.linalg.inv(capture.K)
    pc = np.stack([j + 0.5, i + 0.5, np.ones_like(z)], 1) @ Kinv.T * z[:, None]
    c2w = np.linalg.inv(capture.viewmats[k])
    xyz = np.einsum("nij,nj->ni", c2w[:, :3, :3], pc) + c2w[:, :3, 3]
    return xyz, capture.images[k, i, j]


def cache_dir() -> Path:
    """Where generated scenes go: $WARPGS_CACHE, else $XDG_CACHE_HOME/warpgs, else ~/.cache/warpgs."""
    if os.environ.get("WARPGS_CACHE"):
        return Path(os.environ["WARPGS_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "warpgs"


def ensure_synthetic(config: SyntheticConfig | None = None, out_dir: str | Path | None = None, device: str | None = None) -> Path:
    """The scene folder for ``config``, generating and writing it first unless a complete copy exists."""
    cfg = config or SyntheticConfig()
    out = Path(out_dir) if out_dir is not None else cache_dir() / "synthetic" / cfg.dirname()
    saved = _stamp(out)
    if saved == _stamp_of(cfg):
        return out
    if saved is not None and out_dir is not None:
        raise SceneError(f"{out}: holds a different synthetic scene ({saved}); choose another folder")
    if saved is None and out.exists() and any(out.iterdir()):
        raise SceneError(f"{out}: exists and is not a synthetic scene written by warpgs; refusing to write into it")
    out.parent.mkdir(parents=True, exist_ok=True)
    # overwrite only an outdated scene of the cache; a copy of this one that a parallel run writes meanwhile is kept
    return write_dl3dv(generate_capture(cfg, device), out, overwrite=saved is not None)


def load_synthetic(
    *,
    views: int | None = 9,
    downscale: int | None = None,
    seed: int = 0,
    width: int = 256,
    height: int = 192,
    frames: int = 24,
    kind: str = "room",
    samples_per_side: int = 2,
    out_dir: str | Path | None = None,
    device: str | None = None,
    load_points: bool = False,
    test_every: int = 8,
    test_rest: bool = False,
) -> Scene:
    """Generates (once, cached) and loads the synthetic walk-through through the DL3DV loader."""
    from .nerfstudio import load_nerfstudio

    cfg = SyntheticConfig(seed=seed, width=width, height=height, frames=frames, kind=kind, samples_per_side=samples_per_side)
    path = ensure_synthetic(cfg, out_dir, device)
    scene = load_nerfstudio(path, views=views, downscale=downscale, test_every=test_every, test_rest=test_rest,
                           load_points=load_points, name=f"synthetic-{kind}-{seed}")
    scene.metadata["synthetic"] = asdict(cfg)
    return scene
