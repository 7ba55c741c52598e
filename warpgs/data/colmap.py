"""COLMAP sparse models: readers (and writers) for cameras, images and points3D, binary and text.

Written from COLMAP's documented format (https://colmap.github.io/format.html):

- ``cameras.bin``: uint64 count; per camera int32 id, int32 model id, uint64 width, uint64 height,
  float64 params[model's count]. ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS...``.
- ``images.bin``: uint64 count; per image int32 id, float64 qw qx qy qz, float64 tx ty tz, int32
  camera id, NUL-terminated name, uint64 n2d, n2d x (float64 x, float64 y, int64 point3D id).
  ``images.txt``: two lines per image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` then
  ``X Y POINT3D_ID ...``.
- ``points3D.bin``: uint64 count; per point uint64 id, float64 xyz, uint8 rgb, float64 error,
  uint64 track length, length x (int32 image id, int32 point2D index). ``points3D.txt``:
  ``POINT3D_ID X Y Z R G B ERROR TRACK...``.

An image's (q, t) is the world-to-camera transform in OpenCV axes (x right, y down, z forward), the
library's own convention, and COLMAP's pixel (0, 0) corner convention matches the library's too.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpgs.geometry import quat_to_rotmat as qvec_to_rotmat  # COLMAP's names for the shared helpers
from warpgs.geometry import rotmat_to_quat as rotmat_to_qvec  # noqa: F401

from .scene import SceneError

# model id -> (name, number of params)
CAMERA_MODELS = {
    0: ("SIMPLE_PINHOLE", 3),
    1: ("PINHOLE", 4),
    2: ("SIMPLE_RADIAL", 4),
    3: ("RADIAL", 5),
    4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8),
    6: ("FULL_OPENCV", 12),
    7: ("FOV", 5),
    8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5),
    10: ("THIN_PRISM_FISHEYE", 12),
    11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
}
MODEL_IDS = {name: (mid, n) for mid, (name, n) in CAMERA_MODELS.items()}
# models with one focal length f (params f, cx, cy, ...); the others have fx, fy, cx, cy, ...
SINGLE_FOCAL_MODELS = ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE")


@dataclass
class ColmapCamera:
    id: int
    model: str
    width: int
    height: int
    params: np.ndarray  # float64

    def pinhole(self) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) of the model."""
        p = self.params
        if self.model in SINGLE_FOCAL_MODELS:
            return float(p[0]), float(p[0]), float(p[1]), float(p[2])
        return float(p[0]), float(p[1]), float(p[2]), float(p[3])

    def distortion(self) -> dict[str, float]:
        """Distortion coefficients by name, in OpenCV's naming (k1, k2, p1, p2, ...)."""
        p = self.params
        names = {
            "SIMPLE_PINHOLE": [],
            "PINHOLE": [],
            "SIMPLE_RADIAL": ["k1"],
            "RADIAL": ["k1", "k2"],
            "OPENCV": ["k1", "k2", "p1", "p2"],
            "FULL_OPENCV": ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
            "OPENCV_FISHEYE": ["k1", "k2", "k3", "k4"],
            "SIMPLE_RADIAL_FISHEYE": ["k1"],
            "RADIAL_FISHEYE": ["k1", "k2"],
            "FOV": ["omega"],
            "THIN_PRISM_FISHEYE": ["k1", "k2", "p1", "p2", "k3", "k4", "sx1", "sy1"],
            "RAD_TAN_THIN_PRISM_FISHEYE": ["k0", "k1", "k2", "k3", "k4", "k5", "p0", "p1", "s0", "s1", "s2", "s3"],
        }[self.model]
        first = 3 if self.model in SINGLE_FOCAL_MODELS else 4
        return {n: float(v) for n, v in zip(names, p[first:])}


@dataclass
class ColmapImage:
    id: int
    qvec: np.ndarray  # (w, x, y, z), world -> camera rotation
    tvec: np.ndarray  # world -> camera translation
    camera_id: int
    name: str
    xys: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    point3d_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def viewmat(self) -> np.ndarray:
        """4x4 world-to-camera (OpenCV axes), float64."""
        m = np.eye(4)
        m[:3, :3] = qvec_to_rotmat(self.qvec)
        m[:3, 3] = self.tvec
        return m


@dataclass
class ColmapPoints:
    ids: np.ndarray  # (N,) int64
    xyz: np.ndarray  # (N, 3) float64
    rgb: np.ndarray  # (N, 3) uint8
    error: np.ndarray  # (N,) float64
    track_lengths: np.ndarray  # (N,) int64


# ----------------------------------------------------------------------------------------------
# binary


class _Reader:
    def __init__(self, path: Path):
        self.path = path
        self.buf = path.read_bytes()
        self.pos = 0

    def read(self, fmt: str):
        size = struct.calcsize(fmt)
        if self.pos + size > len(self.buf):
            raise SceneError(f"{self.path}: file ends early (truncated or not a COLMAP binary file)")
        out = struct.unpack_from(fmt, self.buf, self.pos)
        self.pos += size
        return out

    def read_array(self, dtype, count: int) -> np.ndarray:
        dt = np.dtype(dtype)
        size = dt.itemsize * count
        if self.pos + size > len(self.buf):
            raise SceneError(f"{self.path}: file ends early (truncated or not a COLMAP binary file)")
        a = np.frombuffer(self.buf, dt, count, self.pos)
        self.pos += size
        return a

    def read_cstring(self) -> str:
        end = self.buf.find(b"\x00", self.pos)
        if end < 0:
            raise SceneError(f"{self.path}: file ends early inside an image name (truncated)")
        try:
            s = self.buf[self.pos : end].decode("utf-8")
        except UnicodeDecodeError:
            raise SceneError(f"{self.path}: an image name at byte {self.pos} is not UTF-8 text (corrupt file)") from None
        self.pos = end + 1
        return s

    def count(self, record_size: int) -> int:
        """A uint64 count of records of at least ``record_size`` bytes each, checked against the bytes left
        (a corrupt count would otherwise ask for petabytes)."""
        (n,) = self.read("<Q")
        if n * record_size > len(self.buf) - self.pos:
            raise SceneError(f"{self.path}: says it holds {n} records, more than its {len(self.buf)} bytes can "
                             "(truncated or corrupt)")
        return n


def read_cameras_binary(path: str | Path) -> dict[int, ColmapCamera]:
    r = _Reader(Path(path))
    n = r.count(24)
    cams = {}
    for _ in range(n):
        cid, mid, w, h = r.read("<iiQQ")
        if mid not in CAMERA_MODELS:
            raise SceneError(f"{path}: camera {cid} has unknown model id {mid}")
        name, npar = CAMERA_MODELS[mid]
        cams[cid] = ColmapCamera(cid, name, int(w), int(h), r.read_array("<f8", npar).astype(np.float64))
    return cams


def read_images_binary(path: str | Path, with_points2d: bool = False) -> dict[int, ColmapImage]:
    r = _Reader(Path(path))
    n = r.count(73)
    images = {}
    for _ in range(n):
        vals = r.read("<i7di")
        iid, q, t, cid = vals[0], np.array(vals[1:5]), np.array(vals[5:8]), vals[8]
        name = r.read_cstring()
        (n2d,) = r.read("<Q")
        rec = r.read_array(np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")]), n2d)
        img = ColmapImage(iid, q, t, cid, name)
        if with_points2d:
            img.xys = np.stack([rec["x"], rec["y"]], axis=1)
            img.point3d_ids = rec["id"].astype(np.int64)
        images[iid] = img
    return images


def read_points3d_binary(path: str | Path) -> ColmapPoints:
    r = _Reader(Path(path))
    n = r.count(43)
    ids = np.empty(n, np.int64)
    xyz = np.empty((n, 3), np.float64)
    rgb = np.empty((n, 3), np.uint8)
    err = np.empty(n, np.float64)
    tl = np.empty(n, np.int64)
    rec = struct.Struct("<Q3d3BdQ")
    buf, pos = r.buf, r.pos
    for k in range(n):
        if pos + rec.size > len(buf):
            raise SceneError(f"{path}: file ends early (truncated or not a COLMAP binary file)")
        v = rec.unpack_from(buf, pos)
        pos += rec.size
        if v[0] > np.iinfo(np.int64).max or 8 * v[8] > len(buf) - pos:
            raise SceneError(f"{path}: point {k} has id {v[0]} and a track of {v[8]} elements, which the file "
                             "cannot hold (truncated or corrupt)")
        ids[k], xyz[k], rgb[k], err[k], tl[k] = v[0], v[1:4], v[4:7], v[7], v[8]
        pos += 8 * v[8]  # track: (int32 image id, int32 point2D index) per element
    if pos > len(buf):
        raise SceneError(f"{path}: file ends early (truncated or not a COLMAP binary file)")
    return ColmapPoints(ids, xyz, rgb, err, tl)


# ----------------------------------------------------------------------------------------------
# text


def _read_text(path: Path) -> str:
    if not path.is_file():
        raise SceneError(f"{path}: file is missing")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(f"{path}: not UTF-8 text at byte {e.start} (corrupt, or a binary file named .txt)") from None


def _data_lines(path: Path):
    for line in _read_text(path).splitlines():
        s = line.strip()
        if s and not s.startswith("#"):
            yield s


def read_cameras_text(path: str | Path) -> dict[int, ColmapCamera]:
    path = Path(path)
    cams = {}
    for line in _data_lines(path):
        el = line.split()
        try:
            cid, model, w, h = int(el[0]), el[1], int(el[2]), int(el[3])
            params = np.array([float(x) for x in el[4:]])
        except (ValueError, IndexError) as e:
            raise SceneError(f"{path}: cannot parse camera line {line!r}") from e
        if model not in MODEL_IDS:
            raise SceneError(f"{path}: camera {cid} has unknown model {model!r}")
        if len(params) != MODEL_IDS[model][1]:
            raise SceneError(f"{path}: camera {cid} ({model}) has {len(params)} params, expected {MODEL_IDS[model][1]}")
        cams[cid] = ColmapCamera(cid, model, w, h, params)
    return cams


def read_images_text(path: str | Path, with_points2d: bool = False) -> dict[int, ColmapImage]:
    path = Path(path)
    lines = [s for s in _read_text(path).splitlines() if not s.lstrip().startswith("#")]
    # drop leading blank lines only; a blank line after an image line is its (empty) 2D point list
    images = {}
    i = 0
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        el = lines[i].split()
        try:
            iid = int(el[0])
            q = np.array([float(x) for x in el[1:5]])
            t = np.array([float(x) for x in el[5:8]])
            cid = int(el[8])
            name = " ".join(el[9:])
        except (ValueError, IndexError) as e:
            raise SceneError(f"{path}: cannot parse image line {lines[i]!r}") from e
        if not name:
            raise SceneError(f"{path}: image {iid} has no file name")
        img = ColmapImage(iid, q, t, cid, name)
        pts = lines[i + 1].split() if i + 1 < len(lines) else []
        if with_points2d and pts:
            a = np.array([float(x) for x in pts]).reshape(-1, 3)
            img.xys, img.point3d_ids = a[:, :2], a[:, 2].astype(np.int64)
        images[iid] = img
        i += 2
    return images


def read_points3d_text(path: str | Path) -> ColmapPoints:
    path = Path(path)
    ids, xyz, rgb, err, tl = [], [], [], [], []
    for line in _data_lines(path):
        el = line.split()
        try:
            ids.append(int(el[0]))
            xyz.append([float(x) for x in el[1:4]])
            rgb.append([int(x) for x in el[4:7]])
            err.append(float(el[7]))
            tl.append((len(el) - 8) // 2)
        except (ValueError, IndexError) as e:
            raise SceneError(f"{path}: cannot parse point line {line[:80]!r}") from e
    if any(not 0 <= c <= 255 for c in (v for row in rgb for v in row)) or any(abs(i) >= 2**63 for i in ids):
        raise SceneError(f"{path}: a point has a colour outside 0..255 or an id outside 64 bits")
    return ColmapPoints(
        np.array(ids, np.int64),
        np.array(xyz, np.float64).reshape(-1, 3),
        np.array(rgb, np.uint8).reshape(-1, 3),
        np.array(err, np.float64),
        np.array(tl, np.int64),
    )


# ----------------------------------------------------------------------------------------------
# model folder


def find_model_files(folder: str | Path) -> tuple[str, Path]:
    """('bin' | 'txt', folder) for a folder holding cameras.* and images.*; SceneError otherwise."""
    folder = Path(folder)
    for ext in ("bin", "txt"):
        if (folder / f"cameras.{ext}").is_file() and (folder / f"images.{ext}").is_file():
            return ext, folder
    raise SceneError(f"{folder}: no COLMAP model here (expected cameras.bin + images.bin or cameras.txt + images.txt)")


def read_model(
    folder: str | Path, with_points: bool = True, with_points2d: bool = False
) -> tuple[dict[int, ColmapCamera], dict[int, ColmapImage], ColmapPoints | None]:
    """Reads a sparse model folder (binary preferred over text)."""
    ext, folder = find_model_files(folder)
    if ext == "bin":
        cams = read_cameras_binary(folder / "cameras.bin")
        imgs = read_images_binary(folder / "images.bin", with_points2d)
    else:
        cams = read_cameras_text(folder / "cameras.txt")
        imgs = read_images_text(folder / "images.txt", with_points2d)
    pts = None
    if with_points:
        if (folder / f"points3D.{ext}").is_file():
            pts = read_points3d_binary(folder / "points3D.bin") if ext == "bin" else read_points3d_text(folder / "points3D.txt")
    return cams, imgs, pts


def read_points3d(folder_or_file: str | Path) -> ColmapPoints:
    p = Path(folder_or_file)
    if p.is_dir():
        p = p / "points3D.bin" if (p / "points3D.bin").is_file() else p / "points3D.txt"
    if not p.is_file():
        raise SceneError(f"{p}: file is missing")
    return read_points3d_binary(p) if p.suffix == ".bin" else read_points3d_text(p)


# ----------------------------------------------------------------------------------------------
# writers (warpgs writes only into folders it creates: the synthetic scene, test fixtures)


def write_model(
    folder: str | Path,
    cameras: dict[int, ColmapCamera],
    images: dict[int, ColmapImage],
    points: ColmapPoints | None = None,
    binary: bool = True,
) -> None:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if points is None:
        points = ColmapPoints(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0), np.zeros(0, np.int64))
    if binary:
        with open(folder / "cameras.bin", "wb") as f:
            f.write(struct.pack("<Q", len(cameras)))
            for c in cameras.values():
                f.write(struct.pack("<iiQQ", c.id, MODEL_IDS[c.model][0], c.width, c.height))
                f.write(np.asarray(c.params, "<f8").tobytes())
        with open(folder / "images.bin", "wb") as f:
            f.write(struct.pack("<Q", len(images)))
            for im in images.values():
                f.write(struct.pack("<i7di", im.id, *im.qvec, *im.tvec, im.camera_id))
                f.write(im.name.encode("utf-8") + b"\x00")
                f.write(struct.pack("<Q", len(im.xys)))
                for (x, y), pid in zip(im.xys, im.point3d_ids):
                    f.write(struct.pack("<ddq", x, y, pid))
        with open(folder / "points3D.bin", "wb") as f:
            f.write(struct.pack("<Q", len(points.ids)))
            for k in range(len(points.ids)):
                f.write(struct.pack("<Q3d3BdQ", int(points.ids[k]), *points.xyz[k], *[int(c) for c in points.rgb[k]], float(points.error[k]), 0))
    else:
        with open(folder / "cameras.txt", "w") as f:
            f.write("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n")
            for c in cameras.values():
                f.write(f"{c.id} {c.model} {c.width} {c.height} " + " ".join(repr(float(p)) for p in c.params) + "\n")
        with open(folder / "images.txt", "w") as f:
            f.write("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n# POINTS2D[] as (X, Y, POINT3D_ID)\n")
            for im in images.values():
                f.write(f"{im.id} " + " ".join(repr(float(v)) for v in (*im.qvec, *im.tvec)) + f" {im.camera_id} {im.name}\n")
                f.write(" ".join(f"{x!r} {y!r} {int(p)}" for (x, y), p in zip(im.xys.tolist(), im.point3d_ids)) + "\n")
        with open(folder / "points3D.txt", "w") as f:
            f.write("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n")
            for k in range(len(points.ids)):
                x, y, z = (float(c) for c in points.xyz[k])
                r, g, b = (int(c) for c in points.rgb[k])
                f.write(f"{int(points.ids[k])} {x!r} {y!r} {z!r} {r} {g} {b} {float(points.error[k])!r}\n")
