"""Frames per second of the web viewer's own render path (``python -m warpgs.view``), in one process.

    python bench/perf/viewer_fps.py --device cuda                         # 200k Gaussians, 1280x720 (the issue's figure)
    python bench/perf/viewer_fps.py --device cpu --gaussians 20000 --size 320x180 --frames 10
    python bench/perf/viewer_fps.py --device cuda --ply outputs/lego/point_cloud.ply

A ``warpgs.view.Viewer`` is started (its viser server on a free local port, no browser) on a model of
``--gaussians`` random Gaussians (SH degree 3, scales 0.3-1.5% of the scene, opacities 0.1-0.9, in a
cube of side 2; or the model of ``--ply``), and one ``FrameLoop`` (the per-browser frame thread's code)
renders ``--frames`` frames of a camera orbiting the model at ``--size``, after ``--warmup`` frames. Each
frame is what a browser gets: ``render_image`` (the rasterizer, the copy to the host as uint8) and the JPEG
encoding viser applies in ``set_background_image`` (its own encoder function). Timed per frame with
``time.perf_counter`` (the copy to the host synchronises the GPU). Writes JSON (``--out``, default
``bench/results/perf/viewer_fps_<device>.json``): median and mean milliseconds of the render and of render +
encoding, and the frames per second they give.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.data.stress import look_along  # noqa: E402
from warpgs.model import GaussianModel  # noqa: E402
from warpgs.view import FrameLoop, Run, Viewer  # noqa: E402


def random_model(n: int, device, seed: int = 0) -> GaussianModel:
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) * 2 - 1
    quats = torch.randn(n, 4, generator=g)
    scales = torch.log(0.006 + 0.024 * torch.rand(n, 3, generator=g))
    opac = torch.logit(0.1 + 0.8 * torch.rand(n, generator=g))
    sh0 = torch.randn(n, 1, 3, generator=g) * 0.5
    shN = torch.randn(n, 15, 3, generator=g) * 0.05
    m = GaussianModel(means, quats, scales, opac, sh0, shN, max_sh_degree=3)
    m.active_sh_degree = 3
    return m.to(device)


def orbit(k: int, frames: int, centre: np.ndarray, radius: float) -> np.ndarray:
    """World-to-camera of frame ``k`` of a circle around ``centre`` (OpenCV axes, looking at it)."""
    a = 2 * math.pi * k / max(frames, 1)
    eye = centre + radius * np.array([math.sin(a), -0.3, -math.cos(a)])
    return look_along(eye, centre - eye, np.array([0.0, -1.0, 0.0]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--gaussians", type=int, default=200_000)
    ap.add_argument("--ply", default=None, help="a trained 3D-GS PLY instead of random Gaussians")
    ap.add_argument("--size", default="1280x720", help="WIDTHxHEIGHT of every frame")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    from viser._image_encoding import cv2_imencode_with_fallback  # what set_background_image encodes with

    width, height = (int(v) for v in a.size.lower().split("x"))
    device = torch.device(a.device)
    model = GaussianModel.load_ply(a.ply, device=device) if a.ply else random_model(a.gaussians, device)
    p = model.means.detach().cpu().numpy().astype(np.float64)
    centre = np.median(p, axis=0)
    radius = 2.2 * float(np.percentile(np.linalg.norm(p - centre, axis=1), 90))

    viewer = Viewer(Run(name="bench", model=model), host="127.0.0.1", port=0, res=max(width, height),
                    preview_res=max(width, height))
    state = {"k": 0, "encode_s": []}

    def camera():
        return orbit(state["k"], a.frames, centre, radius), math.radians(50), width, height  # vertical fov 50 degrees

    def send(img, final):
        t = time.perf_counter()
        cv2_imencode_with_fallback("jpeg", img, 85 if final else 60, "rgb")
        state["encode_s"].append(time.perf_counter() - t)

    loop = FrameLoop(viewer, camera, send)
    render_s, total_s, covered = [], [], []
    try:
        for k in range(a.warmup + a.frames):
            state["k"] = k
            t = time.perf_counter()
            img = loop.render_once(final=True)
            total = time.perf_counter() - t
            if k >= a.warmup:
                render_s.append(loop.last_render_s)
                total_s.append(total)
                covered.append(float((img.max(-1) > 0).mean()))
            assert img.shape == (height, width, 3)
    finally:
        loop.stop()
        viewer.close()

    def ms(v):
        return {"median": 1000 * statistics.median(v), "mean": 1000 * statistics.fmean(v), "max": 1000 * max(v)}

    res = {
        "what": "warpgs.view frame path: render_image (rasterize + uint8 to host) and viser's JPEG encoding, one process",
        "device": str(device),
        "device_name": torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor() or platform.machine(),
        "torch": torch.__version__,
        "cpu_count": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],  # other work on the machine (a shared CPU slows the figure)
        "gaussians": len(model),
        "model": a.ply or "random (SH degree 3, cube of side 2)",
        "size": [width, height],
        "frames": a.frames,
        "warmup": a.warmup,
        "render_ms": ms(render_s),
        "render_encode_ms": ms(total_s),
        "fps_render": 1000.0 / ms(render_s)["median"],
        "fps_render_encode": 1000.0 / ms(total_s)["median"],
        "covered_fraction": statistics.fmean(covered),
    }
    out = Path(a.out or ROOT / "bench" / "results" / "perf" / f"viewer_fps_{device.type}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(f"{len(model):,} Gaussians at {width}x{height} on {res['device_name']}: render {res['render_ms']['median']:.1f} ms "
          f"({res['fps_render']:.1f} fps), with JPEG {res['render_encode_ms']['median']:.1f} ms "
          f"({res['fps_render_encode']:.1f} fps); wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
