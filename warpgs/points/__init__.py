"""Initial geometry from the sparse inputs: points found between the training views with their known
poses, and the scene's depth bounds measured on those points.

    geo = initial_geometry(scene.train, "sfm+stereo", GeometryConfig())
    geo.xyz, geo.rgb        (N, 3) float32 points and colours in [0, 1]
    geo.bounds              (near, far): per-camera depth percentiles of the points, over the training views
    geo.method              what produced the points, after any fallback ("none" when nothing did)
    geo.stats, geo.times    per method: counts, seconds

Methods (``model.init``):

- ``sfm``: SIFT features and exhaustive matching on the training views, points triangulated with the
  poses held fixed (pycolmap; ``warpgs/points/sfm.py``). Precise; wide baselines leave it a few hundred points.
- ``stereo``: Warp plane-sweep stereo between neighbouring training views, fused and cleaned with
  open3d (``warpgs/points/stereo.py``). Dense where there is texture and overlap.
- ``sfm+stereo``: both; the SfM points fix the sweep's depth range, and the two clouds are merged.

A method that finds fewer than ``min_points`` gives way to the next of its chain (sfm+stereo -> stereo,
sfm -> stereo; after stereo the caller falls back to random points in the frusta), and one line says so; so do
sfm and sfm+stereo with fewer training views than ``sfm_min_views``. Only the cameras passed in are used: callers
pass the training views, never test views.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .sfm import SfmError, SfmInputError, SfmNativeError, SfmOptions, triangulate
from .stereo import StereoInitOptions, StereoPoints, resolvable_depth_range, stereo_points

METHODS = ("sfm", "stereo", "sfm+stereo")
CHAIN = {"sfm": ["sfm", "stereo"], "stereo": ["stereo"], "sfm+stereo": ["sfm+stereo", "stereo"]}


@dataclass
class GeometryConfig:
    min_points: int = 100  # a method that finds fewer gives way to the next (module docstring)
    sfm_min_views: int = 0  # with fewer training views, sfm and sfm+stereo give way to stereo whatever they find
    #   (SfM still runs: its points bound the sweep's depth range). Its few hundred points need growth, and growth
    #   fits so few inputs (captures' config: 4)
    extend_far: bool = False  # when SfM finds fewer than min_points, the sweep's far end is the farther of their far
    #   bound and a first pass's over the resolvable range: distant points fail SfM's triangulation angle first
    #   (castle_p30 at 3 views: 16 points, none beyond 37 m; its back facade at 42-50 m). Captures' config: on; off elsewhere
    #   (DTU scan65, an object on a table, 57 points: its baseline fell from 23.16 to 22.31 with it)
    max_points: int = 150_000  # larger clouds are subsampled to this many (seeded)
    near_percentile: float = 1.0  # per-camera depth percentiles of the points that bound the scene ...
    far_percentile: float = 99.0
    bounds_margin: float = 0.2  # ... widened by this fraction: near x (1 - m), far x (1 + m)
    seed: int = 0
    sfm: SfmOptions = field(default_factory=SfmOptions)
    stereo: StereoInitOptions = field(default_factory=StereoInitOptions)

    LIMITS = {"min_points": ">= 0", "sfm_min_views": ">= 0", "max_points": ">= 1", "near_percentile": "[0, 100]", "far_percentile": "[0, 100]",
              "bounds_margin": "[0, 1)", "seed": ">= 0"}


@dataclass
class Geometry:
    xyz: np.ndarray
    rgb: np.ndarray
    bounds: tuple[float, float] | None  # None when no points were found
    method: str  # what produced the points ("none": nothing did)
    asked: str  # the method asked for
    stats: dict = field(default_factory=dict)
    times: dict = field(default_factory=dict)  # seconds per stage: sfm_s, stereo_s
    notes: list = field(default_factory=list)  # the one-line fallback messages
    # one line per native step (pycolmap, open3d) whose child process died, hung or left no result: the run went on
    # with that step's fallback (``warpgs.densify.native``); ``summary()`` puts them in metrics.json's init
    native_failures: list = field(default_factory=list)
    key: tuple | None = None  # the settings it was found with (warpgs.train.prepare_geometry's cache key)

    def summary(self) -> dict:
        return {"asked": self.asked, "method": self.method, "points": int(len(self.xyz)),
                "bounds": None if self.bounds is None else [round(b, 6) for b in self.bounds],
                "times": {k: round(v, 2) for k, v in self.times.items()}, "stats": self.stats, "notes": self.notes,
                "native_failures": self.native_failures}


def depth_bounds(cameras, xyz: np.ndarray, near_percentile: float = 1.0, far_percentile: float = 99.0,
                 margin: float = 0.2) -> tuple[float, float] | None:
    """(near, far) over the cameras: for each, the percentiles of the z-depths of the points in front of
    it that project into its image, widened by ``margin``; the smallest near and largest far. None
    when no camera sees 10 points."""
    nears, fars = [], []
    for c in cameras:
        uv, z = c.project(xyz)
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < c.width) & (uv[:, 1] < c.height)
        if int(inside.sum()) < 10:
            continue
        lo, hi = np.percentile(z[inside], [near_percentile, far_percentile])
        nears.append(lo * (1 - margin))
        fars.append(hi * (1 + margin))
    if not nears:
        return None
    near, far = max(float(min(nears)), 1e-6), float(max(fars))
    return (near, far) if far > near else None


def _subsample(xyz, rgb, n: int, seed: int):
    if len(xyz) <= n:
        return xyz, rgb
    idx = np.sort(np.random.default_rng(seed).choice(len(xyz), n, replace=False))
    return xyz[idx], rgb[idx]


def initial_geometry(cameras, method: str, config: GeometryConfig | None = None, *, device=None,
                     log=print) -> Geometry:
    """Points for ``method`` (``sfm``, ``stereo``, ``sfm+stereo``) from ``cameras`` with fallbacks
    (module docstring). Bad input that no fallback can help (one view, pycolmap missing) raises."""
    cfg = config or GeometryConfig()
    if method not in METHODS:
        raise ValueError(f"model.init={method!r}: the geometry methods are {', '.join(METHODS)}")
    geo = Geometry(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), None, "none", method)
    sfm_result: list = []  # [SfmPoints or None, why it is not enough or None], filled once

    def note(text: str) -> None:
        geo.notes.append(text)
        log(f"warpgs: {text}")

    def sfm():
        if not sfm_result:
            t0 = time.perf_counter()
            try:
                pts = triangulate(cameras, cfg.sfm, log=lambda *_: None)
                geo.stats["sfm"] = pts.stats
                why = None
                if len(pts.xyz) < cfg.min_points:
                    why = f"triangulation found too few points ({len(pts.xyz)} points)"
                elif len(cameras) < cfg.sfm_min_views:
                    why = f"{len(cameras)} training views, fewer than geometry.sfm_min_views {cfg.sfm_min_views}"
            except SfmInputError:
                raise
            except SfmNativeError as e:  # pycolmap's child died or hung: the next method of the chain
                pts, why = None, f"triangulation failed ({e})"
                geo.native_failures.append(str(e))
            except SfmError as e:  # too few matches or points: the next method may do better
                pts, why = None, f"triangulation found too few points ({e})"
            geo.times["sfm_s"] = time.perf_counter() - t0
            sfm_result.extend([pts, why])
        return sfm_result

    def stereo():
        pts = sfm_result[0] if sfm_result else None
        rng = None  # the SfM points, even too few to start from, bound the sweep ...
        if pts is not None and len(pts.xyz) >= 10:
            rng = depth_bounds(cameras, pts.xyz, cfg.near_percentile, cfg.far_percentile, cfg.bounds_margin)
        # ... and with extend_far, fewer than min_points do not bound its far end (GeometryConfig.extend_far)
        extend_far = cfg.extend_far and (pts is None or len(pts.xyz) < cfg.min_points)
        t0 = time.perf_counter()
        st = stereo_points(cameras, cfg.stereo, rng, extend_far=extend_far, device=device)
        geo.times["stereo_s"] = time.perf_counter() - t0
        geo.stats["stereo"] = st.stats
        if st.stats.get("filter_failure"):
            geo.native_failures.append(st.stats["filter_failure"])
        return st

    for m in CHAIN[method]:
        if m in ("sfm", "sfm+stereo"):
            pts, why = sfm()
            if why is not None:
                note(f"init {m}: {why}; using stereo")
                continue
            xyz, rgb = pts.xyz, pts.rgb
            if m == "sfm+stereo":
                st = stereo()
                xyz, rgb = np.concatenate([xyz, st.xyz]), np.concatenate([rgb, st.rgb])
        else:
            st = stereo()
            xyz, rgb = st.xyz, st.rgb
            if len(xyz) < cfg.min_points:
                note(f"init {m}: stereo found too few points ({len(xyz)}); using random points in the training frusta")
                continue
        geo.xyz, geo.rgb, geo.method = xyz.astype(np.float32), rgb.astype(np.float32), m
        break
    if len(geo.xyz):
        geo.xyz, geo.rgb = _subsample(geo.xyz, geo.rgb, cfg.max_points, cfg.seed)
        geo.bounds = depth_bounds(cameras, geo.xyz, cfg.near_percentile, cfg.far_percentile, cfg.bounds_margin)
    return geo


__all__ = ["CHAIN", "METHODS", "Geometry", "GeometryConfig", "SfmError", "SfmInputError", "SfmNativeError", "SfmOptions", "StereoInitOptions",
           "StereoPoints", "depth_bounds", "initial_geometry", "resolvable_depth_range", "stereo_points", "triangulate"]
