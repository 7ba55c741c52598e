"""Main job: ``python -m warpgs.pipelines.sparse``.

The sparse-view pipeline (training, pseudo views, densification) is being built issue by issue; until
it lands this entry point renders a demo scene of Gaussians with the Warp rasterizer and writes the
colour, depth and alpha images as PNGs, which exercises the whole rendering path on cpu or cuda.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch


def demo_gaussians(n_side: int = 48, seed: int = 0):
    """A textured sphere resting on a checkered floor, as isotropic-ish Gaussians."""
    g = torch.Generator().manual_seed(seed)
    # sphere of radius 0.6 centred at (0, -0.6, 0) (y points down in OpenCV world here)
    u = torch.rand(n_side * n_side * 2, generator=g)
    v = torch.rand(n_side * n_side * 2, generator=g)
    theta, phi = 2 * math.pi * u, torch.acos(2 * v - 1)
    d = torch.stack([torch.sin(phi) * torch.cos(theta), torch.cos(phi), torch.sin(phi) * torch.sin(theta)], -1)
    sphere = 0.6 * d + torch.tensor([0.0, -0.6, 0.0])
    stripes = (torch.floor(theta / (2 * math.pi) * 12) % 2)[:, None]
    sphere_rgb = stripes * torch.tensor([0.9, 0.3, 0.1]) + (1 - stripes) * torch.tensor([0.95, 0.85, 0.2])
    # floor y = 0 on [-2, 2]^2
    xs = torch.linspace(-2, 2, n_side * 2)
    fx, fz = torch.meshgrid(xs, xs, indexing="ij")
    floor = torch.stack([fx.reshape(-1), torch.zeros(fx.numel()), fz.reshape(-1)], -1)
    check = ((torch.floor(floor[:, 0] * 2) + torch.floor(floor[:, 2] * 2)) % 2)[:, None]
    floor_rgb = check * torch.tensor([0.15, 0.2, 0.35]) + (1 - check) * torch.tensor([0.85, 0.85, 0.8])
    means = torch.cat([sphere, floor])
    colors = torch.cat([sphere_rgb, floor_rgb])
    n = means.shape[0]
    scales = torch.full((n, 3), 0.035)
    scales[sphere.shape[0]:, 1] = 0.005  # flat splats on the floor
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1.0
    opacities = torch.full((n,), 0.9)
    return means, quats, scales, opacities, colors


def orbit_viewmat(angle: float, radius: float = 3.2, height: float = -1.2):
    eye = torch.tensor([radius * math.sin(angle), height, -radius * math.cos(angle)])
    target = torch.tensor([0.0, -0.4, 0.0])
    z = (target - eye) / (target - eye).norm()
    x = torch.linalg.cross(torch.tensor([0.0, 1.0, 0.0]), z)  # OpenCV: x = y_down x z
    x = x / x.norm()
    y = torch.linalg.cross(z, x)
    V = torch.eye(4)
    V[:3, :3] = torch.stack([x, y, z])
    V[:3, 3] = -V[:3, :3] @ eye
    return V


def save_png(path: Path, array: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray((np.clip(array, 0, 1) * 255).round().astype(np.uint8)).save(path)


def run_demo(out: Path, device: str, width: int, height: int) -> None:
    from warpgs.render import rasterize

    tensors = [t.to(device) for t in demo_gaussians()]
    K = torch.tensor([[0.9 * width, 0, width / 2], [0, 0.9 * width, height / 2], [0, 0, 1]], device=device)
    bg = torch.tensor([1.0, 1.0, 1.0], device=device)
    t0 = time.perf_counter()
    r = rasterize(*tensors, orbit_viewmat(0.6).to(device), K, width, height, background=bg)
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    dt = time.perf_counter() - t0
    depth = r.depth.cpu().numpy()
    valid = r.alpha.cpu().numpy() > 0.5
    dn = np.zeros_like(depth)
    if valid.any():
        lo, hi = np.percentile(depth[valid], [1, 99])
        dn = np.where(valid, 1 - (depth - lo) / max(hi - lo, 1e-6), 0)
    save_png(out / "render.png", r.image.cpu().numpy())
    save_png(out / "depth.png", dn)
    save_png(out / "alpha.png", r.alpha.cpu().numpy())
    print(f"rendered {tensors[0].shape[0]} Gaussians at {width}x{height} on {device} in {dt * 1000:.0f} ms "
          f"(first call includes kernel compilation)")
    print(f"wrote {out / 'render.png'}, {out / 'depth.png'}, {out / 'alpha.png'}")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m warpgs.pipelines.sparse", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("outputs/demo"), help="output folder")
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu", help="cpu or cuda")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.device.startswith("cuda") and not torch.cuda.is_available():
        print("error: --device cuda was asked for, but torch sees no CUDA device", file=sys.stderr)
        return 2
    run_demo(args.out, args.device, args.width, args.height)
    return 0


if __name__ == "__main__":
    sys.exit(main())
