"""The method's own claim on the embedded scene: the full method (pseudo views between the inputs, densification
from them, training on both) beats plain 3D-GS at equal iterations, by a margin the seeds support.

The main job exactly as a user runs it with no arguments (``python -m warpgs.pipelines.sparse``: the synthetic
room, 3 views, 128x96, 1000 iterations, both methods), at seed 1. Over seeds 0-2 its gains were +1.72, +1.15 and
+1.30 dB (2-core Intel Xeon, ac08454, 2026-11-28: ``bench/results/quality/noarg_cpu.json``); seed 1 has the smallest,
and the margin asserted, 0.5 dB, is below all three. (At 150 iterations the gain is not yet there on every seed:
+0.99 at seed 0 and -0.44 at seed 1, bc97e12.)"""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARGIN_DB = 0.5


def test_the_full_method_beats_the_baseline_on_the_embedded_scene(tmp_path):
    out = tmp_path / "compare"
    proc = subprocess.run([sys.executable, "-m", "warpgs.pipelines.sparse", "--seed", "1", "--device", "cpu",
                           "--no-progress", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    table = json.loads((out / "comparison.json").read_text())
    base, full = table["baseline"]["psnr"], table["full"]["psnr"]
    assert table["iterations"] == 1000
    assert full - base >= MARGIN_DB, (base, full)
