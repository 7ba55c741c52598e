"""The one scene type every loader returns, and the small helpers they share.

Cameras follow the library's convention (see ``warpgs/__init__.py``): OpenCV axes (x right, y down,
z forward), ``viewmat`` the 4x4 world-to-camera matrix, ``K`` the 3x3 intrinsics in pixels with pixel
(j, i) centred at (j + 0.5, i + 0.5). Loaders convert their format's convention once, here at the
boundary, and nothing downstream needs to know where a scene came from.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import DatasetNotFoundError, SceneError  # noqa: F401 (they belong to the scene's interface)
from .plausible import check_camera




@dataclass
class Camera:
    """One view: camera, image and optional per-pixel extras (numpy arrays; see ``to_torch``)."""

    name: str
    viewmat: np.ndarray  # (4, 4) float32, world -> camera, OpenCV axes
    K: np.ndarray  # (3, 3) float32, pixels
    width: int
    height: int
    image: np.ndarray  # (H, W, 3) float32 in [0, 1]
    mask: np.ndarray | None = None  # (H, W) bool, True = inside the object / valid
    depth: np.ndarray | None = None  # (H, W) float32 z-depth along the camera axis; 0 = unknown
    image_path: str | None = None
    alpha: np.ndarray | None = None  # (H, W) float32 opacity of an RGBA source (image is composited over the scene's background)

    @property
    def c2w(self) -> np.ndarray:
        """Camera-to-world 4x4 (float64)."""
        return np.linalg.inv(self.viewmat.astype(np.float64))

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates (float64, shape (3,))."""
        R, t = self.viewmat[:3, :3].astype(np.float64), self.viewmat[:3, 3].astype(np.float64)
        return -R.T @ t

    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction (camera +z) in world coordinates."""
        return self.viewmat[2, :3].astype(np.float64)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) -> pixel coordinates (N, 2) in the library's convention and z-depth (N,)."""
        p = np.asarray(points, np.float64) @ self.viewmat[:3, :3].T.astype(np.float64) + self.viewmat[:3, 3]
        z = p[:, 2]
        uv = p @ self.K.T.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = uv[:, :2] / uv[:, 2:3]
        return uv, z

    def to_torch(self, device: Any = "cpu") -> "CameraTensors":
        """The same view as torch tensors on ``device`` (image (H, W, 3) float32, viewmat/K float32)."""
        import torch  # deferred: loading data needs no torch

        def t(a, dtype=None):
            return None if a is None else torch.as_tensor(np.ascontiguousarray(a), dtype=dtype, device=device)

        return CameraTensors(
            name=self.name,
            viewmat=t(self.viewmat, torch.float32),
            K=t(self.K, torch.float32),
            width=self.width,
            height=self.height,
            image=t(self.image, torch.float32),
            mask=t(self.mask, torch.bool),
            depth=t(self.depth, torch.float32),
            alpha=t(self.alpha, torch.float32),
        )


@dataclass
class CameraTensors:
    """A ``Camera`` with its arrays as torch tensors (see ``Camera.to_torch``)."""

    name: str
    viewmat: Any
    K: Any
    width: int
    height: int
    image: Any
    mask: Any = None
    depth: Any = None
    alpha: Any = None


@dataclass
class Scene:
    """A loaded scene: train/test views, bounds and what the source says about its world.

    ``world_transform`` is the 4x4 similarity (scale, rotation, translation) that maps the source's
    reference world (the frame of its poses as stored on disk, which is also the frame of its COLMAP
    points) to the world the cameras here are expressed in. Apply it to anything else given in the
    source's frame, e.g. ``(world_transform @ [x, 1])[:3]``.
    """

    name: str
    train: list[Camera]
    test: list[Camera]
    bounds: tuple[float, float]  # (near, far) z-depths that contain the scene, in loaded-world units
    world_transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    points3d: np.ndarray | None = None  # (N, 3) float32, loaded world
    points_rgb: np.ndarray | None = None  # (N, 3) float32 in [0, 1]
    white_background: bool = False
    eval_masked: bool = False  # evaluate test views inside Camera.mask only (DTU protocol)
    metadata: dict[str, Any] = field(default_factory=dict)
    geometry: Any = None  # warpgs.points.Geometry found from the training views (model.init sfm / stereo)
    # True when the loader had no depth and no points and ``bounds`` is ``bounds_from_cameras``'s loose guess:
    # the initial geometry measures them (warpgs.train.prepare_geometry)
    bounds_guessed: bool = False

    @property
    def cameras(self) -> list[Camera]:
        return self.train + self.test

    def summary(self) -> str:
        v = self.train[0] if self.train else (self.test[0] if self.test else None)
        res = f"{v.width}x{v.height}" if v is not None else "-"
        return (
            f"{self.name}: {len(self.train)} train / {len(self.test)} test views at {res}, "
            + ("depth bounds to be measured on the initial geometry" if self.bounds_guessed
               else f"bounds {self.bounds[0]:.3g}..{self.bounds[1]:.3g}")
            + (f", {len(self.points3d)} points" if self.points3d is not None else "")
        )


# ----------------------------------------------------------------------------------------------
# helpers shared by the loaders


def intrinsics(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], np.float64)


def number(value, field: str, source: str) -> float:
    """``value`` (a scene file's ``field``) as a float; ``SceneError`` naming the field when it is not a number."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str, np.number)):
        raise SceneError(f"{source}: {field} = {value!r} is not a number")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{source}: {field} = {value!r} is not a number") from None


def check_intrinsics(source: str, positive: dict[str, float], finite: dict[str, float] | None = None) -> None:
    """Each of ``positive`` (focal lengths, image sizes: by the name the file gives them) must be a finite
    number above 0 and each of ``finite`` (principal point) a finite number; ``SceneError`` names the
    first field that is not."""
    for name, v in positive.items():
        if not (np.isfinite(float(v)) and v > 0):
            raise SceneError(f"{source}: invalid intrinsics: {name} = {v!r} (must be a finite number > 0)")
    for name, v in (finite or {}).items():
        if not np.isfinite(float(v)):
            raise SceneError(f"{source}: invalid intrinsics: {name} = {v!r} (must be a finite number)")


def check_pose(m: np.ndarray, source: str, what: str = "pose", atol: float = 1e-3) -> np.ndarray:
    """Checks that ``m`` (3x4 or 4x4) is a finite rigid transform; returns it as 4x4 float64."""
    try:
        m = np.asarray(m, np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{source}: {what} is not a matrix of numbers ({str(m)[:60]})") from None
    if m.shape not in ((3, 4), (4, 4)):
        raise SceneError(f"{source}: {what} has shape {m.shape}, expected 3x4 or 4x4")
    if not np.all(np.isfinite(m)):
        raise SceneError(f"{source}: {what} contains non-finite values (NaN or inf)")
    out = np.eye(4)
    out[: m.shape[0]] = m
    if m.shape == (4, 4) and not np.allclose(m[3], [0, 0, 0, 1], atol=1e-6):
        raise SceneError(f"{source}: {what} has last row {m[3].tolist()}, expected [0, 0, 0, 1]")
    R = out[:3, :3]
    with np.errstate(over="ignore", invalid="ignore"):  # huge entries: err is inf, refused below
        err = np.abs(R.T @ R - np.eye(3)).max()
        det = np.linalg.det(R)
    if not err <= atol or det < 0:
        raise SceneError(
            f"{source}: {what} is not rigid (rotation part has |R^T R - I| = {err:.3g}, det = {det:.4g}); "
            "warpgs needs camera poses that are a rotation and a translation"
        )
    # remove the small non-orthogonality that text formats leave (a few 1e-7)
    u, _, vt = np.linalg.svd(R)
    out[:3, :3] = u @ vt
    return out


def similarity_apply_c2w(W: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Expresses camera-to-world ``c2w`` in the world reached by the similarity ``W`` (x' = W x)."""
    s = np.cbrt(np.linalg.det(W[:3, :3]))
    out = np.eye(4)
    out[:3, :3] = (W[:3, :3] / s) @ c2w[:3, :3]
    out[:3, 3] = W[:3, :3] @ c2w[:3, 3] + W[:3, 3]
    return out


def transform_points(W: np.ndarray, pts: np.ndarray) -> np.ndarray:
    pts = np.asarray(pts, np.float64)
    return pts @ W[:3, :3].T + W[:3, 3]


def make_camera(
    name: str,
    c2w: np.ndarray,
    K: np.ndarray,
    image: np.ndarray,
    mask: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    image_path: str | Path | None = None,
    alpha: np.ndarray | None = None,
) -> Camera:
    """Builds a ``Camera`` from an OpenCV camera-to-world pose (float64 in, float32 stored)."""
    h, w = image.shape[:2]
    with np.errstate(all="ignore"):  # values out of float32's range become inf: refused below
        viewmat = np.linalg.inv(c2w)
        viewmat[3] = [0, 0, 0, 1]
        viewmat32, K32 = viewmat.astype(np.float32), np.asarray(K, np.float32)
    for what, a in (("intrinsics", K32), ("pose", viewmat32)):
        if not np.all(np.isfinite(a)):
            raise SceneError(f"{image_path or name}: its camera's {what} are out of range (not finite as float32: "
                             f"{np.asarray(K if what == 'intrinsics' else c2w).ravel()[:4].tolist()}...)")
    check_camera(str(image_path or name), K, int(w), int(h))
    return Camera(
        name=name,
        viewmat=viewmat32,
        K=K32,
        width=int(w),
        height=int(h),
        image=image,
        mask=mask,
        depth=None if depth is None else depth.astype(np.float32),
        image_path=None if image_path is None else str(image_path),
        alpha=None if alpha is None else np.asarray(alpha, np.float32),
    )


def opengl_to_opencv_c2w(c2w_gl: np.ndarray) -> np.ndarray:
    """OpenGL/Blender camera axes (x right, y up, z back) -> OpenCV (x right, y down, z forward)."""
    c2w = np.array(c2w_gl, np.float64, copy=True)
    c2w[:3, 1:3] *= -1.0
    return c2w


def bounds_from_points(cams_c2w: list[np.ndarray], points: np.ndarray, pad: float = 0.1) -> tuple[float, float]:
    """Near/far z-depths containing the 0.5..99.5 percentile of ``points`` seen from the cameras."""
    zs = []
    for c2w in cams_c2w:
        w2c = np.linalg.inv(c2w)
        z = points @ w2c[2, :3] + w2c[2, 3]
        zs.append(z[z > 0])
    z = np.concatenate(zs) if zs else np.zeros(0)
    if z.size < 10:
        return bounds_from_cameras(cams_c2w)
    near, far = np.percentile(z, 0.5), np.percentile(z, 99.5)
    return float(max(near * (1 - pad), 1e-3)), float(far * (1 + pad))


def bounds_from_cameras(cams_c2w: list[np.ndarray]) -> tuple[float, float]:
    """A loose guess when nothing better is known: near 1% and far 10x of the cameras' extent."""
    centres = np.stack([c[:3, 3] for c in cams_c2w])
    extent = float(np.linalg.norm(centres - centres.mean(0), axis=1).max()) if len(centres) > 1 else 1.0
    extent = max(extent, 1e-3)
    return 0.01 * extent, 10.0 * extent


# ----------------------------------------------------------------------------------------------
# image files

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".JPG", ".JPEG", ".PNG", ".bmp", ".tif", ".tiff", ".exr")


def channels_of(mode: str, info: dict | None = None) -> str:
    """What a PIL image mode holds, in words: RGB, RGBA, grayscale, grayscale with alpha, palette, ..."""
    if mode in ("1", "L", "I", "F") or mode.startswith("I;"):
        return "grayscale"
    if mode in ("LA", "La"):
        return "grayscale with alpha"
    if mode in ("P", "PA"):
        return "palette with alpha" if mode == "PA" or "transparency" in (info or {}) else "palette"
    if mode in ("RGBA", "RGBa"):
        return "RGBA"
    return mode


class ImageChannels:
    """The channels of every image a loader reads (``read_image(..., channels=this)``). A capture whose
    images differ (a grayscale or RGBA frame among RGB ones) is converted image by image to RGB, and
    ``note()`` says so in one line, naming the odd images; None when they all agree."""

    def __init__(self):
        self.kinds: dict[str, str] = {}

    def add(self, path, kind: str) -> None:
        self.kinds[str(path)] = kind

    def note(self, source) -> str | None:
        from collections import Counter

        counts = Counter(self.kinds.values())
        if len(counts) <= 1:
            return None
        main = max(counts, key=lambda k: (counts[k], k in ("RGB", "RGBA")))  # a tie: the colour images are the rule
        odd = [(p, k) for p, k in self.kinds.items() if k != main]
        shown = ", ".join(f"{Path(p).name} ({k})" for p, k in odd[:3]) + (f" and {len(odd) - 3} more" if len(odd) > 3 else "")
        alpha = any("alpha" in k or k == "RGBA" for _, k in odd)
        return (f"warpgs: note: {source}: {len(odd)} of {len(self.kinds)} images are not {main} like the rest and were "
                f"converted to RGB{' (alpha composited over the background)' if alpha else ''}: {shown}")

    def warn(self, source) -> None:
        """Prints ``note(source)`` (once), if there is one."""
        msg = self.note(source)
        if msg:
            from warpgs.console import warn_once

            warn_once(msg)


def read_image(path: str | Path, background: tuple[float, float, float] | None = None,
               channels: ImageChannels | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Reads an image as float32 (H, W, 3) in [0, 1] and its alpha (H, W) float32 or None.

    With ``background`` given and an alpha channel present, RGB is composited over it
    (straight alpha: rgb * a + background * (1 - a)). ``channels`` records what the file held.
    """
    from PIL import Image

    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: image file is missing")
    try:
        with Image.open(path) as im:
            im.load()
            mode = im.mode
            if channels is not None:
                channels.add(path, channels_of(mode, im.info))
            if mode in ("I;16", "I;16B", "I;16L", "I"):
                a = np.asarray(im, np.float32)
                a = a / (65535.0 if a.max() > 255 else 255.0)
                rgb, alpha = np.repeat(a[..., None], 3, axis=2), None
            else:
                has_alpha = mode in ("RGBA", "LA", "PA") or (mode == "P" and "transparency" in im.info)
                arr = np.asarray(im.convert("RGBA" if has_alpha else "RGB"), np.float32) / 255.0
                rgb = arr[..., :3]
                alpha = arr[..., 3] if has_alpha else None
    except SceneError:
        raise
    except Exception as e:  # PIL raises many kinds
        raise SceneError(f"{path}: cannot read image ({e})") from e
    if background is not None and alpha is not None:
        rgb = rgb * alpha[..., None] + np.asarray(background, np.float32) * (1.0 - alpha[..., None])
    return np.ascontiguousarray(rgb, dtype=np.float32), alpha


def image_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an image file without decoding it."""
    from PIL import Image

    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: image file is missing")
    try:
        with Image.open(path) as im:
            return im.size
    except Exception as e:
        raise SceneError(f"{path}: cannot read image ({e})") from e


def read_mask(path: str | Path) -> np.ndarray:
    """A mask image -> (H, W) bool (any channel above half intensity; alpha if the file has one)."""
    rgb, alpha = read_image(path)
    m = alpha if alpha is not None and alpha.min() < 1.0 else rgb.max(axis=2)
    return m > 0.5


def read_depth(path: str | Path, png_scale: float = 1e-3) -> np.ndarray:
    """A depth map: ``.npy`` (float, scene units) or a 16-bit PNG times ``png_scale``."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: depth file is missing")
    if path.suffix == ".npy":
        try:
            d = np.load(path)
        except Exception as e:
            raise SceneError(f"{path}: cannot read depth ({e})") from e
    else:
        from PIL import Image

        with Image.open(path) as im:
            d = np.asarray(im, np.float32) * png_scale
    d = np.asarray(d, np.float32)
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[..., 0]
    if d.ndim != 2:
        raise SceneError(f"{path}: depth has shape {d.shape}, expected (H, W)")
    if not np.all(np.isfinite(d)):
        raise SceneError(f"{path}: depth contains non-finite values (use 0 for unknown)")
    return d


def downsample(a: np.ndarray, factor: int) -> np.ndarray:
    """Box-filter downsampling by an integer factor (crops to a multiple of it)."""
    if factor == 1:
        return a
    h, w = a.shape[0] // factor, a.shape[1] // factor
    b = a[: h * factor, : w * factor].reshape(h, factor, w, factor, *a.shape[2:])
    if a.dtype == bool:
        return b.mean(axis=(1, 3)) > 0.5
    return b.mean(axis=(1, 3)).astype(a.dtype)


def downsample_depth(d: np.ndarray, factor: int) -> np.ndarray:
    """Depth downsampling: mean of the valid (> 0) depths per block, 0 where none (approximate at edges)."""
    if factor == 1:
        return d
    h, w = d.shape[0] // factor, d.shape[1] // factor
    b = d[: h * factor, : w * factor].reshape(h, factor, w, factor)
    valid = b > 0
    n = valid.sum(axis=(1, 3))
    s = np.where(valid, b, 0).sum(axis=(1, 3))
    return np.where(n > 0, s / np.maximum(n, 1), 0).astype(np.float32)


def resize_image(a: np.ndarray, width: int, height: int) -> np.ndarray:
    """Resizes a float image (H, W[, C]) with PIL's antialiasing filter (area-like when shrinking)."""
    from PIL import Image

    if a.shape[1] == width and a.shape[0] == height:
        return a
    if a.dtype == bool:
        im = Image.fromarray(a.astype(np.uint8) * 255).resize((width, height), Image.NEAREST)
        return np.asarray(im) > 127
    chans = [a] if a.ndim == 2 else [a[..., c] for c in range(a.shape[2])]
    out = [np.asarray(Image.fromarray(c.astype(np.float32), mode="F").resize((width, height), Image.BOX)) for c in chans]
    return (out[0] if a.ndim == 2 else np.stack(out, axis=2)).astype(np.float32)


def list_images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix in IMAGE_EXTS and not p.name.startswith("."))
