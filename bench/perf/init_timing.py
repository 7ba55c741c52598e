"""CPU time of the initial-geometry methods (warpgs/points) on the real captures at 768x512 (images_4).

    python bench/perf/init_timing.py [--views 9] [--out bench/results/perf/init_timing_cpu.json]

For castle_p30 and herz_jesus_p25 (../shared/data): seconds for SfM (pycolmap with the poses fixed),
stereo alone (two plane-sweep passes: the resolvable range, then the range found), and sfm+stereo (one
pass over the range of the SfM points), with the number of points and the depth bounds each gives.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import torch

from warpgs.data import load_scene
from warpgs.points import GeometryConfig, initial_geometry

ROOT = Path(__file__).resolve().parents[2]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, default=9)
    ap.add_argument("--data-root", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "perf" / "init_timing_cpu.json"))
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    rows = []
    for scene_name in ("castle_p30", "herz_jesus_p25"):
        scene = load_scene(str(Path(a.data_root) / scene_name), views=a.views, downscale=4)
        for method in ("sfm", "stereo", "sfm+stereo"):
            t0 = time.perf_counter()
            geo = initial_geometry(scene.train, method, GeometryConfig(), device="cpu", log=lambda m: None)
            row = {"scene": scene_name, "views": a.views, "size": [scene.train[0].width, scene.train[0].height],
                   "method": method, "used": geo.method, "points": int(len(geo.xyz)),
                   "bounds": geo.bounds, "loader_bounds": list(scene.bounds), "seconds": round(time.perf_counter() - t0, 2),
                   "stage_seconds": {k: round(v, 2) for k, v in geo.times.items()}}
            rows.append(row)
            print(json.dumps(row))
    out = {"machine": f"{platform.machine()} {torch.get_num_threads()} torch thread(s), Warp CPU (one thread)",
           "cpu_count": __import__("os").cpu_count(), "rows": rows}
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
