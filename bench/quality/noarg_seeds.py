"""The no-argument job's figures over seeds, for the README's first row (``readme_results``).

    python bench/quality/noarg_seeds.py --seeds 0 1 2 --out bench/results/quality/noarg_cpu.json [--machine TEXT]

Runs ``bash scripts/run.sh --seed S`` (the synthetic room, 3 views, 128x96, 1000 it, baseline and full in two
processes) for each seed, one after the other, each into its own folder, and writes each seed's
``comparison.json`` and the command's wall time into one JSON (``per_seed``), with the commit and the machine.
Nothing else should run meanwhile: the times are the machine's.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def run_seed(seed: int, out: Path) -> dict:
    t0 = time.perf_counter()
    subprocess.run(["bash", str(ROOT / "scripts" / "run.sh"), "--seed", str(seed), "--out", str(out), "--no-progress"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    row = json.loads(next(out.rglob("comparison.json")).read_text())
    row["wall_s"] = round(time.perf_counter() - t0, 1)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", type=Path, required=True, help="the JSON to write")
    ap.add_argument("--machine", default=None, help="how to name this machine (default: the CPU's model name)")
    args = ap.parse_args(argv)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT).stdout.strip()
    doc = {"what": "bash scripts/run.sh --seed S (the no-argument job: synthetic room, 3 views, 128x96, 1000 it, "
                   "baseline and full in two processes), seeds one after the other, nothing else running",
           "commit": commit, "machine": args.machine or f"{cpu_name()}, {len(os.sched_getaffinity(0))} cores",
           "per_seed": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for s in args.seeds:
            doc["per_seed"][str(s)] = row = run_seed(s, Path(tmp) / f"seed{s}")
            print(f"seed {s}: baseline {row['baseline']['psnr']:.2f}, full {row['full']['psnr']:.2f}, "
                  f"{row['wall_s']:.0f} s", flush=True)
            args.out.write_text(json.dumps(doc, indent=1) + "\n")  # after each seed: nothing lost on a stop
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
