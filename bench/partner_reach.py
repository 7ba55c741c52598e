"""How far the binocular term's partner moves (``warpgs/binocular.py``): the path partner's farthest pose
(``train.binocular_partner: path``, ``warpgs.clearance.path_partners`` at ``--reach``) against the sideways
partner's largest move (``train.binocular_shift`` x the image width of disparity at the input's median depth), per
training view.

    python bench/partner_reach.py                          # castle_p30, herz_jesus_p25 at 3, 6, 9 views; fern 3 views

The median depth is that of the initial points in each input camera: SfM between the training views from 4 views
on, the plane-sweep stereo below (the captures' config, ``geometry.sfm_min_views: 4``), with the default options of
``warpgs.points.initial_geometry`` (not each config's). Writes ``bench/results/s40/partner_reach.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def ratios(cams, xyz: np.ndarray, order: str, reach: float, shift: float) -> list[float]:
    """Per camera: the path partner's farthest move / the sideways partner's largest (both camera-centre distances)."""
    from warpgs.clearance import path_partners

    names = [c.name for c in cams]
    partners = path_partners(np.stack([np.asarray(c.viewmat) for c in cams]), names, order, reach)
    out = []
    for c in cams:
        vm = np.asarray(c.viewmat, np.float64)
        z = (xyz @ vm[:3, :3].T + vm[:3, 3])[:, 2]
        zmed = float(np.median(z[z > 0]))
        sideways = shift * c.width * zmed / float(c.K[0, 0])
        centre = -vm[:3, :3].T @ vm[:3, 3]
        moves = [np.linalg.norm(-p[:3, :3].T @ p[:3, 3] - centre) for p in partners[c.name].double().numpy()]
        out.append(round(float(max(moves)) / sideways, 3))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--reach", type=float, default=0.5)
    ap.add_argument("--shift", type=float, default=0.1)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "s40" / "partner_reach.json"))
    args = ap.parse_args(argv)
    from warpgs.data.registry import load_scene
    from warpgs.points import initial_geometry

    cases = [("dl3dv", s, v, "capture") for s in ("castle_p30", "herz_jesus_p25") for v in (3, 6, 9)]
    cases.append(("llff", "fern", 3, "capture"))
    rows = []
    for data, scene, views, order in cases:
        sc = load_scene(data, scene=scene, views=views, root=args.root)
        method = "sfm" if views >= 4 else "stereo"
        geo = initial_geometry(sc.train, method)
        r = ratios(sc.train, np.asarray(geo.xyz, np.float64), order, args.reach, args.shift)
        rows.append({"data": data, "scene": scene, "views": views, "init": method, "points": int(len(geo.xyz)),
                     "size": [sc.train[0].width, sc.train[0].height], "ratios": r})
        print(f"{scene} {views}v ({method}, {len(geo.xyz)} points): path / sideways move {min(r):.2f} .. {max(r):.2f}"
              f" (median {float(np.median(r)):.2f})", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"reach": args.reach, "shift": args.shift, "cases": rows}, indent=1))
    print("wrote", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
