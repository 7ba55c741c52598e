"""The batch runner on 1 GPU against 2 (issue 17's acceptance): the same 8 runs (castle_p30 and herz_jesus_p25,
3 and 9 views, baseline and full, seed 0) through ``python -m warpgs.pipelines.batch`` with a local Ray given
one GPU, then two; the wall times and every run's metrics side by side.

    python bench/perf/batch_scaling.py run --gpus 1 --data-root D --out RUNS/gpu1   # each well within 10 minutes
    python bench/perf/batch_scaling.py run --gpus 2 --data-root D --out RUNS/gpu2
    python bench/perf/batch_scaling.py compare RUNS/gpu1 RUNS/gpu2 --json OUT.json  # ratio, identical metrics?

Run on a 2-GPU host with the scenes' images_4 and transforms.json under D, one call per line. The acceptance asks for a 2-GPU wall time of at most 0.6x
the 1-GPU one, and per-run metrics identical to the single-GPU runs of the same seeds: every key of metrics.json
but the times, speeds and memory figures (``VARYING``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENES = ("castle_p30", "herz_jesus_p25")
VARYING = {"train_time_s", "render_fps", "peak_cuda_allocated_mb", "peak_cuda_reserved_mb", "peak_rss_mb",
           "stage_times_s", "curve", "cycles", "device"}  # cycles / curve hold times; their PSNRs are compared apart


def run(gpus: int, data_root: Path, out: Path, iterations: int, extra: list[str]) -> int:
    cmd = [sys.executable, "-m", "warpgs.pipelines.batch", "--data", ",".join(str(data_root / s) for s in SCENES),
           "--views", "3,9", "--method", "compare", "--seeds", "0", "--iterations", str(iterations), "--device", "cuda",
           "--gpus", str(gpus), "--out", str(out), "--progress-every", "30", *extra]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    if gpus == 1:
        env["CUDA_VISIBLE_DEVICES"] = env.get("CUDA_VISIBLE_DEVICES", "0").split(",")[0]
    t0 = time.time()
    code = subprocess.call(cmd, cwd=ROOT, env=env)
    res = out / "results.json"
    if res.is_file():  # the command's own wall time (Ray's start included) beside the batch's
        data = json.loads(res.read_text())
        data["info"]["command_wall_s"] = round(time.time() - t0, 2)
        res.write_text(json.dumps(data, indent=1))
    return code


def _metrics(folder: Path) -> dict:
    out = {}
    for d in sorted((folder / "runs").iterdir()):
        p = d / "metrics.json"
        if p.is_file():
            out[d.name] = json.loads(p.read_text())
    return out


def compare(one: Path, two: Path) -> dict:
    r1, r2 = (json.loads((f / "results.json").read_text()) for f in (one, two))
    m1, m2 = _metrics(one), _metrics(two)
    runs = {}
    for name in sorted(set(m1) | set(m2)):
        a, b = m1.get(name), m2.get(name)
        if a is None or b is None:
            runs[name] = {"identical": False, "missing_in": "1 GPU" if a is None else "2 GPUs"}
            continue
        differ = sorted(k for k in set(a) | set(b) if k not in VARYING and a.get(k) != b.get(k))
        curves = [c["psnr"] for c in a.get("curve", [])] == [c["psnr"] for c in b.get("curve", [])]
        cycles = [c.get("psnr") for c in a.get("cycles", [])] == [c.get("psnr") for c in b.get("cycles", [])]
        runs[name] = {"identical": not differ and curves and cycles, "differing_keys": differ,
                      "psnr": [a["psnr"], b["psnr"]], "num_gaussians": [a["num_gaussians"], b["num_gaussians"]],
                      "train_time_s": [a["train_time_s"], b["train_time_s"]]}
    w1, w2 = r1["info"]["wall_s"], r2["info"]["wall_s"]
    return {"wall_s": {"1_gpu": w1, "2_gpus": w2}, "ratio": round(w2 / w1, 3), "target_ratio": 0.6,
            "ratio_met": w2 / w1 <= 0.6, "command_wall_s": {"1_gpu": r1["info"].get("command_wall_s"),
                                                            "2_gpus": r2["info"].get("command_wall_s")},
            "runs_finished": {"1_gpu": sum(r["status"] == "finished" for r in r1["runs"]),
                              "2_gpus": sum(r["status"] == "finished" for r in r2["runs"])},
            "all_identical": len(runs) == 8 and all(r["identical"] for r in runs.values()), "runs": runs,
            "gpu_shares": sorted({r["spec"]["num_gpus"] for r in r1["runs"]}), "info": {"1_gpu": r1["info"], "2_gpus": r2["info"]}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    r = sub.add_parser("run")
    r.add_argument("--gpus", type=int, required=True)
    r.add_argument("--data-root", type=Path, required=True, help="folder holding castle_p30 and herz_jesus_p25")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--iterations", type=int, default=3000)
    r.add_argument("extra", nargs="*", help="more arguments of the batch runner (after --)")
    c = sub.add_parser("compare")
    c.add_argument("one", type=Path)
    c.add_argument("two", type=Path)
    c.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    if a.what == "run":
        return run(a.gpus, a.data_root.resolve(), a.out.resolve(), a.iterations, a.extra)
    result = compare(a.one, a.two)
    text = json.dumps(result, indent=1)
    if a.json:
        a.json.write_text(text)
    print(f"1 GPU {result['wall_s']['1_gpu']:.0f} s, 2 GPUs {result['wall_s']['2_gpus']:.0f} s: ratio {result['ratio']} "
          f"(target <= 0.6: {'met' if result['ratio_met'] else 'NOT met'}); per-run metrics identical: "
          f"{result['all_identical']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
