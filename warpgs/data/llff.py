"""LLFF: ``poses_bounds.npy`` + ``images_N``.

Each row of ``poses_bounds.npy`` is a 3x5 matrix [R | t | (H, W, f)] flattened row-major, then
(near, far). R's columns are the camera's [down, right, back] axes in the world, t its centre, and
H, W, f the full-resolution image size and focal length; the principal point is the image centre.
Rows follow the images sorted by name.

Conversion: camera axes [down, right, back] -> OpenCV [right, down, forward] = [c1, c0, -c2].
Normalisation, as NeRF's ``load_llff_data`` (``bd_factor=0.75``, ``recenter=True``): the world is
scaled by ``s = 1 / (0.75 * min near)`` (so the nearest bound becomes 1 / 0.75 = 1.33) and then
expressed in the frame of the average camera (centre = mean centre, z = mean back axis, y = mean up
axis, OpenGL-style as NeRF builds it). Bounds are scaled by ``s`` (a rigid recentring leaves z-depths
alone). ``Scene.world_transform`` is that similarity, mapping the poses' world (also the frame of the
scene's ``sparse/0`` COLMAP points) to the loaded one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import colmap as colmap_io
from .plausible import check_frames
from .scene import (
    ImageChannels,
    Scene,
    SceneError,
    check_intrinsics,
    check_pose,
    downsample,
    image_size,
    intrinsics,
    list_images,
    make_camera,
    read_image,
    similarity_apply_c2w,
    transform_points,
)
from .splits import every_nth_split


def _normalize(v):
    return v / np.linalg.norm(v)


def llff_world_transform(c2w_cv: np.ndarray, near_min: float, bd_factor: float | None, recenter: bool) -> np.ndarray:
    """The similarity NeRF's LLFF loader applies: scale by 1/(bd_factor * near_min), then recentre."""
    sc = 1.0 if bd_factor is None else 1.0 / (near_min * bd_factor)
    S = np.diag([sc, sc, sc, 1.0])
    if not recenter:
        return S
    centres = c2w_cv[:, :3, 3] * sc
    back = -c2w_cv[:, :3, 2].sum(0)  # OpenGL z = -OpenCV z
    up = -c2w_cv[:, :3, 1].sum(0)  # OpenGL y = -OpenCV y
    z = _normalize(back)
    x = _normalize(np.cross(up, z))
    y = _normalize(np.cross(z, x))
    avg = np.eye(4)
    avg[:3, :3] = np.stack([x, y, z], axis=1)
    avg[:3, 3] = centres.mean(0)
    return np.linalg.inv(avg) @ S


def load_llff(
    path: str | Path,
    *,
    views: int | None = 3,
    downscale: int | None = 8,
    test_every: int = 8,
    bd_factor: float | None = 0.75,
    recenter: bool = True,
    load_points: bool = False,
    name: str | None = None,
) -> Scene:
    """Loads an LLFF scene; ``downscale`` d reads ``images_d`` (or downsamples ``images`` in memory)."""
    root = Path(path)
    pb = root / "poses_bounds.npy"
    if not pb.is_file():
        raise SceneError(f"{pb}: file is missing (not an LLFF scene)")
    try:
        arr = np.load(pb)
    except Exception as e:
        raise SceneError(f"{pb}: cannot read ({e})") from e
    if arr.ndim != 2 or arr.shape[1] != 17:
        raise SceneError(f"{pb}: array has shape {arr.shape}, expected (N, 17)")
    if arr.dtype.kind not in "fiu":
        raise SceneError(f"{pb}: array holds {arr.dtype} values, expected real numbers")
    if not np.all(np.isfinite(arr)):
        bad = sorted(set(np.nonzero(~np.isfinite(arr))[0].tolist()))
        raise SceneError(f"{pb}: rows {bad} contain non-finite values")
    poses = arr[:, :15].reshape(-1, 3, 5)
    bds = arr[:, 15:17].astype(np.float64)
    if np.any(bds <= 0) or np.any(bds[:, 1] <= bds[:, 0]):
        raise SceneError(f"{pb}: near/far bounds must satisfy 0 < near < far")

    d = downscale or 1
    folder, extra = root / ("images" if d == 1 else f"images_{d}"), 1
    if not folder.is_dir():
        if (root / "images").is_dir():
            folder, extra = root / "images", d
        else:
            raise SceneError(f"{root}: no image folder {folder.name} (nor images to downscale)")
    files = list_images(folder)
    if len(files) != len(poses):
        raise SceneError(
            f"{pb}: {len(poses)} poses but {folder} holds {len(files)} images; "
            + ("some images have no pose" if len(files) > len(poses) else "some poses have no image")
        )

    c2w_cv = np.zeros((len(poses), 4, 4))
    for k, p in enumerate(poses):
        m = check_pose(p[:, :4], f"{pb} row {k} ({files[k].name})")
        R = m[:3, :3]
        c2w_cv[k] = np.eye(4)
        c2w_cv[k, :3, :3] = np.stack([R[:, 1], R[:, 0], -R[:, 2]], axis=1)
        c2w_cv[k, :3, 3] = m[:3, 3]
    W = llff_world_transform(c2w_cv, float(bds.min()), bd_factor, recenter)
    scale = float(np.cbrt(np.linalg.det(W[:3, :3])))

    train_idx, test_idx = every_nth_split(len(files), views, test_every, source=str(pb))

    channels = ImageChannels()

    def load(k: int):
        H, Wd, f = poses[k, :, 4]
        check_intrinsics(f"{pb} row {k} ({files[k].name})", {"H": H, "W": Wd, "f": f})
        w_img, h_img = image_size(files[k])
        w_img, h_img = w_img // extra, h_img // extra
        sx, sy = w_img / Wd, h_img / H
        if abs(sx - sy) * max(Wd, H) > 1.5:
            raise SceneError(f"{files[k]}: image is {w_img}x{h_img}, not a scaled copy of the {Wd:g}x{H:g} in {pb.name}")
        K = intrinsics(f * sx, f * sy, w_img / 2.0, h_img / 2.0)
        rgb, _ = read_image(files[k], channels=channels)
        rgb = downsample(rgb, extra)
        return make_camera(files[k].stem, similarity_apply_c2w(W, c2w_cv[k]), K, rgb, image_path=files[k])

    train = [load(k) for k in train_idx]
    test = [load(k) for k in test_idx]
    channels.warn(folder)
    sizes = {(c.width, c.height) for c in train + test}
    if len(sizes) > 1:
        raise SceneError(f"{folder}: mixed image sizes {sorted(sizes)}")

    points = rgbs = None
    if load_points:
        sp = root / "sparse" / "0"
        pts = colmap_io.read_points3d(sp)
        points = transform_points(W, pts.xyz).astype(np.float32)
        rgbs = (pts.rgb / 255.0).astype(np.float32)
    nb = bds * scale
    return check_frames(Scene(
        name=name or root.name,
        train=train,
        test=test,
        bounds=(float(nb[:, 0].min()), float(nb[:, 1].max())),
        world_transform=W,
        points3d=points,
        points_rgb=rgbs,
        metadata={
            "format": "llff",
            "source": str(pb),
            "frame_names": [f.name for f in files],
            "train_ids": train_idx,
            "test_ids": test_idx,
            "view_bounds": {files[k].stem: tuple(map(float, nb[k])) for k in range(len(files))},
            "downscale": d,
        },
    ))
