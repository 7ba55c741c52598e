"""Captures: nerfstudio ``transforms.json`` (DL3DV's layout) and COLMAP folders.

DL3DV scenes ship a nerfstudio ``transforms.json`` (global intrinsics ``w, h, fl_x, fl_y, cx, cy``,
distortion ``k1, k2, p1, p2`` with ``camera_model``, frames with ``file_path`` and an OpenGL
camera-to-world ``transform_matrix``, and ``applied_transform``, the 3x4 that nerfstudio applied to
the COLMAP world to make those poses), image folders ``images``, ``images_2``, ``images_4``,
``images_8`` (full resolution and downscaled by 2, 4, 8), and the COLMAP model under
``colmap/sparse/0``. Either description can be loaded; the split is the LLFF/DL3DV rule of
``splits.every_nth_split`` over frames sorted by file name.

Poses are used as stored (no recentring or rescaling): the loaded world is the frame of the poses,
and ``Scene.world_transform`` maps the COLMAP world into it (``applied_transform``, or the identity).
Lens distortion is removed by resampling each image onto the pinhole camera with the same K (OpenCV)
(``undistort=True``) or refused with an error (``undistort=False``); it is never ignored.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from . import colmap as colmap_io
from .plausible import check_distortion, check_frames, check_listed
from .scene import (
    Camera,
    ImageChannels,
    Scene,
    SceneError,
    bounds_from_cameras,
    bounds_from_points,
    check_intrinsics,
    check_pose,
    downsample,
    downsample_depth,
    image_size,
    intrinsics,
    make_camera,
    number,
    opengl_to_opencv_c2w,
    read_depth,
    read_image,
    read_mask,
    transform_points,
)
from .splits import every_nth_split

DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2")
FISHEYE_MODELS = ("OPENCV_FISHEYE", "FISHEYE", "EQUIRECTANGULAR", "FOV", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE",
                  "THIN_PRISM_FISHEYE", "RAD_TAN_THIN_PRISM_FISHEYE")
COLMAP_MODEL_DIRS = ("colmap/sparse/0", "sparse/0", "sparse", "colmap/sparse", ".")


# ----------------------------------------------------------------------------------------------
# shared pieces


def undistort_image(a: np.ndarray, K: np.ndarray, dist: dict[str, float], nearest: bool = False) -> np.ndarray:
    """``a`` (H, W[, C]) resampled from the distorted camera onto the pinhole camera with the same K, by
    OpenCV (``initUndistortRectifyMap`` + ``remap``; edges replicated): bilinear, or ``nearest`` for masks
    and depth. OpenCV's radial-tangential model (k1..k6 rational, p1, p2) covers COLMAP's SIMPLE_RADIAL,
    RADIAL, OPENCV and FULL_OPENCV and nerfstudio's OPENCV. ``K`` is in the library's convention (pixel
    centres at +0.5); OpenCV puts them at integers, hence the half-pixel shift of the principal point."""
    import cv2

    h, w = a.shape[:2]
    g = {k: float(dist.get(k, 0.0)) for k in DISTORTION_KEYS}
    coeffs = np.array([g["k1"], g["k2"], g["p1"], g["p2"], g["k3"], g["k4"], g["k5"], g["k6"]], np.float64)
    Kcv = np.asarray(K, np.float64).copy()
    Kcv[0, 2] -= 0.5
    Kcv[1, 2] -= 0.5
    map_x, map_y = cv2.initUndistortRectifyMap(Kcv, coeffs, None, Kcv, (w, h), cv2.CV_32FC1)
    src = a.astype(np.uint8) if a.dtype == bool else a
    out = cv2.remap(src, map_x, map_y, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.astype(a.dtype).reshape(a.shape)


def _has_distortion(dist: dict[str, float]) -> bool:
    return any(abs(float(dist.get(k, 0.0))) > 0 for k in DISTORTION_KEYS)


def _refuse_model(model: str, source: str) -> None:
    if model.upper() in FISHEYE_MODELS:
        raise SceneError(
            f"{source}: camera model {model} is not supported; undistort the images to a pinhole camera first "
            "(e.g. `colmap image_undistorter` or `ns-process-data ... --camera-type perspective`)"
        )


def _resolve_image(root: Path, rel: str, downscale: int | None, source: str) -> tuple[Path, int]:
    """Finds a frame's image for a downscale factor -> (path, factor still to apply in memory).

    ``images/x.png`` with downscale d is looked up as ``images_d/x.png``; when that folder lacks it
    but the full-resolution file exists, it is downscaled in memory (nothing is written).
    With ``downscale=None`` the file as named is used, else the first of ``images_2/4/8`` holding it.
    """
    rel_path = Path(rel)
    full = root / rel_path
    parts = rel_path.parts
    folder = parts[0] if len(parts) > 1 else ""

    def scaled(d: int) -> Path | None:
        if d == 1:
            return full
        if folder:
            return root / Path(f"{folder}_{d}", *parts[1:])
        return None

    tried = []
    if downscale is None:
        if full.is_file():
            return full, 1
        tried.append(full)
        for d in (2, 4, 8):
            p = scaled(d)
            if p is not None and p.is_file():
                return p, 1
            if p is not None:
                tried.append(p)
    else:
        p = scaled(downscale)
        if p is not None and p.is_file():
            return p, 1
        if p is not None:
            tried.append(p)
        if full.is_file():
            return full, downscale
        tried.append(full)
    raise SceneError(f"{source}: file {rel!r} is missing (looked for " + ", ".join(str(t) for t in tried) + ")")


def _folder_factor(path: Path) -> int | None:
    """The downscale factor its folder's name gives an image (``images_4/x.jpg``: 4), or None."""
    head, _, tail = path.parent.name.rpartition("_")
    return int(tail) if head and tail.isdigit() and int(tail) > 0 else None


def _check_size(actual: tuple[int, int], w: float, h: float, downscale: int | None, path: Path, source: str) -> None:
    """The image must be the intrinsics' w x h reduced by one factor (the requested one, or 1, 2, 4, 8
    for folders whose intrinsics were already rescaled), within a pixel of rounding."""
    for d in dict.fromkeys([downscale or 1, 1, 2, 4, 8]):
        if abs(actual[0] - w / d) <= 1.0 and abs(actual[1] - h / d) <= 1.0:
            return
    folder = _folder_factor(path)  # a file in images_4/ is expected at a quarter, whatever its size suggests
    d = folder or downscale
    where = f"in {path.parent.name}/" if folder else f"at downscale {d}"
    raise SceneError(
        f"{path}: image is {actual[0]}x{actual[1]} but {source} gives {w:g}x{h:g}"
        + (f" (expected {int(w // d)}x{int(h // d)} {where})" if d and d > 1 else "")
        + "; mixed image sizes or a wrong downscale folder"
    )


# ----------------------------------------------------------------------------------------------
# nerfstudio transforms.json


def find_transforms(path: str | Path) -> Path:
    path = Path(path)
    if path.is_file():
        return path
    for cand in (path / "transforms.json", path / "nerfstudio" / "transforms.json"):
        if cand.is_file():
            return cand
    raise SceneError(f"{path}: no transforms.json here (nor in {path / 'nerfstudio'})")


def load_nerfstudio(
    path: str | Path,
    *,
    views: int | None = None,
    downscale: int | None = None,
    test_every: int = 8,
    test_rest: bool = False,
    white_background: bool = False,
    undistort: bool = True,
    load_depth: bool = True,
    load_points: bool = False,
    name: str | None = None,
) -> Scene:
    """Loads a nerfstudio ``transforms.json`` capture (DL3DV layout).

    ``views``: training views (None = every non-test frame). ``downscale``: 1, 2, 4, 8 selects the
    ``images_d`` folder (intrinsics scaled to the images found); None uses the files as named.
    ``test_rest``: every frame not trained on is a test view (see ``every_nth_split``).
    ``load_points``: also return the COLMAP points (triangulated from all frames, so they see the
    test views: use them for checking, not to initialise a sparse-view run).
    """
    tf = find_transforms(path)
    root = tf.parent
    try:
        meta = json.loads(tf.read_text())
    except Exception as e:
        raise SceneError(f"{tf}: cannot parse JSON ({e})") from e
    if not isinstance(meta, dict):
        raise SceneError(f"{tf}: expected a JSON object at the top level, got {type(meta).__name__}")
    frames = meta.get("frames")
    if not isinstance(frames, list) or not frames:
        raise SceneError(f"{tf}: no 'frames' list")
    for k, fr in enumerate(frames):
        if not isinstance(fr, dict):
            raise SceneError(f"{tf}: frame {k} is {type(fr).__name__}, not an object")
        if "file_path" not in fr:
            raise SceneError(f"{tf}: frame {k} has no 'file_path'")
        if not isinstance(fr["file_path"], str) or not fr["file_path"].strip():
            raise SceneError(f"{tf}: frame {k}: file_path = {fr['file_path']!r} is not a file name")
        if "transform_matrix" not in fr:
            raise SceneError(f"{tf}: frame {k} ({fr['file_path']}) has no pose ('transform_matrix')")
    frames = sorted(frames, key=lambda f: str(f["file_path"]))
    names = [str(f["file_path"]) for f in frames]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise SceneError(f"{tf}: frames listed more than once: {dup[:5]}")
    check_listed(str(tf), [(n, root / n) for n in names])

    train_idx, test_idx = every_nth_split(len(frames), views, test_every, test_rest, str(tf))

    A = np.eye(4)
    if "applied_transform" in meta:
        at = np.asarray(meta["applied_transform"], np.float64)
        A = check_pose(at, str(tf), "applied_transform")

    def get(fr, key, default=None):
        return fr.get(key, meta.get(key, default))

    bg = (1.0, 1.0, 1.0) if white_background else (0.0, 0.0, 0.0)
    png_depth_scale = number(meta.get("depth_unit_scale_factor", 1e-3), "depth_unit_scale_factor", str(tf))
    sizes: dict[tuple[int, int], str] = {}
    channels = ImageChannels()

    def load_frame(k: int) -> Camera:
        fr = frames[k]
        src = f"{tf} frame {fr['file_path']!r}"
        c2w = opengl_to_opencv_c2w(check_pose(fr["transform_matrix"], src, "transform_matrix"))
        model = str(get(fr, "camera_model", "OPENCV"))
        _refuse_model(model, src)
        img_path, extra = _resolve_image(root, fr["file_path"], downscale, src)
        W_img, H_img = image_size(img_path)
        W_img, H_img = W_img // extra, H_img // extra
        w, h = get(fr, "w"), get(fr, "h")
        if w is None or h is None:
            w, h = W_img * (downscale or 1), H_img * (downscale or 1)
        w, h = number(w, "w", src), number(h, "h", src)
        check_intrinsics(src, {"w": w, "h": h})
        # the image's own scale relative to the intrinsics (nerfstudio floors w/d when downscaling)
        d = downscale if downscale is not None else max(1, round(w / max(W_img, 1)))
        _check_size((W_img, H_img), w, h, d, img_path, f"{tf.name} (w, h)")
        sizes.setdefault((W_img, H_img), str(img_path))
        if len(sizes) > 1 and "w" not in fr:  # frames sharing one set of intrinsics share one size
            first_size, first_path = next(iter(sizes.items()))
            raise SceneError(f"{img_path}: image is {W_img}x{H_img} but {first_path} is {first_size[0]}x{first_size[1]}; mixed image sizes")
        sx, sy = W_img / w, H_img / h
        if "fl_x" in fr or "fl_x" in meta:
            fx = number(get(fr, "fl_x"), "fl_x", src)
            fy = number(get(fr, "fl_y", fx), "fl_y", src)
            check_intrinsics(src, {"fl_x": fx, "fl_y": fy})
        elif "camera_angle_x" in meta or "camera_angle_x" in fr:
            angles = {k: number(get(fr, k), k, src) for k in ("camera_angle_x", "camera_angle_y") if get(fr, k) is not None}
            for k, a in angles.items():
                if not (np.isfinite(a) and 0 < a < math.pi):
                    raise SceneError(f"{src}: invalid intrinsics: {k} = {a!r} (a field of view in radians, "
                                     "between 0 and pi)")
            fx = 0.5 * w / math.tan(0.5 * angles["camera_angle_x"])
            fy = 0.5 * h / math.tan(0.5 * angles["camera_angle_y"]) if "camera_angle_y" in angles else fx
        else:
            raise SceneError(f"{tf}: no focal length (fl_x or camera_angle_x) for frame {fr['file_path']!r}")
        cx, cy = number(get(fr, "cx", w / 2), "cx", src), number(get(fr, "cy", h / 2), "cy", src)
        check_intrinsics(src, {}, {"cx": cx, "cy": cy})
        K = intrinsics(fx * sx, fy * sy, cx * sx, cy * sy)

        rgb, _ = read_image(img_path, bg, channels)
        rgb = downsample(rgb, extra)
        mask = depth = None
        if fr.get("mask_path"):
            mp, mextra = _resolve_image(root, fr["mask_path"], d, src)
            mask = downsample(read_mask(mp), mextra)
            if mask.shape != rgb.shape[:2]:
                raise SceneError(f"{mp}: mask is {mask.shape[1]}x{mask.shape[0]} but image {img_path} is {rgb.shape[1]}x{rgb.shape[0]}")
        dpath = fr.get("depth_file_path") or fr.get("depth_path")
        if load_depth and dpath:
            depth = _load_depth(root, str(dpath), rgb.shape[:2], png_depth_scale, src)

        dist = {key: number(get(fr, key, 0.0), key, src) for key in DISTORTION_KEYS}
        if not all(np.isfinite(v) for v in dist.values()):
            raise SceneError(f"{src}: distortion {({k: v for k, v in dist.items() if not np.isfinite(v)})} is not finite")
        check_distortion(src, dist, K, rgb.shape[1], rgb.shape[0])
        if _has_distortion(dist):
            if not undistort:
                raise SceneError(
                    f"{src}: the camera has lens distortion {({k: v for k, v in dist.items() if v})}; "
                    "load with undistort=True (resamples to a pinhole camera) or undistort the images first"
                )
            rgb = undistort_image(rgb, K, dist)
            if mask is not None:
                mask = undistort_image(mask, K, dist, nearest=True)
            if depth is not None:
                depth = undistort_image(depth, K, dist, nearest=True)
        return make_camera(Path(fr["file_path"]).stem, c2w, K, rgb, mask, depth, img_path)

    train = [load_frame(k) for k in train_idx]
    test = [load_frame(k) for k in test_idx]
    channels.warn(tf)

    points = rgbs = None
    sparse = _find_colmap_near(root)
    pts_world = None
    if sparse is not None:
        try:
            pts = colmap_io.read_points3d(sparse)
            if len(pts.ids):
                pts_world = transform_points(A, pts.xyz)
                if load_points:
                    points, rgbs = pts_world.astype(np.float32), (pts.rgb / 255.0).astype(np.float32)
        except SceneError:
            if load_points:
                raise
    elif load_points:
        raise SceneError(f"{tf}: load_points asked but no COLMAP model found near it (looked in {', '.join(COLMAP_MODEL_DIRS)})")

    bounds = _bounds(train, pts_world)
    return check_frames(Scene(
        bounds_guessed=_bounds_guessed(train, pts_world),
        name=name or _scene_name(root),
        train=train,
        test=test,
        bounds=bounds,
        world_transform=A,
        points3d=points,
        points_rgb=rgbs,
        white_background=white_background,
        metadata={
            "format": "nerfstudio",
            "source": str(tf),
            "frame_names": names,
            "train_ids": train_idx,
            "test_ids": test_idx,
            "downscale": downscale,
            "world_transform_from": "COLMAP world (applied_transform)" if "applied_transform" in meta else "identity",
        },
    ))


def _scene_name(root: Path) -> str:
    return root.parent.name if root.name == "nerfstudio" else root.name


def _find_colmap_near(root: Path) -> Path | None:
    for base in (root, root.parent):
        for sub in COLMAP_MODEL_DIRS[:-1]:
            p = base / sub
            if (p / "points3D.bin").is_file() or (p / "points3D.txt").is_file():
                return p
    return None


def _load_depth(root: Path, rel: str, shape: tuple[int, int], png_scale: float, src: str) -> np.ndarray:
    p = root / rel
    d = read_depth(p, png_scale)
    if d.shape == shape:
        return d
    f = d.shape[0] // shape[0] if shape[0] else 0
    # a downscaled copy next to the full one (depths_4/ for depths/), else block-averaged
    parts = Path(rel).parts
    if f > 1 and len(parts) > 1:
        alt = root / Path(f"{parts[0]}_{f}", *parts[1:])
        if alt.is_file():
            d2 = read_depth(alt, png_scale)
            if d2.shape == shape:
                return d2
    if f >= 1 and d.shape[0] // f == shape[0] and d.shape[1] // f == shape[1]:
        return downsample_depth(d, f)
    raise SceneError(f"{p}: depth is {d.shape[1]}x{d.shape[0]} but the image is {shape[1]}x{shape[0]} ({src})")


def _bounds_guessed(cams: list[Camera], points: np.ndarray | None) -> bool:
    """Whether ``_bounds`` falls back to the cameras' extent (no depth maps, no points)."""
    return not _has_depth(cams) and not (points is not None and len(points) > 10)


def _has_depth(cams: list[Camera]) -> bool:
    return sum(int((c.depth > 0).sum()) for c in cams if c.depth is not None) > 100


def _bounds(cams: list[Camera], points: np.ndarray | None) -> tuple[float, float]:
    depths = [c.depth[c.depth > 0] for c in cams if c.depth is not None]
    if _has_depth(cams):
        z = np.concatenate(depths)
        return float(max(np.percentile(z, 0.1) * 0.9, 1e-3)), float(z.max() * 1.1)
    c2ws = [c.c2w for c in cams]
    if points is not None and len(points) > 10:
        return bounds_from_points(c2ws, points)
    return bounds_from_cameras(c2ws)


# ----------------------------------------------------------------------------------------------
# COLMAP folder


def find_colmap_model(path: str | Path) -> Path:
    path = Path(path)
    for sub in COLMAP_MODEL_DIRS:
        p = path / sub
        if p.is_dir():
            try:
                colmap_io.find_model_files(p)
                return p
            except SceneError:
                pass
    raise SceneError(f"{path}: no COLMAP model (looked in " + ", ".join(str(path / s) for s in COLMAP_MODEL_DIRS) + ")")


def _find_images_dir(root: Path, model: Path, downscale: int | None) -> tuple[Path, int]:
    """The image folder of a COLMAP scene: ``images`` (or ``images_d``) beside the model or the scene root."""
    bases = []
    for b in (root, model.parent.parent if model.parent.name == "sparse" else model.parent, model.parent):
        if b not in bases:
            bases.append(b)
    tried = []
    for b in bases:
        if downscale and downscale > 1:
            p = b / f"images_{downscale}"
            if p.is_dir():
                return p, 1
            tried.append(p)
        p = b / "images"
        if p.is_dir():
            return p, (downscale or 1)
        tried.append(p)
    raise SceneError(f"{root}: no image folder for the COLMAP model in {model} (looked in " + ", ".join(map(str, tried)) + ")")


def load_colmap(
    path: str | Path,
    *,
    views: int | None = None,
    downscale: int | None = None,
    test_every: int = 8,
    white_background: bool = False,
    undistort: bool = True,
    load_points: bool = False,
    images_dir: str | Path | None = None,
    name: str | None = None,
) -> Scene:
    """Loads a COLMAP scene: a folder with ``sparse/0`` (or ``colmap/sparse/0``, ``sparse``) and ``images``.

    Poses are COLMAP's own (world-to-camera, OpenCV axes), so ``world_transform`` is the identity.
    ``downscale`` d reads ``images_d`` when present, else downsamples ``images`` in memory; K is scaled
    to the images found. Images without a registered pose are not used (COLMAP could not place them).
    """
    root = Path(path)
    model = find_colmap_model(root)
    cams, imgs, pts = colmap_io.read_model(model, with_points=True)
    if not imgs:
        raise SceneError(f"{model}: the model has no registered images")
    img_dir, extra = (Path(images_dir), 1) if images_dir is not None else _find_images_dir(root, model, downscale)
    order = sorted(imgs.values(), key=lambda im: im.name)
    train_idx, test_idx = every_nth_split(len(order), views, test_every, source=str(model))
    bg = (1.0, 1.0, 1.0) if white_background else (0.0, 0.0, 0.0)
    channels = ImageChannels()

    def load_frame(k: int) -> Camera:
        im = order[k]
        src = f"{model} image {im.name!r}"
        if im.camera_id not in cams:
            raise SceneError(f"{src}: refers to camera {im.camera_id}, which cameras.* does not define")
        cam = cams[im.camera_id]
        _refuse_model(cam.model, src)
        if not (np.all(np.isfinite(im.qvec)) and np.all(np.isfinite(im.tvec))) or np.linalg.norm(im.qvec) < 1e-8:
            raise SceneError(f"{src}: pose contains non-finite values or a zero quaternion")
        c2w = np.linalg.inv(check_pose(im.viewmat(), src, "pose"))
        fx, fy, cx, cy = cam.pinhole()
        focal = {"f": fx} if cam.model in colmap_io.SINGLE_FOCAL_MODELS else {"fx": fx, "fy": fy}
        check_intrinsics(f"{model}/cameras.* camera {cam.id} ({cam.model})",
                         {"width": cam.width, "height": cam.height, **focal}, {"cx": cx, "cy": cy})
        dist = cam.distortion()
        bad = {k: v for k, v in dist.items() if not np.isfinite(v)}
        if bad:
            raise SceneError(f"{model}/cameras.* camera {cam.id} ({cam.model}): distortion {bad} is not finite")
        p = img_dir / im.name
        W_img, H_img = image_size(p)
        W_img, H_img = W_img // extra, H_img // extra
        _check_size((W_img, H_img), cam.width, cam.height, downscale, p, f"{model.name}/cameras.* (camera {cam.id})")
        sx, sy = W_img / cam.width, H_img / cam.height
        K = intrinsics(fx * sx, fy * sy, cx * sx, cy * sy)
        rgb, _ = read_image(p, bg, channels)
        rgb = downsample(rgb, extra)
        check_distortion(src, dist, K, rgb.shape[1], rgb.shape[0])
        if _has_distortion(dist):
            if not undistort:
                raise SceneError(f"{src}: camera {cam.id} ({cam.model}) has lens distortion {dist}; "
                                 "load with undistort=True or undistort the images first (colmap image_undistorter)")
            rgb = undistort_image(rgb, K, dist)
        return make_camera(Path(im.name).stem, c2w, K, rgb, image_path=p)

    train = [load_frame(k) for k in train_idx]
    test = [load_frame(k) for k in test_idx]
    channels.warn(model)
    pts_xyz = pts.xyz if pts is not None and len(pts.ids) else None
    return check_frames(Scene(
        name=name or (root.name if root.name not in ("0", "sparse") else root.parent.name),
        train=train,
        test=test,
        bounds=_bounds(train, pts_xyz),
        bounds_guessed=_bounds_guessed(train, pts_xyz),
        world_transform=np.eye(4),
        points3d=None if not (load_points and pts_xyz is not None) else pts_xyz.astype(np.float32),
        points_rgb=None if not (load_points and pts_xyz is not None) else (pts.rgb / 255.0).astype(np.float32),
        white_background=white_background,
        metadata={
            "format": "colmap",
            "source": str(model),
            "images_dir": str(img_dir),
            "frame_names": [im.name for im in order],
            "train_ids": train_idx,
            "test_ids": test_idx,
            "downscale": downscale,
        },
    ))
