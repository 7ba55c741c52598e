"""Look at point clouds and Gaussian centres: an open3d window, or a PNG rendered without a display.

    python -m warpgs.viz cloud.ply                      # open3d window
    python -m warpgs.viz cloud.ply --png view.png       # the same view to an image, headless
    python -m warpgs.viz point_cloud.ply --png v.png --color rgb --size 1280x960 --point-size 3

Reads any vertex PLY (through ``warpgs.ply``, i.e. plyfile): a plain point cloud (``red/green/blue``), a 3D-GS Gaussian
file (centres coloured by their DC colour), or a densification cloud written by ``save_origin_ply``,
whose ``origin`` property marks each point kept (an existing Gaussian), added (a new Gaussian) or
removed (a stereo point dropped as an outlier); with ``--color auto`` (default) such a cloud is
coloured by origin, with a legend.

Headless PNG: open3d's legacy ``Visualizer`` with an invisible window. Without a display it falls back
to an EGL offscreen context, which Mesa's software rasteriser (llvmpipe) provides on a machine
without a GPU; that is the renderer used where it works (open3d 0.20's Filament ``OffscreenRenderer``
needs Vulkan, which such machines lack). Where no EGL context can be made, or it returns a blank
frame, a numpy point-splat renderer draws the same camera view (z-buffered square splats of the
same size); ``--renderer`` picks one explicitly, and the chosen one is printed.

The camera looks at the cloud's robust bounding box (1st-99th percentiles) along its least principal
axis, at a distance that fits the box in a 60-degree field of view (``default_camera``), in the
library's convention (OpenCV axes, world-to-camera ``viewmat``, ``K`` in pixels).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from warpgs.console import filtered_stderr
from warpgs.ply import gaussian_fields, keep_finite, read_elements, require, write_vertices

def to_uint8(image) -> np.ndarray:
    """[H, W, 3] or [H, W] values in [0, 1] (numpy or torch) as 8-bit values; NaN becomes 0."""
    a = image.detach().float().cpu().numpy() if hasattr(image, "detach") else np.asarray(image, np.float32)
    return (np.clip(np.nan_to_num(a), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def save_image(path: str | Path, image, compress_level: int = 6) -> Path:
    """Saves [H, W, 3] or [H, W] values in [0, 1] (numpy or torch; uint8 as they are) as an 8-bit PNG; NaN is
    written as 0. ``compress_level`` is zlib's (1: fastest, 9: smallest; PIL's default 6)."""
    from PIL import Image

    a = image if isinstance(image, np.ndarray) and image.dtype == np.uint8 else to_uint8(image)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(a).save(path, compress_level=compress_level)
    return path


ORIGIN_KEPT = 0  # an existing Gaussian centre      (values of the PLY's 'origin' property)
ORIGIN_ADDED = 1  # a new Gaussian from the stereo cloud
ORIGIN_REMOVED = 2  # a stereo point dropped as an outlier
ORIGIN_NAMES = ("kept", "added", "removed")
ORIGIN_COLORS = np.array([[0.45, 0.50, 0.62], [0.10, 0.72, 0.20], [0.90, 0.12, 0.10]], np.float32)
SH_C0 = 0.28209479177387814


# ----------------------------------------------------------------------------------------------
# PLY


def read_cloud(path: str | Path, drop_invalid: bool = False) -> dict:
    """{'points' [N, 3] float32, 'colors' [N, 3] in [0, 1] or None, 'origin' [N] uint8 or None,
    'kind': 'points' | 'gaussians' | 'mesh'} from any PLY with vertices. Points (for a Gaussian file: Gaussians,
    every field) with non-finite values are refused with their count (``ValueError``), or with
    ``drop_invalid`` dropped with one warning line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    raw, counts = read_elements(path)
    names = tuple(raw)
    if not all(k in names for k in ("x", "y", "z")):
        raise ValueError(f"{path}: PLY vertices have no x, y, z")
    points = np.stack([raw["x"], raw["y"], raw["z"]], 1).astype(np.float32)
    colors, kind = None, "mesh" if counts.get("face", 0) else "points"
    if any(k.startswith("f_dc_") for k in names):  # a 3D-GS file: every column a Gaussian needs
        require(names, [k for k in gaussian_fields(0) if k not in ("nx", "ny", "nz")], path, "3D-GS PLY")
        kind = "gaussians"
        colors = np.clip(np.stack([raw[f"f_dc_{i}"] for i in range(3)], 1) * SH_C0 + 0.5, 0, 1).astype(np.float32)
    else:
        for keys in (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
            if all(k in names for k in keys):
                c = np.stack([raw[k] for k in keys], 1)
                colors = (c.astype(np.float32) / 255.0) if c.dtype.kind in "ui" else c.astype(np.float32)
                break
    origin = np.asarray(raw["origin"], np.uint8) if "origin" in names else None
    cols = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    if kind == "gaussians":  # a Gaussian is invalid when any of its values is (opacity, scales, rotation too)
        cols.update({k: np.asarray(raw[k]) for k in names if k not in cols})
    elif colors is not None and colors.dtype.kind == "f":
        cols.update({f"colour_{i}": colors[:, i] for i in range(colors.shape[1])})
    rows = {"points": points, "colors": colors, "origin": origin}
    kept = keep_finite({**cols, **{f"_{k}": a for k, a in rows.items() if a is not None}}, list(cols), path,
                       drop_invalid, what="Gaussians" if kind == "gaussians" else "points")
    return {**{k: kept.get(f"_{k}") for k in rows}, "kind": kind}


def save_origin_ply(path: str | Path, points, colors=None, origin=None) -> Path:
    """Binary PLY of points (x, y, z float32), colours (8-bit red/green/blue) and, if given, the
    'origin' (uchar: 0 kept, 1 added, 2 removed) that ``python -m warpgs.viz`` colours by."""
    p = np.asarray(points, np.float32).reshape(-1, 3)
    n = len(p)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if origin is not None:
        fields += [("origin", "u1")]
    rec = np.zeros(n, dtype=fields)
    rec["x"], rec["y"], rec["z"] = p[:, 0], p[:, 1], p[:, 2]
    if colors is not None:
        c = np.clip(np.round(np.asarray(colors, np.float32).reshape(n, -1)[:, :3] * 255.0), 0, 255).astype(np.uint8)
        rec["red"], rec["green"], rec["blue"] = c[:, 0], c[:, 1], c[:, 2]
    if origin is not None:
        o = np.asarray(origin).reshape(-1)
        if len(o) != n or (o > 2).any():
            raise ValueError("origin must hold one value in {0, 1, 2} per point")
        rec["origin"] = o
    return write_vertices(path, rec)


# ----------------------------------------------------------------------------------------------
# camera and rendering


def default_camera(points: np.ndarray, width: int, height: int, fov_deg: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """(K [3, 3], viewmat [4, 4]) looking at the robust bounding box of ``points`` along its least
    principal axis, at a distance that fits the box in the field of view."""
    p = np.asarray(points, np.float64)
    p = p[np.isfinite(p).all(1)]
    f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])
    if len(p) == 0:
        vm = np.eye(4)
        vm[2, 3] = 1.0
        return K, vm
    lo, hi = np.percentile(p, 1, axis=0), np.percentile(p, 99, axis=0)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * np.linalg.norm(hi - lo), 1e-6)
    core = p[np.all((p >= lo) & (p <= hi), 1)]
    core = core if len(core) >= 3 else p
    _, _, vt = np.linalg.svd(core - core.mean(0), full_matrices=False) if len(core) >= 3 else (None, None, np.eye(3))
    axes = np.eye(3) if vt.shape[0] < 3 else vt
    fwd = axes[2] / np.linalg.norm(axes[2])
    up_hint = axes[1]
    # look slightly from above the plane of the two main axes, so depth reads in the image
    fwd = fwd + 0.35 * up_hint
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, -up_hint)
    if np.linalg.norm(right) < 1e-6:
        right = np.cross(fwd, [0.0, 0.0, 1.0] if abs(fwd[2]) < 0.9 else [1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    dist = radius / np.sin(np.radians(min(fov_deg, fov_deg * height / width)) / 2)
    eye = centre - fwd * dist
    R = np.stack([right, down, fwd])
    vm = np.eye(4)
    vm[:3, :3] = R
    vm[:3, 3] = -R @ eye
    return K, vm


def splat_render(points, colors, K, viewmat, width: int, height: int, point_size: float = 2.0,
                 background=(1.0, 1.0, 1.0)) -> np.ndarray:
    """[H, W, 3] float32: each point a square of ``point_size`` pixels at its projection, nearest
    point wins (z-buffer); the library's camera convention."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    c = np.asarray(colors, np.float32).reshape(-1, 3)
    img = np.empty((height, width, 3), np.float32)
    img[:] = np.asarray(background, np.float32)
    xc = p @ viewmat[:3, :3].T + viewmat[:3, 3]
    z = xc[:, 2]
    ok = np.isfinite(z) & (z > 1e-6)
    uv = (xc[ok] @ np.asarray(K, np.float64).T)
    uv = uv[:, :2] / uv[:, 2:3]
    z, c = z[ok], c[ok]
    size = max(1, int(round(point_size)))
    j0 = np.floor(uv[:, 0] - 0.5 * (size - 1)).astype(np.int64)  # the square's first column and row
    i0 = np.floor(uv[:, 1] - 0.5 * (size - 1)).astype(np.int64)
    depth = np.full(height * width, np.inf)
    best = np.full(height * width, -1, np.int64)
    order = np.argsort(-z, kind="stable")  # far to near
    for di in range(size):
        for dj in range(size):
            ii, jj = i0[order] + di, j0[order] + dj
            inside = (ii >= 0) & (ii < height) & (jj >= 0) & (jj < width)
            flat, idx = ii[inside] * width + jj[inside], order[inside]
            win = z[idx] < depth[flat]
            # with repeated pixels numpy keeps the last write, the nearest point (order is far to near)
            depth[flat[win]] = z[idx[win]]
            best[flat[win]] = idx[win]
    best = best.reshape(height, width)
    hit = best >= 0
    img[hit] = c[best[hit]]
    return img


def open3d_render(points, colors, K, viewmat, width: int, height: int, point_size: float = 2.0,
                  background=(1.0, 1.0, 1.0)) -> np.ndarray:
    """[H, W, 3] float32 from open3d's legacy Visualizer in an invisible window (EGL offscreen without
    a display). Raises RuntimeError where no context can be made."""
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)  # no "falling back to EGL" notes
    # Mesa's EGL says "XDG_RUNTIME_DIR is invalid or not set" on machines without a desktop session; it
    # needs no runtime folder for an offscreen frame, so that line does not apply (anything else it says stays)
    with filtered_stderr(["XDG_RUNTIME_DIR"]):
        vis = o3d.visualization.Visualizer()
        if not vis.create_window(window_name="warpgs", width=width, height=height, visible=False):
            raise RuntimeError("open3d could not create an offscreen window (no display and no EGL)")
        try:
            _setup_open3d(vis, points, colors, K, viewmat, width, height, point_size, background)
            vis.poll_events()
            vis.update_renderer()
            img = np.asarray(vis.capture_screen_float_buffer(do_render=True), np.float32)
        finally:
            vis.destroy_window()
    if img.shape[:2] != (height, width):
        raise RuntimeError(f"open3d returned a {img.shape[1]}x{img.shape[0]} frame, {width}x{height} was asked for")
    return img


def _setup_open3d(vis, points, colors, K, viewmat, width, height, point_size, background) -> None:
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64).reshape(-1, 3)))
    pcd.colors = o3d.utility.Vector3dVector(np.clip(np.asarray(colors, np.float64).reshape(-1, 3), 0, 1))
    vis.add_geometry(pcd)
    opt = vis.get_render_option()
    opt.point_size = float(point_size)
    opt.background_color = np.asarray(background, np.float64)
    params = o3d.camera.PinholeCameraParameters()
    # open3d puts pixel centres at integers; the library at +0.5
    params.intrinsic = o3d.camera.PinholeCameraIntrinsic(width, height, float(K[0, 0]), float(K[1, 1]),
                                                         float(K[0, 2]) - 0.5, float(K[1, 2]) - 0.5)
    params.extrinsic = np.asarray(viewmat, np.float64)
    vis.get_view_control().convert_from_pinhole_camera_parameters(params, allow_arbitrary=True)


def _legend(img: np.ndarray, counts: list[int]) -> np.ndarray:
    from PIL import Image, ImageDraw

    im = Image.fromarray(np.clip(np.round(img * 255), 0, 255).astype(np.uint8))
    d = ImageDraw.Draw(im)
    s = max(8, img.shape[0] // 40)
    y = s // 2
    for k, (name, n) in enumerate(zip(ORIGIN_NAMES, counts)):
        col = tuple(int(v * 255) for v in ORIGIN_COLORS[k])
        d.rectangle([s // 2, y, s // 2 + s, y + s], fill=col, outline=(0, 0, 0))
        d.text((2 * s, y), f"{name}: {n}", fill=(0, 0, 0))
        y += int(1.5 * s)
    return np.asarray(im, np.float32) / 255.0


def cloud_colors(cloud: dict, color: str = "auto") -> np.ndarray:
    """[N, 3] display colours: by origin ('origin'; 'auto' when the cloud has one), the file's own
    ('rgb'; grey where it has none)."""
    n = len(cloud["points"])
    if color not in ("auto", "rgb", "origin"):
        raise ValueError(f"color must be auto, rgb or origin, got {color!r}")
    if color == "origin" or (color == "auto" and cloud.get("origin") is not None):
        if cloud.get("origin") is None:
            raise ValueError("this cloud has no 'origin' property (write it with warpgs.viz.save_origin_ply)")
        return ORIGIN_COLORS[np.minimum(cloud["origin"], 2)]
    if cloud.get("colors") is not None:
        return cloud["colors"]
    return np.full((n, 3), 0.4, np.float32)


def render_png(cloud: dict, out: str | Path, width: int = 960, height: int = 720, point_size: float = 2.0,
               color: str = "auto", renderer: str = "auto", background=(1.0, 1.0, 1.0)) -> str:
    """Renders ``cloud`` (``read_cloud``'s dict) from ``default_camera`` to ``out``; returns the
    renderer used ('open3d-egl' or 'numpy-splat')."""
    from PIL import Image

    pts = cloud["points"]
    cols = cloud_colors(cloud, color)
    K, vm = default_camera(pts, width, height)
    img, used = None, None
    if renderer in ("auto", "open3d"):
        try:
            img = open3d_render(pts, cols, K, vm, width, height, point_size, background)
            used = "open3d-egl"
            if renderer == "auto" and len(pts) and np.all(np.abs(img - np.asarray(background, np.float32)) < 1e-6):
                img, used = None, None  # a blank frame from a broken context: draw it ourselves
        except Exception as e:  # no EGL here
            if renderer == "open3d":
                raise RuntimeError(f"open3d cannot render offscreen here ({e}); use --renderer numpy") from e
    if img is None:
        if renderer not in ("auto", "numpy"):
            raise ValueError(f"renderer must be auto, open3d or numpy, got {renderer!r}")
        img = splat_render(pts, cols, K, vm, width, height, point_size, background)
        used = "numpy-splat"
    if (color == "origin" or (color == "auto" and cloud.get("origin") is not None)) and cloud.get("origin") is not None:
        img = _legend(img, [int((cloud["origin"] == k).sum()) for k in range(3)])
    out = Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"{out}: the folder {out.parent} does not exist (create it first)")
    Image.fromarray(np.clip(np.round(img * 255), 0, 255).astype(np.uint8)).save(out)
    return used


def show(cloud: dict, width: int = 960, height: int = 720, point_size: float = 2.0, color: str = "auto",
         background=(1.0, 1.0, 1.0)) -> None:
    """An interactive open3d window on the cloud, starting from ``default_camera``."""
    import open3d as o3d

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise RuntimeError("no display (DISPLAY / WAYLAND_DISPLAY unset): use --png out.png to render headless")
    pts = cloud["points"]
    K, vm = default_camera(pts, width, height)
    vis = o3d.visualization.Visualizer()
    if not vis.create_window(window_name="warpgs.viz", width=width, height=height, visible=True):
        raise RuntimeError("open3d could not open a window")
    _setup_open3d(vis, pts, cloud_colors(cloud, color), K, vm, width, height, point_size, background)
    vis.run()
    vis.destroy_window()


class OneLineParser(argparse.ArgumentParser):
    """argparse whose refusals are one line, ``error: ...``, and exit code 2 (no usage block)."""

    def error(self, message: str):
        print(f"error: {message} (see {self.prog} --help)", file=sys.stderr)
        sys.exit(2)


def main(argv=None) -> int:
    ap = OneLineParser(prog="python -m warpgs.viz", description="Show a point cloud or Gaussian centres (PLY).")
    ap.add_argument("ply", help="point cloud, 3D-GS PLY, or a densification cloud with an 'origin' property")
    ap.add_argument("--png", default=None, help="render to this PNG instead of opening a window (no display needed)")
    ap.add_argument("--color", default="auto", choices=["auto", "rgb", "origin"],
                    help="auto: by origin (kept / added / removed) when the file has it, else its colours")
    ap.add_argument("--size", default="960x720", help="WIDTHxHEIGHT (default 960x720)")
    ap.add_argument("--point-size", type=float, default=2.0)
    ap.add_argument("--renderer", default="auto", choices=["auto", "open3d", "numpy"], help="for --png")
    ap.add_argument("--background", default="1,1,1", help="r,g,b in [0, 1]")
    ap.add_argument("--drop-invalid", action="store_true",
                    help="drop points / Gaussians with non-finite values (one warning) instead of refusing the file")
    a = ap.parse_args(argv)
    try:
        width, height = (int(v) for v in a.size.lower().split("x"))
        bg = tuple(float(v) for v in a.background.split(","))
        if len(bg) != 3:
            raise ValueError
    except ValueError:
        ap.error("--size is WIDTHxHEIGHT and --background is r,g,b")
    try:
        if a.png and not Path(a.png).resolve().parent.is_dir():
            raise ValueError(f"--png {a.png}: the folder {Path(a.png).resolve().parent} does not exist (create it first)")
        if width < 1 or height < 1 or width * height > 1 << 26:
            raise ValueError(f"--size {a.size}: width and height must be positive, at most 2^26 pixels in all")
        cloud = read_cloud(a.ply, drop_invalid=a.drop_invalid)
        counts = ""
        if cloud["origin"] is not None:
            counts = " (" + ", ".join(f"{n} {int((cloud['origin'] == k).sum())}" for k, n in enumerate(ORIGIN_NAMES)) + ")"
        print(f"{a.ply}: {len(cloud['points'])} {cloud['kind']}{counts}")
        if a.png:
            used = render_png(cloud, a.png, width, height, a.point_size, a.color, a.renderer, bg)
            print(f"wrote {a.png} ({width}x{height}, renderer: {used})")
        else:
            show(cloud, width, height, a.point_size, a.color, bg)
    except (OSError, ValueError, RuntimeError, MemoryError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
