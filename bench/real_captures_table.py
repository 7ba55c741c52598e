"""The README's real-capture table from the GPU run records (bench/gather_runs.py output).

    python bench/real_captures_table.py [bench/results/real_captures/session5_final.json]

Prints markdown: per scene and view count, baseline and full method (PSNR / SSIM), the initial points
(method, count, seconds) and the training time of each run.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

DEFAULT = Path(__file__).resolve().parent / "results" / "real_captures" / "session5_final.json"
SCENES = {"c": "castle_p30", "h": "herz_jesus_p25"}


def _m(runs: dict, name: str) -> dict | None:
    row = runs.get(name, {})
    return row.get(".")


def table(runs: dict) -> str:
    lines = ["| scene | views | images, iterations | baseline PSNR / SSIM | full PSNR / SSIM | full - baseline | "
             "initial points (method, count, s) | training s (baseline / full) |",
             "|---|---|---|---|---|---|---|---|"]
    for tag, label in (("i4", "768x512, 10k"), ("i8", "384x256, 3k")):
        for key, scene in SCENES.items():
            for v in (3, 6, 9):
                b, f = _m(runs, f"{key}{v}_baseline_{tag}"), _m(runs, f"{key}{v}_full_{tag}")
                if b is None:
                    continue
                init = b.get("init") or {}
                secs = "+".join(f"{x:.1f}" for x in (init.get("times") or {}).values())
                gain = f"{f['psnr'] - b['psnr']:+.2f}" if f else "-"
                full = f"{f['psnr']:.2f} / {f['ssim']:.3f}" if f else "-"
                ft = f"{f['train_time_s']:.0f}" if f else "-"
                lines.append(f"| {scene} | {v} | {label} | {b['psnr']:.2f} / {b['ssim']:.3f} | {full} | {gain} | "
                             f"{init.get('method', '-')}, {init.get('points', '-')}, {secs} | {b['train_time_s']:.0f} / {ft} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else DEFAULT
    print(table(json.loads(path.read_text())))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
