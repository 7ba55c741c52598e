"""Behaviour fingerprint: short fixed-seed CPU runs whose metrics and final Gaussians must stay bit-identical
across refactors of the orchestration layer.

    python bench/fingerprint.py --out bench/results/fingerprint_before.json     # record
    python bench/fingerprint.py --check bench/results/fingerprint_before.json   # compare (exit 1 on a change)

Runs (``python -m warpgs.pipelines.sparse`` on the CPU, seed 0), each with ``--method compare`` (the baseline
and the full method): the embedded synthetic scene, lego (8 views), fern (3 views) and castle_p30 (3 views).
Each record holds PSNR, SSIM, the Gaussian count and the SHA-256 of the written point_cloud.ply.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("WARPGS_SHARED_DATA", ROOT.parent / "shared" / "data"))  # the scenes of ../shared
RUNS = {
    "synthetic_compare": ["--method", "compare", "--iterations", "60"],
    "lego_compare": ["--data", str(SHARED / "blender_lego"), "--method", "compare", "--iterations", "40"],
    "fern_compare": ["--data", str(SHARED / "llff_fern"), "--views", "3", "--method", "compare", "--iterations", "40"],
    "castle3_compare": ["--data", str(SHARED / "castle_p30"), "--views", "3", "--method", "compare",
                        "--iterations", "40"],
}


def _records(folder: Path) -> dict:
    out = {}
    for metrics in sorted(folder.rglob("metrics.json")):
        m = json.loads(metrics.read_text())
        ply = metrics.parent / "point_cloud.ply"
        key = str(metrics.parent.relative_to(folder)) or "."
        out[key] = {"psnr": m.get("psnr"), "ssim": m.get("ssim"), "num_gaussians": m.get("num_gaussians"),
                    "ply_sha256": hashlib.sha256(ply.read_bytes()).hexdigest() if ply.is_file() else None}
    return out


def run_all(names) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    result = {}
    for name in names:
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [sys.executable, "-m", "warpgs.pipelines.sparse", "--device", "cpu", "--seed", "0", "--no-progress",
                   "--out", tmp, *RUNS[name]]
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                raise SystemExit(f"{name}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
            result[name] = _records(Path(tmp))
            print(name, json.dumps(result[name]), flush=True)
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", help="write the fingerprint here")
    ap.add_argument("--check", help="compare with this recorded fingerprint")
    ap.add_argument("--only", nargs="*", choices=sorted(RUNS), help="a subset of the runs")
    a = ap.parse_args(argv)
    names = a.only or list(RUNS)
    now = run_all(names)
    if a.out:
        Path(a.out).write_text(json.dumps(now, indent=1) + "\n")
    if a.check:
        ref = json.loads(Path(a.check).read_text())
        bad = [n for n in names if ref.get(n) != now[n]]
        for n in bad:
            print(f"CHANGED {n}:\n  before {ref.get(n)}\n  now    {now[n]}")
        print("bit-identical" if not bad else f"{len(bad)} of {len(names)} runs changed")
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
