"""The tables of docs/benchmarks.md, generated from the committed results (not typed by hand).

    python bench/report/docs_tables.py [--results bench/results]                   # print every table
    python bench/report/docs_tables.py --write docs/benchmarks.md                   # put each between its markers

Each table goes between ``<!-- NAME: start -->`` and ``<!-- NAME: end -->`` of the file, NAME one of ``TABLES``:

- ``current_figures``: the README's table of test PSNR of the current defaults (``readme_tables.py``);
- ``rasterizer``: warpgs against gsplat 1.5.3, forward+backward per call, from ``perf/rasterizer_vs_gsplat_*.json``
  (``bench/perf/rasterizer.py``): random Gaussians, and a model trained on fern at 1x, 2x and 3x its test view;
- ``train_speed``: the trainer against plain training loops, from ``perf/train_speed_*.json``
  (``bench/perf/train_speed.py``);

Every table names the machine each figure was measured on. The tables beside the charts (speed against accuracy,
stability, compact mode) are ``bench/report/charts.py``'s.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from markers import markers, replace_between_markers  # noqa: E402
from readme_tables import rows as current_figures  # noqa: E402

RASTERIZER = (("perf/rasterizer_vs_gsplat_random_h200.json", "random"),
              ("perf/rasterizer_vs_gsplat_fern_h200.json", "trained on fern"))
TRAIN_SPEED = ("perf/train_speed_fern_h200.json", "perf/train_speed_cpu.json")


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def _load(results: Path, name: str) -> dict:
    return json.loads((results / name).read_text())


def rasterizer(results: Path) -> list[str]:
    rows = []
    for name, what in RASTERIZER:
        doc = _load(results, name)
        for c in doc["configs"]:
            p = c["ratio_fwd_bwd_paired"]
            rows.append([f"{c['gaussians']:,} {what}", f"{c['width']}x{c['height']}", str(c.get("sh_degree") or "RGB"),
                         f"{c['warpgs']['forward_backward_ms']:.2f}", f"{c['gsplat']['forward_backward_ms']:.2f}",
                         f"{p['median']:.2f} [{p['min']:.2f}, {p['max']:.2f}]", f"{c['ratio_fwd']:.2f}",
                         doc["device"], f"`{name}`"])
    return _table(["Gaussians", "image", "SH degree", "warpgs ms", "gsplat ms", "warpgs / gsplat (fwd+bwd)",
                   "warpgs / gsplat (fwd)", "machine", "source"], rows)


def train_speed(results: Path) -> list[str]:
    rows = []
    for name in TRAIN_SPEED:
        doc = _load(results, name)
        m, s = doc["machine"], doc["settings"]
        machine = m.get("gpu") if s["device"] == "cuda" else f"{m['cpu']}, {m['cpu_count']} cores"
        setting = f"{s['scene']}, {s['views']} views, {s['width']}x{s['height']}, {s['iterations']} it"
        for loop, r in doc["loops"].items():
            rows.append([setting, loop, f"{r['seconds']:.2f}", f"{r['it_per_s']:.1f}", f"{r['gaussians']:,}",
                         f"{r['test_psnr']:.2f}", machine, f"`{name}`"])
    return _table(["setting", "loop", "seconds", "it/s", "Gaussians", "test PSNR", "machine", "source"], rows)


TABLES = {"current_figures": current_figures, "rasterizer": rasterizer, "train_speed": train_speed}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path(__file__).resolve().parents[1] / "results")
    ap.add_argument("--write", type=Path, default=None, help="replace each table between its markers in this file")
    args = ap.parse_args(argv)
    tables = {name: "\n".join(fn(args.results)) for name, fn in TABLES.items()}
    if args.write is None:
        for name, text in tables.items():
            print(f"## {name}\n\n{text}\n")
        return 0
    doc = args.write.read_text()
    present = [name for name in tables if markers(name)[0] in doc]  # the README holds some of them
    if not present:
        ap.error(f"{args.write}: no table markers ({', '.join(markers(n)[0] for n in tables)})")
    try:
        for name in present:
            doc = replace_between_markers(doc, tables[name], *markers(name))
    except ValueError as e:
        ap.error(f"{args.write}: {e}")
    args.write.write_text(doc)
    print(f"wrote {len(present)} tables into {args.write}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
