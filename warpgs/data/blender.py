"""NeRF-synthetic (Blender): ``transforms_{train,test}.json`` with ``camera_angle_x`` and OpenGL poses.

Cameras: fx = fy = 0.5 W / tan(0.5 camera_angle_x), principal point at the image centre; the OpenGL
camera-to-world (x right, y up, z back) becomes OpenCV by negating its y and z axes. Images are RGBA,
composited over white by default (``white_background=False`` composites over black); the alpha is
kept as ``Camera.mask`` (alpha > 0.5). Compositing happens at full resolution, before any
downscaling (box filter), which equals averaging premultiplied colours.

Protocol: train = frames r_26, r_86, r_2, r_55, r_75, r_93, r_16, r_73 of the train file (first
``views``), test = every 8th frame of the test file (frame number % 8 == 0) at half resolution
(``test_downscale=2``). Bounds are NeRF's near 2, far 6.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

from .plausible import check_frames
from .scene import (ImageChannels, Scene, SceneError, check_pose, downsample, intrinsics, make_camera, number,
                    opengl_to_opencv_c2w, read_image)
from .splits import blender_train_ids


def _frame_number(fp: str) -> int | None:
    m = re.search(r"(\d+)$", Path(fp).stem)
    return int(m.group(1)) if m else None


def _read(path: Path) -> dict:
    if not path.is_file():
        raise SceneError(f"{path}: file is missing (not a Blender scene)")
    try:
        meta = json.loads(path.read_text())
    except Exception as e:
        raise SceneError(f"{path}: cannot parse JSON ({e})") from e
    if not isinstance(meta, dict):
        raise SceneError(f"{path}: expected a JSON object at the top level, got {type(meta).__name__}")
    if "camera_angle_x" not in meta:
        raise SceneError(f"{path}: no 'camera_angle_x'")
    angle = number(meta["camera_angle_x"], "camera_angle_x", str(path))
    if not (math.isfinite(angle) and 0 < angle < math.pi):
        raise SceneError(f"{path}: invalid intrinsics: camera_angle_x = {angle!r} (a field of view in radians, "
                         "between 0 and pi)")
    if not isinstance(meta.get("frames"), list):
        raise SceneError(f"{path}: no 'frames' list")
    for k, fr in enumerate(meta["frames"]):
        if not isinstance(fr, dict):
            raise SceneError(f"{path}: frame {k} is {type(fr).__name__}, not an object")
        if "file_path" not in fr:
            raise SceneError(f"{path}: frame {k} has no 'file_path'")
        if not isinstance(fr["file_path"], str) or not fr["file_path"].strip():
            raise SceneError(f"{path}: frame {k}: file_path = {fr['file_path']!r} is not a file name")
        if "transform_matrix" not in fr:
            raise SceneError(f"{path}: frame {k} ({fr['file_path']}) has no pose ('transform_matrix')")
    return meta


def _image_path(root: Path, fp: str) -> Path:
    p = root / fp
    return p if p.suffix else p.with_name(p.name + ".png")


def load_blender(
    path: str | Path,
    *,
    views: int | None = 8,
    downscale: int | None = 1,
    test_downscale: int | None = 2,
    white_background: bool = True,
    name: str | None = None,
) -> Scene:
    """Loads a NeRF-synthetic scene with the 8-view protocol (train at ``downscale``, test at ``test_downscale``)."""
    root = Path(path)
    train_meta = _read(root / "transforms_train.json")
    test_meta = _read(root / "transforms_test.json")
    bg = (1.0, 1.0, 1.0) if white_background else (0.0, 0.0, 0.0)
    channels = ImageChannels()

    def load(meta: dict, fr: dict, src: Path, factor: int):
        c2w = opengl_to_opencv_c2w(check_pose(fr["transform_matrix"], f"{src} frame {fr['file_path']!r}", "transform_matrix"))
        p = _image_path(root, fr["file_path"])
        rgb, alpha = read_image(p, bg, channels)
        h, w = rgb.shape[:2]
        f = 0.5 * w / math.tan(0.5 * float(meta["camera_angle_x"]))
        rgb = downsample(rgb, factor)
        alpha = None if alpha is None else downsample(alpha, factor)
        mask = None if alpha is None else alpha > 0.5
        s = rgb.shape[1] / w
        K = intrinsics(f * s, f * s, rgb.shape[1] / 2.0, rgb.shape[0] / 2.0)
        return make_camera(Path(fr["file_path"]).stem, c2w, K, rgb, mask, image_path=p, alpha=alpha)

    by_num = {_frame_number(fr["file_path"]): fr for fr in train_meta["frames"]}
    train = []
    for i in blender_train_ids(views):
        if i not in by_num:
            raise SceneError(f"{root / 'transforms_train.json'}: the 8-view protocol needs frame r_{i}, which is not listed")
        train.append(load(train_meta, by_num[i], root / "transforms_train.json", downscale or 1))
    test_frames = []
    for k, fr in enumerate(test_meta["frames"]):
        num = _frame_number(fr["file_path"])
        if (num if num is not None else k) % 8 == 0:
            test_frames.append(fr)
    test = [load(test_meta, fr, root / "transforms_test.json", test_downscale or 1) for fr in test_frames]
    channels.warn(root)
    sizes = {(c.width, c.height) for c in train}
    if len(sizes) > 1:
        raise SceneError(f"{root}: mixed image sizes among training views {sorted(sizes)}")
    return check_frames(Scene(
        name=name or root.name,
        train=train,
        test=test,
        bounds=(2.0, 6.0),
        white_background=white_background,
        metadata={
            "format": "blender",
            "source": str(root),
            "train_ids": blender_train_ids(views),
            "test_ids": [_frame_number(fr["file_path"]) for fr in test_frames],
            "downscale": downscale,
            "test_downscale": test_downscale,
        },
    ))
