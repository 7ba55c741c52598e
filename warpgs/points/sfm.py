"""A sparse point cloud triangulated from the training views with their known poses (pycolmap).

    pts = triangulate(scene.train)            # SfmOptions() defaults
    pts.xyz, pts.rgb                          (N, 3) float32 world points and colours in [0, 1]
    pts.track_length, pts.error               views per point, mean reprojection error (pixels)
    pts.observations                          (point, view, u, v) of every observation
    pts.stats                                 counts per stage and seconds per stage

Steps: the cameras' images are written to a working folder as PNG (downscaled to ``max_image_size``)
-> a COLMAP database holding one PINHOLE camera per view with its given K -> SIFT features
(``pycolmap.extract_features``, CPU) -> putative matches between every pair
(``pycolmap.match_exhaustive``, ratio test and cross-check) -> verification against the epipolar
geometry of the KNOWN poses (``pycolmap.guided_geometric_verification``: a match is kept when its
Sampson error is within ``max_epipolar_error``; no model is fitted, so wide-baseline pairs with few
matches survive, which RANSAC's 15-inlier minimum and model selection reject) ->
``pycolmap.triangulate_points`` with the poses and intrinsics held fixed, two-view tracks kept ->
points re-measured in the given cameras (reprojection error, depth in every observing view),
filtered, and coloured from the given images.

Only the cameras passed in are used: callers pass the training views, never test views. Poses are
never estimated; ``verification="ransac"`` (see ``SfmOptions.colmap_defaults``) verifies matches with
COLMAP's own two-view geometry estimation instead, as the reference the defaults were tuned against
(``bench/perf/sfm_init.py``).
"""

from __future__ import annotations

import contextlib
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np


class SfmError(ValueError):
    """Triangulation cannot give points for these views; the one-line message says why."""


class SfmInputError(SfmError):
    """The input cannot be triangulated at all (fewer than 2 views, a bad option, image or matrix, pycolmap
    missing): unlike too few matches or points, no other initialisation helps, so callers do not fall back."""


@dataclass
class SfmOptions:
    """Every threshold of the pipeline. Pixel thresholds are in pixels of the extraction images."""

    # feature extraction (SIFT on the CPU)
    max_image_size: int = 1600  # images with a larger side are downscaled for extraction (K scaled with them)
    max_features: int = 8192  # per view; the largest-scale features are kept
    peak_threshold: float = 0.004  # SIFT's DoG contrast threshold (COLMAP: 0.0067): more features where texture is weak
    first_octave: int = -1  # -1 upsamples the image first: finer features on small images
    upright: bool = False  # orientation fixed to 0 (only for captures without camera roll)
    domain_size_pooling: bool = False  # DSP-SIFT descriptors: more matches, but a much slower extraction
    # matching
    max_ratio: float = 0.8  # Lowe's ratio test; looser lets in repeated structure that the epipolar test cannot reject
    max_distance: float = 0.7  # largest descriptor distance of a match
    cross_check: bool = True  # mutual nearest neighbours only
    verification: str = "poses"  # "poses": Sampson error under the known poses; "ransac": COLMAP's model estimation
    max_epipolar_error: float = 1.0  # pixels: largest Sampson error of a verified match (RANSAC threshold for "ransac")
    min_num_inliers: int = 8  # pairs with fewer verified matches are not used
    # triangulation (pycolmap.triangulate_points, poses and intrinsics fixed)
    min_angle: float = 2.0  # degrees: smallest triangulation angle (depth error grows as 1 / angle)
    max_angle_error: float = 2.0  # degrees: ray error to create or continue a track
    max_reproj_error: float = 2.0  # pixels: to merge or complete tracks and to keep a point
    ignore_two_view_tracks: bool = False  # COLMAP's default (True) drops points seen by 2 views: most of them at 3 views
    min_track_length: int = 2  # points seen by fewer views are dropped
    seed: int = 0  # triangulation/RANSAC seed
    # 1: bit-identical points run to run. -1 (all cores) is faster on many-core machines, but COLMAP's
    # thread pools can then change a few points between runs (a CI run got 854 against 856 points)
    num_threads: int = 1

    @classmethod
    def colmap_defaults(cls) -> "SfmOptions":
        """COLMAP's own settings (RANSAC verification, two-view tracks dropped) on the known poses: the
        reference the defaults above were tuned against."""
        return cls(max_image_size=3200, max_features=8192, peak_threshold=0.02 / 3, max_ratio=0.8,
                   verification="ransac", max_epipolar_error=4.0, min_num_inliers=15,
                   min_angle=1.5, max_reproj_error=4.0, ignore_two_view_tracks=True)

    def check(self) -> None:
        if self.verification not in ("poses", "ransac"):
            raise SfmInputError(f"sfm verification={self.verification!r}: use 'poses' or 'ransac'")
        positive = ("max_image_size", "max_features", "peak_threshold", "max_ratio", "max_distance",
                    "max_epipolar_error", "max_angle_error", "max_reproj_error")
        for name in positive:
            if not getattr(self, name) > 0:
                raise SfmInputError(f"sfm option {name}={getattr(self, name)!r} must be positive")
        if self.min_track_length < 2:
            raise SfmInputError(f"sfm option min_track_length={self.min_track_length} must be at least 2")


@dataclass
class SfmPoints:
    xyz: np.ndarray  # (N, 3) float32, the world of the cameras' viewmats
    rgb: np.ndarray  # (N, 3) float32 in [0, 1]
    track_length: np.ndarray  # (N,) int32, views that see the point
    error: np.ndarray  # (N,) float32 mean reprojection error in pixels of the given cameras
    stats: dict = field(default_factory=dict)  # views, features, matches, pairs, points, seconds per stage
    # (M, 4) float64 rows (point index, view index, u, v): where each point was observed, in pixels of
    # the given cameras, sorted by point then view (sparse depth per view, evaluation)
    observations: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))


PIP_HINT = "pycolmap is not installed: pip install pycolmap (CPU wheel) to triangulate points from the training views"


def _import_pycolmap():
    try:
        import pycolmap  # noqa: PLC0415 (optional dependency)
    except ImportError as e:
        raise SfmInputError(PIP_HINT) from e
    return pycolmap


@contextlib.contextmanager
def _quiet(pycolmap):
    """COLMAP logs through glog at INFO; keep only its errors while we run, then restore."""
    lg = pycolmap.logging
    saved = (lg.minloglevel, lg.verbose_level)
    lg.minloglevel, lg.verbose_level = 2, 0
    try:
        yield
    finally:
        lg.minloglevel, lg.verbose_level = saved


@contextlib.contextmanager
def _folder(workdir):
    """The working folder: a temporary one, or ``workdir`` (kept; a database left there is replaced)."""
    if workdir is None:
        with tempfile.TemporaryDirectory(prefix="warpgs-sfm-") as d:
            yield Path(d)
    else:
        d = Path(workdir)
        d.mkdir(parents=True, exist_ok=True)
        for stale in ("database.db", "database.db-wal", "database.db-shm"):
            (d / stale).unlink(missing_ok=True)
        yield d


def _check_cameras(cameras: Sequence) -> None:
    """At least two views, each with an image of its camera's size and finite matrices."""
    if len(cameras) < 2:
        raise SfmInputError(f"sfm needs at least 2 training views, got {len(cameras)}")
    for k, c in enumerate(cameras):
        img = np.asarray(c.image)
        if img.ndim != 3 or img.shape[2] < 3 or img.shape[:2] != (c.height, c.width):
            raise SfmInputError(f"sfm view {k} ({c.name}): image of shape {img.shape} does not match its {c.width}x{c.height} camera")
        V, K = np.asarray(c.viewmat, np.float64), np.asarray(c.K, np.float64)
        if V.shape != (4, 4) or K.shape != (3, 3) or not (np.all(np.isfinite(V)) and np.all(np.isfinite(K))):
            raise SfmInputError(f"sfm view {k} ({c.name}): viewmat must be a finite 4x4 and K a finite 3x3 matrix")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise SfmInputError(f"sfm view {k} ({c.name}): focal lengths fx={K[0, 0]:g}, fy={K[1, 1]:g} must be positive")


def _write_images(cameras, folder: Path, max_size: int) -> tuple[list[str], list[np.ndarray], list[list[int]]]:
    """Writes each view as a lossless PNG named by its index -> (names, K and [w, h] of the written images)."""
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    names, Ks, sizes = [], [], []
    for k, c in enumerate(cameras):
        rgb = np.clip(np.round(np.asarray(c.image)[..., :3] * 255.0), 0, 255).astype(np.uint8)
        im = Image.fromarray(rgb)
        s = min(1.0, max_size / max(c.width, c.height))
        K = np.asarray(c.K, np.float64).copy()
        if s < 1.0:
            w, h = max(1, round(c.width * s)), max(1, round(c.height * s))
            im = im.resize((w, h), Image.Resampling.LANCZOS)
            K[0] *= w / c.width  # pixel edges scale with the image, so centres at +0.5 stay centres
            K[1] *= h / c.height
        name = f"{k:04d}.png"
        im.save(folder / name, compress_level=1)
        names.append(name)
        Ks.append(K)
        sizes.append(list(im.size))
    return names, Ks, sizes


def _rigid(pycolmap, M: np.ndarray):
    return pycolmap.Rigid3d(pycolmap.Rotation3d(np.ascontiguousarray(M[:3, :3])), np.ascontiguousarray(M[:3, 3]))


def _viewmat(cam) -> np.ndarray:
    """World->camera as float64 with the rotation re-orthonormalised (float32 storage leaves ~1e-7)."""
    V = np.asarray(cam.viewmat, np.float64).copy()
    u, _, vt = np.linalg.svd(V[:3, :3])
    V[:3, :3] = u @ vt
    return V


def _prepare_database(pycolmap, db, names: list[str], Ks: list[np.ndarray], sizes: list[list[int]]) -> None:
    """Writes one PINHOLE camera (the given K), a trivial rig, an image and a frame per view, with ids
    1..N in the views' order, before extraction. Feature extraction then fills in the keypoints of
    these images instead of creating its own: its writer numbers images in the order its threads
    finish, which would make the ids, and so the results, depend on thread timing."""
    for k, (name, K, (w, h)) in enumerate(zip(names, Ks, sizes)):
        cam = pycolmap.Camera.create_from_model_name(k + 1, "PINHOLE", float(K[0, 0]), int(w), int(h))
        cam.params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
        db.write_camera(cam, use_camera_id=True)
        rig = pycolmap.Rig()
        rig.rig_id = k + 1
        rig.add_ref_sensor(cam.sensor_id)
        db.write_rig(rig, use_rig_id=True)
        im = pycolmap.Image(name=name, camera_id=k + 1, image_id=k + 1)
        im.frame_id = k + 1
        frame = pycolmap.Frame()
        frame.frame_id, frame.rig_id = k + 1, k + 1
        frame.add_data_id(im.data_id)
        db.write_frame(frame, use_frame_id=True)  # before the image, which must belong to a frame
        db.write_image(im, use_image_id=True)


def _known_pose_reconstruction(pycolmap, db, Vs: list[np.ndarray]):
    """A Reconstruction holding the database's cameras, rigs, frames and images (same ids and names),
    every frame registered with its view's pose.

    pycolmap 4 keeps poses on frames (``rig_from_world``), not on images; in a trivial rig (one
    camera, the reference sensor) rig == camera, so ``rig_from_world`` is the world->camera pose.
    """
    rec = pycolmap.Reconstruction()
    for cam in db.read_all_cameras():
        rec.add_camera(cam)
    for rig in db.read_all_rigs():  # after the cameras they refer to
        rec.add_rig(rig)
    frames = {f.frame_id: f for f in db.read_all_frames()}
    for im in sorted(db.read_all_images(), key=lambda im: im.image_id):
        frame = frames[im.frame_id]
        frame.rig_from_world = _rigid(pycolmap, Vs[im.image_id - 1])
        rec.add_frame(frame)
        rec.add_image(im)
    return rec


def _match_counts(pycolmap, db_path, min_inliers: int) -> tuple[int, int, int]:
    """-> (putative matches, verified matches, pairs with at least ``min_inliers`` verified matches)."""
    with pycolmap.Database.open(db_path) as db:
        putative = int(db.num_matches())
        _, geoms = db.read_two_view_geometries()
    counts = [len(g.inlier_matches) for g in geoms]
    return putative, int(sum(counts)), sum(1 for c in counts if c >= min_inliers)


def _pipeline_options(pycolmap, opts: SfmOptions):
    """Triangulation settings; bundle adjustment refines only the points (frames are fixed by
    ``triangulate_points``, intrinsics here)."""
    po = pycolmap.IncrementalPipelineOptions()
    po.min_num_matches = max(1, opts.min_num_inliers)
    po.num_threads = opts.num_threads
    po.random_seed = opts.seed
    po.extract_colors = False
    po.ba_refine_focal_length = False
    po.ba_refine_principal_point = False
    po.ba_refine_extra_params = False
    tri = po.triangulation
    tri.min_angle = opts.min_angle
    tri.create_max_angle_error = opts.max_angle_error
    tri.continue_max_angle_error = opts.max_angle_error
    tri.merge_max_reproj_error = opts.max_reproj_error
    tri.complete_max_reproj_error = opts.max_reproj_error
    tri.ignore_two_view_tracks = opts.ignore_two_view_tracks
    tri.random_seed = opts.seed
    po.triangulation = tri
    mp = po.mapper
    mp.filter_max_reproj_error = opts.max_reproj_error
    mp.filter_min_tri_angle = opts.min_angle
    mp.random_seed = opts.seed
    po.mapper = mp
    return po


def _collect(rec, cameras, Ks, opts: SfmOptions):
    """Points of the reconstruction, re-measured in the given cameras (float64): per-point mean
    reprojection error against the keypoints, depth in every observing view, colour as the mean of
    the given images at the keypoints."""
    index = {im.image_id: im.image_id - 1 for im in rec.images.values()}  # ids are 1..N (_prepare_database)
    kp = {iid: np.array([p.xy for p in im.points2D], np.float64).reshape(-1, 2) for iid, im in rec.images.items()}
    ids = sorted(rec.point3D_ids())
    xyz = np.zeros((len(ids), 3))
    obs_p, obs_v, obs_uv, obs_k = [], [], [], []
    for n, pid in enumerate(ids):
        p = rec.point3D(pid)
        xyz[n] = p.xyz
        for el in p.track.elements:
            obs_p.append(n)
            obs_v.append(index[el.image_id])
            obs_uv.append(kp[el.image_id][el.point2D_idx])
            obs_k.append(el.point2D_idx)
    obs_p, obs_v = np.asarray(obs_p, np.int64), np.asarray(obs_v, np.int64)
    obs_uv = np.asarray(obs_uv, np.float64).reshape(-1, 2)
    err = np.zeros(len(obs_p))
    depth = np.zeros(len(obs_p))
    rgb = np.zeros((len(obs_p), 3))
    for k, c in enumerate(cameras):
        sel = obs_v == k
        if not sel.any():
            continue
        V = np.asarray(c.viewmat, np.float64)
        pc = xyz[obs_p[sel]] @ V[:3, :3].T + V[:3, 3]
        q = pc @ Ks[k].T
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = q[:, :2] / q[:, 2:3]
        err[sel] = np.linalg.norm(uv - obs_uv[sel], axis=1)
        depth[sel] = pc[:, 2]
        # keypoints are in extraction pixels; the colour comes from the given image's pixel under it
        sx, sy = float(c.K[0, 0]) / Ks[k][0, 0], float(c.K[1, 1]) / Ks[k][1, 1]
        j = np.clip(np.floor(obs_uv[sel, 0] * sx).astype(np.int64), 0, c.width - 1)
        i = np.clip(np.floor(obs_uv[sel, 1] * sy).astype(np.int64), 0, c.height - 1)
        rgb[sel] = np.asarray(c.image, np.float64)[i, j, :3]
    n_pts = len(ids)
    track = np.bincount(obs_p, minlength=n_pts)
    mean_err = np.bincount(obs_p, err, minlength=n_pts) / np.maximum(track, 1)
    bad_depth = np.bincount(obs_p, (depth <= 0).astype(float), minlength=n_pts) > 0
    colour = np.stack([np.bincount(obs_p, rgb[:, ch], minlength=n_pts) for ch in range(3)], 1) / np.maximum(track, 1)[:, None]
    # errors in the pixels of the given cameras (the extraction may have been downscaled)
    scale = np.array([float(c.K[0, 0]) / Ks[k][0, 0] for k, c in enumerate(cameras)])
    err_given = np.bincount(obs_p, err * scale[obs_v], minlength=n_pts) / np.maximum(track, 1)
    keep = (~bad_depth) & (mean_err <= opts.max_reproj_error) & (track >= opts.min_track_length) & np.all(np.isfinite(xyz), 1)
    # a canonical order that does not depend on COLMAP's numbering of points: a keypoint belongs to
    # one point at most, so the first (view, keypoint) of each track is a unique key
    first = np.full(n_pts, np.iinfo(np.int64).max)
    np.minimum.at(first, obs_p, obs_v * (1 << 32) + np.asarray(obs_k, np.int64))
    keep = np.nonzero(keep)[0]
    keep = keep[np.argsort(first[keep], kind="stable")]
    new_index = np.full(n_pts, -1)
    new_index[keep] = np.arange(len(keep))
    rows = np.nonzero(new_index[obs_p] >= 0)[0]
    rows = rows[np.lexsort((obs_v[rows], new_index[obs_p[rows]]))]
    obs = np.c_[new_index[obs_p[rows]], obs_v[rows], obs_uv[rows] * scale[obs_v[rows], None]]
    return (xyz[keep].astype(np.float32), np.clip(colour[keep], 0, 1).astype(np.float32),
            track[keep].astype(np.int32), err_given[keep].astype(np.float32), obs, int(n_pts))


def _check_poses(rec, Vs) -> float:
    """Largest change of a camera pose entry after triangulation (must stay ~0: poses are fixed)."""
    worst = 0.0
    for im in rec.images.values():
        M = np.eye(4)
        M[:3] = im.cam_from_world().matrix()
        V = Vs[im.image_id - 1]
        worst = max(worst, float(np.abs(M[:3, :3] - V[:3, :3]).max()),
                    float(np.abs(M[:3, 3] - V[:3, 3]).max() / max(1.0, np.abs(V[:3, 3]).max())))
    return worst


def _extract(pycolmap, db_path: Path, img_dir: Path, names, Ks, sizes, opts: SfmOptions) -> list[int]:
    """SIFT features of every view into the database -> features per view."""
    with pycolmap.Database.open(db_path) as db:
        _prepare_database(pycolmap, db, names, Ks, sizes)
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = opts.num_threads
    ext.max_image_size = opts.max_image_size  # the images are written no larger than this
    sift = ext.sift
    sift.max_num_features = opts.max_features
    sift.peak_threshold = opts.peak_threshold
    sift.first_octave = opts.first_octave
    sift.upright = opts.upright
    sift.domain_size_pooling = opts.domain_size_pooling
    ext.sift = sift
    pycolmap.extract_features(db_path, img_dir, image_names=names, camera_mode=pycolmap.CameraMode.PER_IMAGE,
                              extraction_options=ext, device=pycolmap.Device.cpu)
    n = len(names)
    with pycolmap.Database.open(db_path) as db:
        if db.num_images() != n or db.num_cameras() != n:  # extraction must have used the prepared images
            raise SfmError(f"sfm: feature extraction left {db.num_images()} images and {db.num_cameras()} cameras "
                           f"in the database for {n} views")
        return [int(db.num_keypoints_for_image(k + 1)) if db.exists_keypoints(k + 1) else 0 for k in range(n)]


def _match(pycolmap, db_path: Path, rec, opts: SfmOptions) -> None:
    """Putative matches of every pair, then verification: under the known poses, or by RANSAC."""
    mo = pycolmap.FeatureMatchingOptions()
    mo.num_threads = opts.num_threads
    sm = mo.sift
    sm.max_ratio, sm.max_distance, sm.cross_check = opts.max_ratio, opts.max_distance, opts.cross_check
    mo.sift = sm
    mo.skip_geometric_verification = opts.verification == "poses"
    tvg = pycolmap.TwoViewGeometryOptions()
    tvg.min_num_inliers = opts.min_num_inliers
    tvg.ransac.max_error = opts.max_epipolar_error
    tvg.ransac.random_seed = opts.seed
    pycolmap.match_exhaustive(db_path, matching_options=mo, verification_options=tvg, device=pycolmap.Device.cpu)
    if opts.verification == "poses":
        # writes each pair's relative pose from ``rec`` and keeps the matches within the Sampson threshold
        pycolmap.guided_geometric_verification(rec, db_path, two_view_geometry_options=tvg,
                                               num_threads=opts.num_threads)


class SfmNativeError(SfmError):
    """pycolmap's child process died (a signal), hung past its time limit or left no result: the next
    initialisation of the chain takes over (``warpgs.points.initial_geometry``), and the line is recorded."""


SFM_TIMEOUT_S = 1800.0  # the child process of a triangulation is stopped after this long


def triangulate(cameras: Sequence, options: SfmOptions | None = None, *, workdir: str | Path | None = None,
                log: Callable[[str], Any] = print, isolate: bool = True,
                timeout_s: float = SFM_TIMEOUT_S) -> SfmPoints:
    """Triangulates a sparse point cloud from ``cameras`` (their images, K and viewmat; nothing
    else is read) with the poses held fixed. ``workdir``: keep the images, database and COLMAP
    model there (default: a temporary folder). ``log`` gets one summary line.

    The inputs are checked here (at least 2 views, images of their cameras' sizes, finite matrices, positive focal
    lengths); pycolmap then runs in a child process (``isolate``; ``warpgs.densify.native``), never imported into
    this one, so that its aborts and glog's signal handlers stay there: a child that dies or runs past
    ``timeout_s`` raises SfmNativeError.

    Raises SfmError (one line) for fewer than 2 views, pycolmap missing, no verified matches between
    any pair, or no point triangulated."""
    opts = options or SfmOptions()
    opts.check()
    cameras = list(cameras)
    _check_cameras(cameras)
    if not isolate:
        pts, line = _triangulate_here(cameras, opts, workdir)
    else:
        from warpgs.densify.native import NativeStepFailed, run_native

        try:
            pts, line = run_native("sfm", _triangulate_here, cameras, opts, workdir, timeout_s=timeout_s)
        except NativeStepFailed as e:
            raise SfmNativeError(f"pycolmap: {e}") from None
    log(line)
    return pts


def _triangulate_here(cameras: list, opts: SfmOptions, workdir) -> tuple[SfmPoints, str]:
    """``triangulate``'s work in this process: (the points, the summary line)."""
    pycolmap = _import_pycolmap()
    n, n_pairs = len(cameras), len(cameras) * (len(cameras) - 1) // 2
    Vs = [_viewmat(c) for c in cameras]
    secs: dict[str, float] = {}
    t_all = t = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal t
        now = time.perf_counter()
        secs[stage], t = now - t, now

    with _folder(workdir) as wd, _quiet(pycolmap):
        pycolmap.set_random_seed(opts.seed)
        img_dir, db_path, out_dir = wd / "images", wd / "database.db", wd / "sparse"
        names, Ks, sizes = _write_images(cameras, img_dir, opts.max_image_size)
        lap("write")
        feats = _extract(pycolmap, db_path, img_dir, names, Ks, sizes, opts)
        with pycolmap.Database.open(db_path) as db:
            rec = _known_pose_reconstruction(pycolmap, db, Vs)
        lap("extract")
        _match(pycolmap, db_path, rec, opts)
        putative, verified, pairs = _match_counts(pycolmap, db_path, opts.min_num_inliers)
        lap("match")
        stats: dict[str, Any] = {
            "views": n, "names": [c.name for c in cameras],
            "image_size": sizes[0] if len(set(map(tuple, sizes))) == 1 else sizes,
            "features": feats, "putative_matches": putative, "verified_matches": verified,
            "verified_pairs": pairs, "pairs": n_pairs,
        }
        if pairs == 0:
            raise SfmError(
                f"no feature matches between the {n} training views ({int(np.median(feats))} features per view, "
                f"{putative} putative matches, none verified): the images are textureless or overlap too little")
        out_dir.mkdir(parents=True, exist_ok=True)
        try:
            rec = pycolmap.triangulate_points(rec, db_path, img_dir, out_dir, clear_points=True,
                                              options=_pipeline_options(pycolmap, opts), refine_intrinsics=False)
        except Exception as e:  # pycolmap raises RuntimeError/ValueError from its C++ checks
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise SfmError(f"pycolmap could not triangulate the {n} training views: {first}") from e
        drift = _check_poses(rec, Vs)
        if drift > 1e-6:
            raise SfmError(f"pycolmap moved the given camera poses during triangulation (by {drift:.2g}); points refused")
        xyz, rgb, track, err, obs, raw = _collect(rec, cameras, Ks, opts)
        lap("triangulate")

    secs["total"] = time.perf_counter() - t_all
    stats.update({
        "points_triangulated": raw, "points": int(len(xyz)),
        "median_error": float(np.median(err)) if len(err) else math.nan,
        "mean_track_length": float(track.mean()) if len(track) else 0.0,
        "seconds": {k: round(v, 3) for k, v in secs.items()},
    })
    if len(xyz) == 0:
        raise SfmError(
            f"no 3D points triangulated from the {n} training views ({pairs} verified pairs, {verified} matches): "
            "the baselines are too small or the views overlap too little")
    line = (f"sfm: {len(xyz)} points from {n} views ({pairs}/{n_pairs} pairs verified, median error "
            f"{stats['median_error']:.2f} px, {secs['total']:.1f} s)")
    return SfmPoints(xyz, rgb, track, err, stats, obs), line


__all__ = ["SFM_TIMEOUT_S", "SfmError", "SfmInputError", "SfmNativeError", "SfmOptions", "SfmPoints", "triangulate"]
