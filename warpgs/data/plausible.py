"""What no real capture has, refused at load with the frame and the field named.

- intrinsics: a focal length outside [0.05, 100] x the image's larger side (a 1 mm fisheye to a long telephoto on
  a small sensor lie well inside), a principal point more than one image size outside the image;
- lens distortion: a radial-tangential model (k1..k6, p1, p2) that scales some radius of the image by less than
  0.25x or more than 4x, folds the image over (the distorted radius must grow with the radius), or has a
  tangential coefficient beyond 0.5;
- the same frame twice: two frames whose image files resolve to one file (``images/./0001.jpg``, a symlink), or
  whose files are byte-identical copies (hashed), or, without files, whose pixels are identical.

A user who means it loads with the option ``allow_implausible_camera`` or ``allow_duplicate_frames`` (loader option
keys of ``load_scene``; ``allowing(...)`` around a loader called directly). ``make_camera`` checks every camera and
every loader passes its scene through ``check_frames``.
"""

from __future__ import annotations

import contextlib
import hashlib
from contextvars import ContextVar
from pathlib import Path

import numpy as np

from .errors import SceneError

FOCAL_RANGE = (0.05, 100.0)  # focal length in pixels / the image's larger side
PRINCIPAL_RANGE = (-1.0, 2.0)  # principal point / image size
RADIUS_SCALE = (0.25, 4.0)  # what distortion may do to a radius within the image
MAX_TANGENTIAL = 0.5

ALLOW_CAMERA = "allow_implausible_camera"
ALLOW_DUPLICATES = "allow_duplicate_frames"
OPTIONS = (ALLOW_CAMERA, ALLOW_DUPLICATES)

_allowed: ContextVar[frozenset] = ContextVar("warpgs_data_allowed", default=frozenset())


@contextlib.contextmanager
def allowing(*names: str):
    """Within the block, the checks named (``OPTIONS``) let data through."""
    unknown = set(names) - set(OPTIONS)
    if unknown:
        raise ValueError(f"unknown allowance(s) {sorted(unknown)}; known: {', '.join(OPTIONS)}")
    token = _allowed.set(_allowed.get() | frozenset(names))
    try:
        yield
    finally:
        _allowed.reset(token)


def _hint(option: str) -> str:
    return f"no real camera has this; if it is meant, load with the option {option}=True"


def check_camera(source: str, K: np.ndarray, width: int, height: int) -> None:
    """Refuses pinhole intrinsics no real camera has (module docstring)."""
    if ALLOW_CAMERA in _allowed.get():
        return
    K = np.asarray(K, np.float64)
    side = float(max(width, height))
    lo, hi = FOCAL_RANGE
    for name, f in (("fx", K[0, 0]), ("fy", K[1, 1])):
        if not (lo * side <= f <= hi * side):
            raise SceneError(f"{source}: implausible intrinsics: {name} = {f:.6g} px is {f / side:.3g} x the image's larger "
                         f"side ({side:g} px), outside [{lo:g}, {hi:g}]; {_hint(ALLOW_CAMERA)}")
    plo, phi = PRINCIPAL_RANGE
    for name, c, size in (("cx", K[0, 2], width), ("cy", K[1, 2], height)):
        if not (plo * size <= c <= phi * size):
            raise SceneError(f"{source}: implausible intrinsics: principal point {name} = {c:.6g} px lies far outside the "
                         f"{size} px image (allowed: {plo * size:g} to {phi * size:g}); {_hint(ALLOW_CAMERA)}")


def check_distortion(source: str, dist: dict[str, float], K: np.ndarray, width: int, height: int) -> None:
    """Refuses OpenCV radial-tangential coefficients no lens has (module docstring): the radius scale is measured
    from the principal point out to the image's farthest corner."""
    if ALLOW_CAMERA in _allowed.get():
        return
    g = {k: float(dist.get(k, 0.0)) for k in ("k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2")}
    for name in ("p1", "p2"):
        if abs(g[name]) > MAX_TANGENTIAL:
            raise SceneError(f"{source}: implausible lens distortion: {name} = {g[name]:.6g} (tangential, beyond "
                         f"+-{MAX_TANGENTIAL:g}); {_hint(ALLOW_CAMERA)}")
    K = np.asarray(K, np.float64)
    corners = np.array([[0.0, 0.0], [width, 0.0], [0.0, height], [width, height]])
    r_max = float(np.max(np.hypot((corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1])))
    r = np.linspace(0.0, r_max, 513)[1:]
    r2 = r * r
    with np.errstate(all="ignore"):
        num = 1 + g["k1"] * r2 + g["k2"] * r2**2 + g["k3"] * r2**3
        den = 1 + g["k4"] * r2 + g["k5"] * r2**2 + g["k6"] * r2**3
        scale = num / den
        rd = r * scale
    lo, hi = RADIUS_SCALE
    bad = ~(np.isfinite(scale) & (scale >= lo) & (scale <= hi))
    folds = not bool(np.all(np.diff(rd) > 0))
    if bad.any() or folds:
        radial = {k: v for k, v in g.items() if k[0] == "k" and v}
        worst = max(radial, key=lambda k: abs(radial[k])) if radial else "k1"
        at = float(r[np.argmax(bad)]) if bad.any() else r_max
        what = (f"scales the radius {at:.3g} (normalised; the corner is at {r_max:.3g}) by {scale[np.argmax(bad)]:.3g}x, "
                f"outside [{lo:g}, {hi:g}]") if bad.any() else "folds the image over (the distorted radius shrinks)"
        raise SceneError(f"{source}: implausible lens distortion: {worst} = {radial.get(worst, 0.0):.6g} (with "
                     f"{radial}) {what}; {_hint(ALLOW_CAMERA)}")


class _Distinct:
    """Frames seen so far, by resolved file and by content; ``add`` refuses one seen before, naming both."""

    def __init__(self, source: str | None = None):
        self.prefix = f"{source}: " if source else ""
        self.paths: dict[Path, str] = {}
        self.digests: dict[tuple[str, str], str] = {}

    def _refuse(self, label: str, first: str, what: str):
        raise SceneError(f"{self.prefix}{label} and {first}: {what}; remove one, or load with the option "
                         f"{ALLOW_DUPLICATES}=True")

    def add(self, label: str, path: Path | None = None, pixels: np.ndarray | None = None) -> None:
        h = hashlib.blake2b(digest_size=16)
        if path is not None:
            real = Path(path).resolve()
            if real in self.paths:
                self._refuse(label, self.paths[real], f"one image file listed twice (both are {real})")
            self.paths[real] = label
            if not real.is_file():  # a missing file is the loader's to report, if the frame is loaded
                return
            with open(real, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            key = ("byte-identical image files", h.hexdigest())
        else:
            a = np.ascontiguousarray(pixels)
            h.update(str((a.shape, a.dtype.str)).encode())
            h.update(a.tobytes())
            key = ("identical pixels", h.hexdigest())
        if key in self.digests:
            self._refuse(label, self.digests[key], f"the same frame twice ({key[0]})")
        self.digests[key] = label


def check_listed(source: str, files: list[tuple[str, Path]]) -> None:
    """Refuses a scene description that lists one frame twice (module docstring), before its split is chosen
    (a second entry shifts which frames train and which test): ``files`` are (the frame as listed, its file)."""
    if ALLOW_DUPLICATES in _allowed.get():
        return
    seen = _Distinct(source)
    for label, path in files:
        seen.add(repr(label), path)


def check_frames(scene):
    """Refuses a scene that holds one frame twice (module docstring), naming both; returns ``scene``."""
    if ALLOW_DUPLICATES in _allowed.get():
        return scene
    seen = _Distinct()
    for cam in scene.train + scene.test:
        if cam.image_path:
            seen.add(str(cam.image_path), Path(cam.image_path))
        else:
            seen.add(cam.name, pixels=cam.image)
    return scene


__all__ = ["ALLOW_CAMERA", "ALLOW_DUPLICATES", "OPTIONS", "allowing", "check_camera", "check_distortion", "check_frames",
           "check_listed"]
