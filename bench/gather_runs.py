"""Collects the metrics of many runs into one JSON (what the GPU figures in bench/results/runs come from).

    python bench/gather_runs.py RUNS_DIR OUT.json [--logs OUT.txt]

RUNS_DIR holds one output folder per run (``--out RUNS_DIR/<name>``) and optionally ``<name>.log``;
a run without metrics.json is reported with the end of its log.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

KEYS = ("method", "scene", "train_views", "iterations", "psnr", "ssim", "lpips", "num_gaussians", "train_time_s",
        "render_fps", "peak_cuda_allocated_mb", "peak_rss_mb", "seed", "device", "curve", "cycles", "compact",
        "recoveries", "initial_psnr", "train_psnr", "init", "stage_times_s", "stopped_early")


def gather(runs: Path) -> dict:
    out = {}
    for d in sorted(p for p in runs.iterdir() if p.is_dir()):
        found = sorted(d.rglob("metrics.json"))
        log = runs / f"{d.name}.log"
        row = {}
        for m in found:
            data = json.loads(m.read_text())
            row[str(m.parent.relative_to(d)) or "."] = {k: data[k] for k in KEYS if k in data}
        if (d / "comparison.json").is_file():
            row["comparison"] = json.loads((d / "comparison.json").read_text())
        if not found and log.is_file():
            row["log_tail"] = log.read_text()[-2000:]
        out[d.name] = row
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--logs", type=Path, default=None, help="also write the end of every log here")
    a = ap.parse_args(argv)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(gather(a.runs), indent=1))
    if a.logs is not None:
        parts = [f"==== {p.name}\n{p.read_text()[-1500:]}" for p in sorted(a.runs.glob("*.log"))]
        a.logs.write_text("\n".join(parts))
    for name, row in gather(a.runs).items():
        for sub, m in row.items():
            if isinstance(m, dict) and "psnr" in m:
                init = m.get("init") or {}
                print(f"{name:>14} {sub:<9} PSNR {m['psnr']:.3f} SSIM {m['ssim']:.4f} (initial "
                      f"{m.get('initial_psnr') or 0:.2f}, train {m.get('train_psnr') or 0:.2f}) n {m.get('num_gaussians')} "
                      f"t {m.get('train_time_s')} init {init.get('method', '-')}:{init.get('points', '-')} "
                      f"{init.get('times', '')}" + (" STOPPED" if m.get("stopped_early") else ""))


if __name__ == "__main__":
    main()
