"""How much of each test view a sparse split's training views see at all: a bound on what any method
without a generative prior can reconstruct.

    python bench/diagnostics/covisibility.py                     # castle_p30, herz_jesus_p25 at 3, 6, 9 views
    python bench/diagnostics/covisibility.py --scenes castle_p30 --views 3

Points are triangulated from *every* frame of the capture (its ground-truth poses held fixed, SfM as in
``warpgs.points.sfm``), for this measurement only. For each test view of the standard split, the share
of the points it observes that at least one training view also observes is its covisibility. Writes
``bench/results/quality/covisibility_captures.json``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("WARPGS_SHARED_DATA", ROOT.parent / "shared" / "data"))


def covisibility(scene: str, views_list, downscale: int = 8) -> dict:
    from warpgs.data.nerfstudio import load_nerfstudio
    from warpgs.points.sfm import SfmOptions, triangulate

    every = load_nerfstudio(SHARED / scene, views=None, downscale=downscale)
    cams = sorted(every.train + every.test, key=lambda c: c.name)
    names = [c.name for c in cams]
    pts = triangulate(cams, SfmOptions(), log=print)
    pid, vid = pts.observations[:, 0].astype(int), pts.observations[:, 1].astype(int)
    out = {"scene": scene, "frames": len(cams), "points": int(len(pts.xyz)), "splits": {}}
    for views in views_list:
        split = load_nerfstudio(SHARED / scene, views=views, downscale=downscale)
        seen = np.zeros(len(pts.xyz), bool)
        for c in split.train:
            seen[pid[vid == names.index(c.name)]] = True
        per_test = {}
        for c in split.test:
            mine = np.unique(pid[vid == names.index(c.name)])
            per_test[c.name] = {"points": int(len(mine)), "seen_by_training": round(float(seen[mine].mean()), 4)}
        out["splits"][str(views)] = {"train": [c.name for c in split.train], "test": per_test,
                                     "mean": round(float(np.mean([v["seen_by_training"] for v in per_test.values()])), 4)}
        print(f"{scene} {views} views (train {', '.join(c.name for c in split.train)}): "
              + ", ".join(f"{k} {v['seen_by_training']:.0%}" for k, v in per_test.items())
              + f"; mean {out['splits'][str(views)]['mean']:.0%}")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", nargs="+", default=["castle_p30", "herz_jesus_p25"])
    p.add_argument("--views", nargs="+", type=int, default=[3, 6, 9])
    p.add_argument("--out", default=str(ROOT / "bench" / "results" / "quality" / "covisibility_captures.json"))
    args = p.parse_args(argv)
    result = {s: covisibility(s, args.views) for s in args.scenes}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
