"""DTU in the IDR/NeuS layout: ``cameras.npz`` (``world_mat_i``, ``scale_mat_i``), ``image/``, ``mask/``.

``world_mat_i`` is a 4x4 whose top 3x4 is the projection K [R | t] of the original 1600x1200 images.
As NeuS does, the projection used is ``P = world_mat @ scale_mat``, so the loaded world is the
normalised one in which the object fits the unit sphere; ``Scene.world_transform = inv(scale_mat)``
maps DTU's original world into it. P is split into K, R, t by an RQ decomposition (numpy only),
K's first two rows are scaled by image width / 1600 (0.25 for the common 400x300 copies) and taken
as given otherwise, as the sparse-view literature does.

Split: train ids 25, 22, 28 (then 40, 44, 48, 0, 8, 13), test = the remaining ids minus 3-7, 16-21,
36-39. Masks are loaded for every view, and ``Scene.eval_masked`` says evaluation uses them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plausible import check_frames
from .scene import ImageChannels, Scene, SceneError, downsample, list_images, make_camera, read_image, read_mask
from .splits import dtu_split


def rq3(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RQ decomposition of a 3x3: M = U @ Q with U upper triangular (positive diagonal), Q orthogonal."""
    P = np.eye(3)[::-1]
    Q0, R0 = np.linalg.qr((P @ M).T)
    U = P @ R0.T @ P
    Q = P @ Q0.T
    D = np.diag(np.sign(np.diag(U)))
    return U @ D, D @ Q


def decompose_projection(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """3x4 projection (up to scale) -> K (K[2, 2] = 1), R (a rotation), t with P ~ K [R | t].

    The overall sign is chosen so that R is a proper rotation, which also puts points with positive
    projective depth in front of the camera.
    """
    P = np.asarray(P, np.float64)[:3, :4]
    K, R = rq3(P[:, :3])
    s = 1.0
    if np.linalg.det(R) < 0:
        R, s = -R, -1.0
    t = np.linalg.solve(K, s * P[:, 3])  # s P = K [R | t]; normalising K changes only the scale
    return K / K[2, 2], R, t


def load_dtu(
    path: str | Path,
    *,
    views: int | None = 3,
    downscale: int | None = None,
    full_width: int = 1600,
    name: str | None = None,
) -> Scene:
    """Loads a DTU scan (IDR/NeuS layout); ``downscale`` d box-filters the images found by d."""
    root = Path(path)
    npz = root / "cameras.npz"
    if not npz.is_file():
        raise SceneError(f"{npz}: file is missing (not a DTU scene in the IDR/NeuS layout)")
    img_dir = root / "image"
    if not img_dir.is_dir():
        raise SceneError(f"{img_dir}: image folder is missing")
    files = list_images(img_dir)
    try:
        cams = dict(np.load(npz))
    except Exception as e:
        raise SceneError(f"{npz}: cannot read ({e})") from e
    n = len(files)
    for i in range(n):
        if f"world_mat_{i}" not in cams:
            raise SceneError(f"{npz}: no world_mat_{i} for image {files[i].name} (frames without poses)")
    extra_poses = [k for k in cams if k.startswith("world_mat_") and not k.startswith("world_mat_inv") and int(k.split("_")[-1]) >= n]
    if extra_poses:
        raise SceneError(f"{npz}: {len(extra_poses)} poses have no image in {img_dir} (has {n} images)")
    scale_mat = cams.get("scale_mat_0", np.eye(4)).astype(np.float64)
    for i in range(n):
        sm = cams.get(f"scale_mat_{i}", scale_mat)
        if not np.allclose(sm, scale_mat, rtol=1e-6, atol=1e-6):
            raise SceneError(f"{npz}: scale_mat_{i} differs from scale_mat_0; one normalisation per scene is expected")
    if not np.all(np.isfinite(scale_mat)) or abs(np.linalg.det(scale_mat[:3, :3])) < 1e-12:
        raise SceneError(f"{npz}: scale_mat_0 is not an invertible finite matrix")

    train_ids, test_ids = dtu_split(n, views)
    mask_dir = root / "mask"
    d = downscale or 1
    channels = ImageChannels()

    def load(i: int):
        wm = cams[f"world_mat_{i}"].astype(np.float64)
        src = f"{npz} world_mat_{i}"
        if not np.all(np.isfinite(wm)):
            raise SceneError(f"{src}: contains non-finite values")
        K, R, t = decompose_projection(wm @ scale_mat)
        if abs(np.linalg.det(K)) < 1e-9:
            raise SceneError(f"{src}: degenerate projection matrix")
        rgb, _ = read_image(files[i], channels=channels)
        h_img, w_img = rgb.shape[:2]
        s = w_img / full_width
        if abs(h_img - round(full_width * 0.75 * s)) > 1:
            raise SceneError(f"{files[i]}: image is {w_img}x{h_img}, expected a 4:3 copy of the {full_width}-wide original")
        mask = None
        if mask_dir.is_dir():
            mp = mask_dir / f"{i:03d}.png"
            if not mp.is_file():
                raise SceneError(f"{mp}: mask file is missing")
            mask = read_mask(mp)
            if mask.shape != rgb.shape[:2]:
                raise SceneError(f"{mp}: mask is {mask.shape[1]}x{mask.shape[0]} but {files[i].name} is {w_img}x{h_img}")
        if d > 1:
            rgb = downsample(rgb, d)
            mask = None if mask is None else downsample(mask, d)
            s = s * rgb.shape[1] / w_img
        Ks = K.copy()
        Ks[:2] *= s
        c2w = np.eye(4)
        c2w[:3, :3] = R.T
        c2w[:3, 3] = -R.T @ t
        return make_camera(f"{i:03d}", c2w, Ks, rgb, mask, image_path=files[i])

    train = [load(i) for i in train_ids]
    test = [load(i) for i in test_ids]
    channels.warn(img_dir)
    sizes = {(c.width, c.height) for c in train + test}
    if len(sizes) > 1:
        raise SceneError(f"{img_dir}: mixed image sizes {sorted(sizes)}")
    # the object lies inside the unit sphere of the normalised world
    dist = np.array([np.linalg.norm(c.center) for c in train + test])
    bounds = (float(max(dist.min() - 1.0, 0.05)), float(dist.max() + 1.0))
    return check_frames(Scene(
        name=name or root.name,
        train=train,
        test=test,
        bounds=bounds,
        world_transform=np.linalg.inv(scale_mat),
        eval_masked=True,
        metadata={
            "format": "dtu",
            "source": str(npz),
            "train_ids": train_ids,
            "test_ids": test_ids,
            "frame_names": [f.name for f in files],
            "scale_mat": scale_mat,
        },
    ))
