"""What a sparse-view benchmark pass costs in GPU-hours, from measured per-run times.

    python bench/perf/batch_cost.py                                   # DL3DV from the committed capture runs (H200)
    python bench/perf/batch_cost.py --runs outputs/batch/results.json # from a batch of warpgs.pipelines.batch
    python bench/perf/batch_cost.py --scenes 140 --views 3,6,9 --methods baseline,full --seeds 3 --json out.json

GPU-seconds of one run:
- from a batch's results.json: the run's wall time (all its attempts: start, initial points, training,
  evaluation, outputs) x the GPU share it held (``warpgs.pipelines.batch.gpu_share``);
- from a file of run records (``bench/results/perf/capture_runs_768x512_h200.json``: 768x512 captures, 10,000 it),
  which holds only the stage times: initial points + training, / ``--runs-per-gpu`` (runs that shared one GPU at a
  time while they were measured; those ran 12-13 runs on 2 H200s: 6.25). Start, evaluation and output writing are
  not in those files.

Each (method, views) gets the mean over the files' runs, x ``--pixel-scale`` (the benchmark's pixels per image
over the measured runs': DL3DV's 960x540 images_4 against the 768x512 captures, 1.32; the training cost of the
rasterizer grows about with pixels), x scenes x seeds; views the files lack take the nearest measured count.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CAPTURE_RUNS = ROOT / "bench" / "results" / "perf" / "capture_runs_768x512_h200.json"


def _shown(p: Path) -> str:
    """``p`` relative to the repository where it is in it (no machine's paths in a committed file)."""
    p = Path(p).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def run_costs(path: Path, runs_per_gpu: float, iterations: int | None) -> dict[tuple[str, int], list[float]]:
    """{(method, views): [GPU-seconds of each run]} from a batch's results.json or a file of run records."""
    data = json.loads(Path(path).read_text())
    out: dict[tuple[str, int], list[float]] = {}
    if "runs" in data and isinstance(data["runs"], list):  # warpgs.pipelines.batch
        for r in data["runs"]:
            m = r.get("metrics") or {}
            if r.get("status") == "finished" and not r.get("reused") and (iterations is None or m.get("iterations") == iterations):
                out.setdefault((m["method"], m["train_views"]), []).append(r["wall_s"] * r["spec"]["num_gpus"])
        return out
    for row in data.values():  # a file of run records: {name: {".": metrics}}
        m = row.get(".") if isinstance(row, dict) else None
        if not m or "train_time_s" not in m or (iterations is not None and m.get("iterations") != iterations):
            continue
        init = sum(v for k, v in (m.get("stage_times_s") or {}).items() if k.startswith("init_"))
        out.setdefault((m["method"], m["train_views"]), []).append((m["train_time_s"] + init) / runs_per_gpu)
    return out


def estimate(costs: dict, scenes: int, views: list[int], methods: list[str], seeds: int, pixel_scale: float) -> dict:
    rows, total = [], 0.0
    for method in methods:
        measured = sorted(v for m, v in costs if m == method)
        if not measured:
            raise SystemExit(f"error: no measured run of method {method!r}")
        for v in views:
            near = min(measured, key=lambda x: (abs(x - v), x))
            per_run = statistics.mean(costs[(method, near)]) * pixel_scale
            runs = scenes * seeds
            rows.append({"method": method, "views": v, "measured_views": near, "measured_runs": len(costs[(method, near)]),
                         "gpu_s_per_run": round(per_run, 1), "runs": runs, "gpu_hours": round(per_run * runs / 3600, 2)})
            total += per_run * runs
    return {"rows": rows, "runs": scenes * seeds * len(views) * len(methods), "gpu_hours": round(total / 3600, 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=Path, action="append", default=None, help=f"measured runs (default {CAPTURE_RUNS.relative_to(ROOT)})")
    ap.add_argument("--runs-per-gpu", type=float, default=6.25, help="files of run records: runs that shared one GPU (6.25)")
    ap.add_argument("--iterations", type=int, default=10000, help="only runs of this many steps (0: any)")
    ap.add_argument("--pixel-scale", type=float, default=960 * 540 / (768 * 512), help="benchmark / measured pixels (1.32)")
    ap.add_argument("--scenes", type=int, default=140)
    ap.add_argument("--views", default="3,6,9")
    ap.add_argument("--methods", default="baseline,full")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None, help="also write the estimate here")
    a = ap.parse_args(argv)
    costs: dict = {}
    for p in a.runs or [CAPTURE_RUNS]:
        for k, v in run_costs(p, a.runs_per_gpu, a.iterations or None).items():
            costs.setdefault(k, []).extend(v)
    est = estimate(costs, a.scenes, [int(v) for v in a.views.split(",")], a.methods.split(","), a.seeds, a.pixel_scale)
    est["assumptions"] = {"runs": [_shown(p) for p in a.runs or [CAPTURE_RUNS]], "runs_per_gpu": a.runs_per_gpu,
                          "iterations": a.iterations, "pixel_scale": round(a.pixel_scale, 3), "scenes": a.scenes,
                          "seeds": a.seeds}
    for r in est["rows"]:
        print(f"{r['method']:<9} {r['views']} views: {r['gpu_s_per_run']:7.1f} GPU-s per run (measured at "
              f"{r['measured_views']} views, {r['measured_runs']} runs) x {r['runs']} runs = {r['gpu_hours']:.1f} GPU-h")
    print(f"{est['runs']} runs: {est['gpu_hours']} GPU-hours")
    if a.json:
        a.json.write_text(json.dumps(est, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
