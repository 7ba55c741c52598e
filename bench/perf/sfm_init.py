"""SfM initialisation benchmark: points, reprojection error, accuracy and time of ``warpgs.points.sfm``.

    python bench/perf/sfm_init.py                                   # castle_p30, herz_jesus_p25 x 3/6/9 views
    python bench/perf/sfm_init.py --scenes castle_p30 --views 3 --variant tuned --variant 'loose={"min_angle": 1.0}'

For each scene, number of views and option set it triangulates the sparse-view training views (the
repository's loader and split: test = every 8th frame, train = round(linspace) over the rest) and
measures the points against a REFERENCE cloud triangulated with the same code from ALL frames of the
scene (test frames included; strict options: ``REFERENCE``, tracks of 3+ views). The reference is for
evaluation only, never an input of a sparse-view run, and is cached outside the repository (``--cache``).

Accuracy without ground truth:
- same keypoint: SIFT finds the same keypoints in a training view whether it is processed with 2 or 30
  frames, so a point and the reference point observed at the same keypoint (within 1 px) of a training
  view should coincide. Reported: the fraction of points that have such a reference point, and over
  those the median of |X - X_ref| / depth and the fractions off by more than 1% and 5% (wrong matches);
- NN: the median distance to the nearest reference point over the point's depth (biased upwards where
  the reference is sparse; its own spacing is listed under the table);
- the median reprojection error in pixels of the given cameras.

Writes ``bench/results/perf/sfm_init_cpu.json`` and prints a markdown table. Every case runs twice (``--repeat``):
the faster time is reported, and ``deterministic`` says whether both runs gave identical points.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.points.sfm import SfmError, SfmOptions, triangulate  # noqa: E402

# the reference cloud: every frame, verification under the known poses, tracks of 3+ views only
REFERENCE = dict(peak_threshold=0.004, max_ratio=0.8, max_epipolar_error=1.0, min_angle=2.0,
                 ignore_two_view_tracks=True, min_track_length=3)
VARIANTS = {
    "defaults": lambda: SfmOptions.colmap_defaults(),  # pycolmap's own settings, on the known poses
    "tuned": lambda: SfmOptions(),  # warpgs' defaults
    # ablations of the two largest changes
    "tuned_3view_tracks": lambda: SfmOptions(ignore_two_view_tracks=True),  # COLMAP's rule: points of 3+ views
    "tuned_ransac": lambda: SfmOptions(verification="ransac", max_epipolar_error=4.0),  # COLMAP's verification
}


def _options(spec: str) -> tuple[str, SfmOptions]:
    """'name' (a preset) or 'name={json}' (SfmOptions() with those fields; "base": "defaults" starts
    from COLMAP's defaults instead)."""
    if "=" not in spec:
        if spec not in VARIANTS:
            raise SystemExit(f"unknown variant {spec!r}; presets: {', '.join(VARIANTS)} (or name={{json}})")
        return spec, VARIANTS[spec]()
    name, text = spec.split("=", 1)
    fields = json.loads(text)
    base = VARIANTS[fields.pop("base", "tuned")]()
    for k, v in fields.items():
        if not hasattr(base, k):
            raise SystemExit(f"SfmOptions has no field {k!r}")
        setattr(base, k, v)
    return name, base


def load_views(data_root: Path, scene: str, views: int | None, downscale: int):
    from warpgs.data.nerfstudio import load_nerfstudio
    from warpgs.data.registry import load_scene

    if views is None:  # every frame, test frames included: the reference only
        return load_nerfstudio(data_root / scene, views=None, downscale=downscale, test_every=0).train
    return load_scene(str(data_root / scene), views=views, downscale=downscale).train


def reference_cloud(data_root: Path, scene: str, downscale: int, cache: Path) -> dict:
    """-> {xyz, obs (point, frame, u, v), names (of the frames), stats}, built once and cached."""
    key = hashlib.sha1(json.dumps([2, scene, downscale, asdict(SfmOptions(**REFERENCE))], sort_keys=True).encode()).hexdigest()[:10]
    path = cache / f"{scene}_ds{downscale}_{key}.npz"
    if not path.is_file():
        cams = load_views(data_root, scene, None, downscale)
        print(f"[{scene}] reference cloud from all {len(cams)} frames (cached in {path}) ...", flush=True)
        pts = triangulate(cams, SfmOptions(**REFERENCE), log=lambda *_: None)
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, xyz=pts.xyz, obs=pts.observations, names=np.array([c.name for c in cams]),
                 stats=json.dumps(pts.stats))
    z = np.load(path, allow_pickle=False)
    return {"xyz": z["xyz"], "obs": z["obs"], "names": [str(n) for n in z["names"]], "stats": json.loads(str(z["stats"]))}


def _depth_in_nearest_view(cams, xyz: np.ndarray) -> np.ndarray:
    """Depth of each point in the training camera nearest to it among those that have it in front."""
    best = np.full(len(xyz), np.inf)
    for c in cams:
        _, z = c.project(xyz)
        d = np.linalg.norm(xyz - c.center[None], axis=1)
        take = (z > 0) & (d < best)
        best[take] = d[take]
    return best


def accuracy(cams, xyz: np.ndarray, ref: np.ndarray) -> dict:
    from scipy.spatial import cKDTree

    if len(xyz) == 0:
        return {"rel3d": None, "out5": None}
    tree = cKDTree(ref.astype(np.float64))
    dist, _ = tree.query(xyz.astype(np.float64), k=1)
    rel = dist / np.maximum(_depth_in_nearest_view(cams, xyz.astype(np.float64)), 1e-9)
    rel = rel[np.isfinite(rel)]
    return {"rel3d": float(np.median(rel)), "rel3d_p90": float(np.percentile(rel, 90)), "out5": float(np.mean(rel > 0.05))}


def keypoint_accuracy(cams, pts, ref: dict, radius: float = 1.0) -> dict:
    """Compares each point with the reference point triangulated from the SAME keypoint: an observation
    (view, u, v) of the point and one of a reference point in that frame within ``radius`` pixels.
    -> matched (fraction of points with such a reference point), and over those the median of
    |X - X_ref| / depth and the fractions off by more than 1% and 5%."""
    from scipy.spatial import cKDTree

    if len(pts.xyz) == 0:
        return {"matched": None, "rel_ref": None, "bad1": None, "bad5": None}
    frame = {n: k for k, n in enumerate(ref["names"])}
    best = np.full(len(pts.xyz), np.inf)
    obs = pts.observations
    for v, c in enumerate(cams):
        rsel = ref["obs"][ref["obs"][:, 1] == frame[c.name]]
        psel = obs[obs[:, 1] == v]
        if len(rsel) == 0 or len(psel) == 0:
            continue
        d, j = cKDTree(rsel[:, 2:4]).query(psel[:, 2:4], k=1, distance_upper_bound=radius)
        hit = np.isfinite(d)
        p_idx = psel[hit, 0].astype(int)
        r_idx = rsel[j[hit], 0].astype(int)
        X, Xr = pts.xyz[p_idx].astype(np.float64), ref["xyz"][r_idx].astype(np.float64)
        _, zr = c.project(Xr)
        rel = np.linalg.norm(X - Xr, axis=1) / np.maximum(zr, 1e-9)
        np.minimum.at(best, p_idx, rel)
    m = np.isfinite(best)
    if not m.any():
        return {"matched": 0.0, "rel_ref": None, "bad1": None, "bad5": None}
    return {"matched": float(m.mean()), "rel_ref": float(np.median(best[m])),
            "bad1": float(np.mean(best[m] > 0.01)), "bad5": float(np.mean(best[m] > 0.05))}


def reference_spacing(cams, ref: np.ndarray) -> float:
    from scipy.spatial import cKDTree

    d, _ = cKDTree(ref.astype(np.float64)).query(ref.astype(np.float64), k=2)
    rel = d[:, 1] / np.maximum(_depth_in_nearest_view(cams, ref.astype(np.float64)), 1e-9)
    return float(np.median(rel[np.isfinite(rel)]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data-root", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--scenes", nargs="+", default=["castle_p30", "herz_jesus_p25"])
    ap.add_argument("--views", nargs="+", type=int, default=[3, 6, 9])
    ap.add_argument("--downscale", type=int, default=4)
    ap.add_argument("--variant", action="append", default=None,
                    help=f"option set: a preset ({', '.join(VARIANTS)}; default: all) or name={{json of SfmOptions "
                    "fields}; repeatable")
    ap.add_argument("--repeat", type=int, default=2, help="runs per case: the fastest time is reported, and "
                    "'deterministic' says whether all runs gave identical points")
    ap.add_argument("--cache", default=os.environ.get("WARPGS_CACHE", str(Path.home() / ".cache" / "warpgs")) + "/sfm_reference")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "perf" / "sfm_init_cpu.json"))
    args = ap.parse_args(argv)
    variants = [_options(v) for v in (args.variant or list(VARIANTS))]
    data_root = Path(args.data_root)
    rows, refs = [], {}
    for scene in args.scenes:
        if not (data_root / scene).is_dir():
            print(f"[{scene}] not found under {data_root}; skipped")
            continue
        ref = reference_cloud(data_root, scene, args.downscale, Path(args.cache))
        all_cams = load_views(data_root, scene, None, args.downscale)
        refs[scene] = {"points": int(len(ref["xyz"])), "frames": len(all_cams),
                       "spacing": reference_spacing(all_cams, ref["xyz"]),
                       "median_error": ref["stats"].get("median_error"), "seconds": ref["stats"].get("seconds")}
        for views in args.views:
            cams = load_views(data_root, scene, views, args.downscale)
            for name, opts in variants:
                row = {"scene": scene, "views": views, "variant": name, "options": asdict(opts),
                       "size": [cams[0].width, cams[0].height]}
                runs = []
                for _ in range(args.repeat):
                    try:
                        runs.append(triangulate(cams, opts, log=lambda *_: None))
                    except SfmError as e:
                        row["error"] = str(e)
                        break
                if runs:
                    pts = runs[0]
                    row["deterministic"] = all(np.array_equal(r.xyz, pts.xyz) for r in runs[1:]) if len(runs) > 1 else None
                    st = dict(pts.stats)
                    st["seconds"] = min((r.stats["seconds"] for r in runs), key=lambda s: s["total"])
                    row.update({"points": int(len(pts.xyz)), "median_error": st["median_error"],
                                "mean_track_length": st["mean_track_length"], "seconds": st["seconds"],
                                "features": st["features"], "putative_matches": st["putative_matches"],
                                "verified_matches": st["verified_matches"], "verified_pairs": st["verified_pairs"],
                                "pairs": st["pairs"], **accuracy(cams, pts.xyz, ref["xyz"]),
                                **keypoint_accuracy(cams, pts, ref)})
                else:
                    row.update({"points": 0})
                rows.append(row)
                print(_line(row), flush=True)
    out = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                       "load_average": [round(x, 2) for x in os.getloadavg()]},
           "date": time.strftime("%Y-%m-%d %H:%M:%S"), "reference": REFERENCE, "references": refs, "rows": rows}
    try:
        import pycolmap

        out["pycolmap"] = pycolmap.__version__
    except ImportError:
        pass
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    print()
    print(table(rows, refs))
    print(f"\nwrote {args.out}")
    return 0


def _pct(v, digits=1):
    return "-" if v is None else f"{100 * v:.{digits}f}%"


def _line(r) -> str:
    if "error" in r:
        return f"{r['scene']} {r['views']:>2} {r['variant']:<14} error: {r['error']}"
    s = r["seconds"]
    return (f"{r['scene']} {r['views']:>2} {r['variant']:<14} {r['points']:>6} pts  err {r['median_error']:.2f}px  "
            f"same-keypoint: matched {_pct(r.get('matched'), 0)} rel {_pct(r.get('rel_ref'), 2)} >1% {_pct(r.get('bad1'))} "
            f">5% {_pct(r.get('bad5'))}  NN {_pct(r.get('rel3d'), 2)}  {s['total']:.1f}s "
            f"(extract {s['extract']:.1f}, match {s['match']:.1f}, triangulate {s['triangulate']:.1f})")


def table(rows, refs) -> str:
    lines = [
        "| scene | views | options | points | median reproj. error (px) | with a ref. point at the same keypoint | "
        "median rel. error vs ref. | >1% off | >5% off | median NN distance to ref. | seconds: total (extract / match+verify / triangulate) |",
        "|" + "---|" * 11,
    ]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['scene']} | {r['views']} | {r['variant']} | 0 | - | - | - | - | - | - | {r['error']} |")
            continue
        s = r["seconds"]
        lines.append(
            f"| {r['scene']} | {r['views']} | {r['variant']} | {r['points']} | {r['median_error']:.2f} | "
            f"{_pct(r.get('matched'), 0)} | {_pct(r.get('rel_ref'), 2)} | {_pct(r.get('bad1'))} | {_pct(r.get('bad5'))} | "
            f"{_pct(r.get('rel3d'), 2)} | {s['total']:.1f} ({s['extract']:.1f} / {s['match']:.1f} / {s['triangulate']:.1f}) |")
    if refs:
        lines.append("")
        lines.append("Reference clouds (all frames, tracks of 3+ views; evaluation only): " + "; ".join(
            f"{k}: {v['points']} points from {v['frames']} frames, median reproj. error {v['median_error']:.2f} px, "
            f"NN spacing {100 * v['spacing']:.2f}% of depth" for k, v in refs.items()))
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
