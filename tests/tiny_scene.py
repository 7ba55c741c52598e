"""A tiny ground-truth scene for the training tests: Gaussians rendered by the rasterizer from known cameras.

The ground truth is a cluster of coloured Gaussians around the origin; cameras sit on a circle of
radius 4 looking at it. Images are tiny (48x48 by default) so that a few hundred training steps take
seconds on one CPU thread.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import torch

from warpgs.config import Config
from warpgs.data.scene import Camera, Scene, make_camera
from warpgs.render import rasterize


def look_at_c2w(eye, target=(0.0, 0.0, 0.0), up=(0.0, -1.0, 0.0)) -> np.ndarray:
    """OpenCV camera-to-world (x right, y down, z forward) at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([x, y, z], 1)
    c2w[:3, 3] = eye
    return c2w


def gt_gaussians(n: int = 40, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g) * 2 - 1) * 0.9
    quats = torch.randn(n, 4, generator=g)
    scales = 0.12 + 0.18 * torch.rand(n, 3, generator=g)
    opac = 0.6 + 0.35 * torch.rand(n, generator=g)
    colors = torch.rand(n, 3, generator=g)
    return means, quats, scales, opac, colors


def camera_ring(angles_deg, radius=4.0, height=-0.8):
    return [look_at_c2w((radius * math.sin(math.radians(a)), height, -radius * math.cos(math.radians(a))))
            for a in angles_deg]


def render_views(c2ws, width, height, focal, gaussians, prefix, background=(0.0, 0.0, 0.0),
                 device="cpu") -> list[Camera]:
    """The views of ``gaussians`` from the cameras ``c2ws``, rendered on ``device`` (a GPU machine whose Warp has no
    CPU compiler renders them there)."""
    K = np.array([[focal, 0, width / 2], [0, focal, height / 2], [0, 0, 1]], np.float64)
    bg = torch.tensor(background, dtype=torch.float32, device=device)
    gaussians = [g.to(device) for g in gaussians]
    cams = []
    for i, c2w in enumerate(c2ws):
        V = torch.tensor(np.linalg.inv(c2w), dtype=torch.float32, device=device)
        img = rasterize(*gaussians, V, torch.tensor(K, dtype=torch.float32, device=device), width, height,
                        background=bg).image.cpu()
        cams.append(make_camera(f"{prefix}{i:02d}", c2w, K, img.numpy().astype(np.float32)))
    return cams


def make_scene(width=48, height=48, train_angles=(0, 35, 70), test_angles=(18, 52), seed=0, masked=False,
               device="cpu") -> Scene:
    gs = gt_gaussians(seed=seed)
    focal = 1.1 * width
    train = render_views(camera_ring(train_angles), width, height, focal, gs, "train", device=device)
    test = render_views(camera_ring(test_angles), width, height, focal, gs, "test", device=device)
    if masked:
        for c in train + test:
            c.mask = np.zeros((height, width), bool)
            c.mask[height // 4: 3 * height // 4, width // 4: 3 * width // 4] = True
    return Scene(name="tiny", train=train, test=test, bounds=(2.5, 5.5), eval_masked=masked)


def write_nerfstudio(folder: Path, n_frames: int = 10) -> Path:
    """Writes frames on a ring as a nerfstudio capture (transforms.json + PNGs) the loaders read."""
    from PIL import Image

    folder = Path(folder)
    (folder / "images").mkdir(parents=True, exist_ok=True)
    gs = gt_gaussians()
    c2ws = camera_ring(np.linspace(0, 80, n_frames))
    w = h = 48
    focal = 1.1 * w
    cams = render_views(c2ws, w, h, focal, gs, "frame")
    frames = []
    for i, (cam, c2w) in enumerate(zip(cams, c2ws)):
        Image.fromarray((np.clip(cam.image, 0, 1) * 255 + 0.5).astype(np.uint8)).save(folder / "images" / f"f{i:03d}.png")
        gl = c2w.copy()
        gl[:3, 1:3] *= -1  # OpenCV -> OpenGL axes
        frames.append({"file_path": f"images/f{i:03d}.png", "transform_matrix": gl.tolist()})
    meta = {"w": w, "h": h, "fl_x": focal, "fl_y": focal, "cx": w / 2, "cy": h / 2, "camera_model": "OPENCV",
            "frames": frames}
    (folder / "transforms.json").write_text(json.dumps(meta))
    return folder


def tiny_config(iterations: int = 300, lpips_weights: str = "/nonexistent/alexnet.pth", **train) -> Config:
    """The training config the tests use on the tiny scene: CPU, 300 random Gaussians in a box,
    densification from step 30 every 20 (opacity resets every 120), a budget of 800 Gaussians;
    ``train`` sets further ``train.*`` fields."""
    cfg = Config()
    cfg.train.device = "cpu"
    cfg.train.progress = False
    cfg.train.iterations = iterations
    cfg.train.checkpoint_every = 0
    cfg.train.sh_degree_interval = 100
    for k, v in train.items():
        setattr(cfg.train, k, v)
    cfg.model.init = "box"
    cfg.model.init_box = [-1.2, -1.2, -1.2, 1.2, 1.2, 1.2]
    cfg.model.init_num = 300
    s = cfg.strategy
    s.refine_start_iter, s.refine_every, s.refine_stop_iter, s.reset_every = 30, 20, 250, 120
    s.max_gaussians = 800
    cfg.eval.fps_repeats = 1
    cfg.eval.lpips_weights = lpips_weights
    return cfg


def param_copy(trainer) -> dict:
    """A copy of a trainer's model parameters (to compare states)."""
    return {k: v.detach().clone() for k, v in trainer.model.params.items()}


def same_params(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def small_full_trainer(tmp_path, *extra):
    """(config, trainer): the full method, 40 steps on the CPU, on the 3-view stress scene at a
    quarter size, without densification; ``extra``: more command-line arguments."""
    from warpgs.data.stress import stress_scene
    from warpgs.pipelines.sparse import build_parser, make_config, make_trainer

    args = build_parser().parse_args([
        "--method", "full", "--iterations", "40", "--device", "cpu", "--no-progress", "--set", "pseudo.trajectory.n_frames=4",
        "--set", "pseudo.sampler.steps=3", "--set", "model.init_num=300", "--set", "full.densify=false",
        "--set", "eval.lpips_weights=/nonexistent/alexnet.pth", *extra])
    cfg, _ = make_config(args)
    return cfg, make_trainer(cfg, stress_scene("views_3", downscale=4), tmp_path)



def record_loss_parts(trainer) -> list[dict]:
    """Wraps ``trainer.method.loss_terms``: the list it returns gets the parts of every step's loss, in order."""
    seen: list[dict] = []
    loss_terms = trainer.method.loss_terms

    def record(out, cam, loss, parts):
        total = loss_terms(out, cam, loss, parts)
        seen.append(dict(parts))
        return total

    trainer.method.loss_terms = record
    return seen


def full_method_trainer(out, device: str, iterations: int, *extra: str):
    """The full method on the 3-view stress scene at a quarter size, as the CUDA graph tests run it: both cycles,
    one input and one pseudo view a step, the stereo's depth priors, the binocular term from the first step,
    dropout; ``extra``: more command-line arguments (``--set KEY=VALUE``)."""
    from warpgs.data.stress import stress_scene
    from warpgs.pipelines.sparse import build_parser, make_config, make_trainer

    args = build_parser().parse_args([
        "--method", "full", "--iterations", str(iterations), "--device", device, "--no-progress",
        "--set", "pseudo.trajectory.n_frames=4", "--set", "pseudo.sampler.steps=3", "--set", "model.init_num=300",
        "--set", "eval.lpips_weights=/nonexistent/alexnet.pth",
        "--set", "regularizers.binocular.weight=1.0", "--set", "regularizers.binocular.start=0.0",
        "--set", "regularizers.dropout.rate=0.2", *extra])
    cfg, _ = make_config(args)
    return make_trainer(cfg, stress_scene("views_3", downscale=4, device=device), out)
