"""How closely the pseudo views' camera path follows the walk the photographer took: the distance from each held-out
frame of a capture (neither a training nor a test view, between the first and the last input) to the path through
the inputs, for the interpolation ``warpgs.pseudo.trajectory`` uses (a natural cubic spline through the centres with
chord-length knots, as SYN3R) and for the alternatives: straight segments and Catmull-Rom splines (uniform,
centripetal, chordal).

    python bench/path_fit.py [--data-root ../shared/data] [--scenes castle_p30,herz_jesus_p25] [--views 3,6,9]
                             [--out bench/results/s29/path_fit.json]

Prints, per scene and view count, the median and largest distance (m) per interpolation, and over all cases the
median and mean.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

KINDS = ("natural", "line", "catmull_rom_uniform", "catmull_rom_centripetal", "catmull_rom_chordal")


def dense_path(C: np.ndarray, kind: str, n: int = 200) -> np.ndarray:
    """[M, 3] points along the path through the centres ``C`` [N, 3] in order, ``n`` per pair of neighbours."""
    from warpgs.pseudo.trajectory import chord_knots, natural_cubic_spline

    C = np.asarray(C, np.float64)
    if kind == "line":
        return np.concatenate([a + (b - a) * np.linspace(0, 1, n)[:, None] for a, b in zip(C[:-1], C[1:])])
    if kind == "natural":
        k = chord_knots(C)
        f = natural_cubic_spline(k, C)
        return np.concatenate([f(np.linspace(a, b, n)) for a, b in zip(k[:-1], k[1:])])
    alpha = {"catmull_rom_uniform": 0.0, "catmull_rom_centripetal": 0.5, "catmull_rom_chordal": 1.0}[kind]
    P = np.vstack([2 * C[0] - C[1], C, 2 * C[-1] - C[-2]])  # the ends continued by reflection
    out = []
    for i in range(1, len(P) - 2):  # Barry-Goldman's pyramid
        p0, p1, p2, p3 = P[i - 1], P[i], P[i + 1], P[i + 2]
        t0 = 0.0
        t1 = t0 + max(np.linalg.norm(p1 - p0), 1e-9) ** alpha
        t2 = t1 + max(np.linalg.norm(p2 - p1), 1e-9) ** alpha
        t3 = t2 + max(np.linalg.norm(p3 - p2), 1e-9) ** alpha
        t = np.linspace(t1, t2, n)[:, None]
        a1 = (t1 - t) / (t1 - t0) * p0 + (t - t0) / (t1 - t0) * p1
        a2 = (t2 - t) / (t2 - t1) * p1 + (t - t1) / (t2 - t1) * p2
        a3 = (t3 - t) / (t3 - t2) * p2 + (t - t2) / (t3 - t2) * p3
        b1 = (t2 - t) / (t2 - t0) * a1 + (t - t0) / (t2 - t0) * a2
        b2 = (t3 - t) / (t3 - t1) * a2 + (t - t1) / (t3 - t1) * a3
        out.append((t2 - t) / (t2 - t1) * b1 + (t - t1) / (t2 - t1) * b2)
    return np.concatenate(out)


def main(argv=None) -> int:
    from warpgs.data.registry import load_scene
    from warpgs.geometry import camera_centres

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data-root", default=str(ROOT.parent / "shared" / "data"))
    p.add_argument("--scenes", default="castle_p30,herz_jesus_p25")
    p.add_argument("--views", default="3,6,9")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    rows, pooled = [], {k: [] for k in KINDS}
    for scene in args.scenes.split(","):
        every = {c.name: c for c in load_scene("dl3dv", scene=scene, views="all", downscale=8, root=args.data_root).train}
        for views in (int(v) for v in args.views.split(",")):
            sc = load_scene("dl3dv", scene=scene, views=views, downscale=8, root=args.data_root)
            names = [c.name for c in sc.train]
            C = camera_centres(np.array([c.viewmat for c in sc.train], np.float64))  # capture order, as given
            lo, hi = min(int(n) for n in names), max(int(n) for n in names)
            held = [c for n, c in every.items() if n not in names and lo < int(n) < hi]
            H = camera_centres(np.array([c.viewmat for c in held], np.float64))
            row = {"scene": scene, "views": views, "held_out_frames": len(held)}
            for k in KINDS:
                d = np.linalg.norm(H[:, None] - dense_path(C, k)[None], axis=-1).min(1)
                pooled[k] += d.tolist()
                row[k] = {"median_m": round(float(np.median(d)), 3), "max_m": round(float(d.max()), 3)}
            rows.append(row)
            print(f"{scene} {views} views, {len(held)} held-out frames (median / largest distance, m): "
                  + ", ".join(f"{k} {row[k]['median_m']:.2f} / {row[k]['max_m']:.2f}" for k in KINDS))
    summary = {k: {"median_m": round(float(np.median(v)), 3), "mean_m": round(float(np.mean(v)), 3)} for k, v in pooled.items()}
    print("all cases:", ", ".join(f"{k} {s['median_m']:.2f} / {s['mean_m']:.2f}" for k, s in summary.items()))
    if args.out:
        Path(args.out).write_text(json.dumps({"rows": rows, "all": summary}, indent=1))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
