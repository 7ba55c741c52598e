"""Median [min, max] over seeds of the runs in summary files (``summary`` of bench/gpu_one.sh: one line per run,
``NAME PSNR GAUSSIANS [per-view] [curve]``, NAME ending in ``_s<seed>``), as a markdown table.

    python bench/seed_medians.py bench/results/s31/o.txt [more files ...]

A row per run name without its seed suffix: the median test PSNR over its seeds, the range, the seeds, and the
median Gaussian count. Rows in the order their first run appears in the files.
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from captures_table import cell  # noqa: E402  (median [min, max], as every capture table writes it)

_LINE = re.compile(r"^(?P<name>\S+)_s(?P<seed>\d+) (?P<psnr>[-\d.]+|nan) (?P<n>\d+)")


def read(paths: list[Path]) -> dict[str, dict[int, tuple[float, int]]]:
    """name -> {seed: (PSNR, Gaussians)} from the summary files (later files win for a repeated run)."""
    rows: dict[str, dict[int, tuple[float, int]]] = {}
    for path in paths:
        for line in path.read_text().splitlines():
            m = _LINE.match(line)
            if m:
                rows.setdefault(m["name"], {})[int(m["seed"])] = (float(m["psnr"]), int(m["n"]))
    return rows


def table(rows: dict[str, dict[int, tuple[float, int]]]) -> list[str]:
    out = ["| run | test PSNR, median [min, max] | seeds | Gaussians (median) |", "|---|---|---|---|"]
    for name, seeds in rows.items():
        n = statistics.median(g for _, g in seeds.values())
        out.append(f"| {name} | {cell({s: p for s, (p, _) in seeds.items()})} | "
                   f"{', '.join(str(s) for s in sorted(seeds))} | {n:,.0f} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    args = ap.parse_args(argv)
    missing = [str(p) for p in args.files if not p.is_file()]
    if missing:
        ap.error(f"no such summary file: {', '.join(missing)}")
    print("\n".join(table(read(args.files))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
