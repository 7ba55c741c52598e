"""The README's table of current figures, generated from the committed results (not typed by hand).

    python bench/report/readme_tables.py [--results bench/results] [--write README.md]

``--write``: put the table between the file's ``<!-- readme_results: start -->`` and ``<!-- readme_results: end -->``.

One row per scene and setting: the baseline's and the full method's test PSNR as median [min, max] over the seeds
the row names, the full method's gain (difference of the medians), the machine the runs ran on, and the results file.
The sources, all under ``bench/results/quality/``:

- ``noarg_cpu.json``: the no-argument job (``bash scripts/run.sh``: the synthetic room, 3 views, 128x96, 1000 it) per
  seed, made by ``bench/quality/noarg_seeds.py``;
- ``datasets_h200.json``: the current defaults on LLFF fern, DTU scan65 and Blender lego (and lego's best baseline
  setting, the runs with the suffix ``_best``);
- ``captures_384x256_h200.json`` and ``captures_768x512_h200.json``: the current defaults on the captures
  castle_p30 and herz_jesus_p25 at 3, 6 and 9 views (``bench/sweeps/captures_384x256.yaml``, ``captures_768x512.yaml``).

Each summary holds ``{"machine", "date", "runs": {<scene>_<views>v_<method>_s<seed>[_<variant>]: metrics}}``; the
cells are ``bench/report/compare.py``'s.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from compare import by_seed, cell, seeds_text, spread  # noqa: E402
from markers import replace_between_markers  # noqa: E402

START, END = "<!-- readme_results: start -->", "<!-- readme_results: end -->"

NOARG = "quality/noarg_cpu.json"
DATASETS = "quality/datasets_h200.json"
CAPTURES = (("quality/captures_384x256_h200.json", "384x256, 3000 it"),
            ("quality/captures_768x512_h200.json", "768x512 (images_4), 10,000 it"))
NAMED = (("fern_3v", "LLFF fern, 3 views", "504x378, 3000 it"),
         ("scan65_3v", "DTU scan65, 3 views (masked)", "400x300, 3000 it"),
         ("lego_8v", "Blender lego, 8 views", "400x400, 10,000 it"))

HEAD = ["scene", "setting", "machine", "seeds", "baseline", "full", "full - baseline", "source"]


def _row(scene: str, setting: str, machine: str, base: dict, full: dict, source: str) -> str:
    b, f = spread(base), spread(full)
    gain = f"{statistics.median(full.values()) - statistics.median(base.values()):+.2f}" if b and f else "-"
    seeds = sorted(set(base) | set(full))
    return "| " + " | ".join([scene, setting, machine, seeds_text(seeds), cell(b), cell(f), gain, source]) + " |"


def _load(results: Path, name: str) -> dict:
    return json.loads((results / name).read_text())


def rows(results: Path) -> list[str]:
    out = ["| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
    doc = _load(results, NOARG)
    noarg = doc["per_seed"]
    out.append(_row("synthetic room, 3 views", "no arguments: 128x96, 1000 it", doc["machine"],
                    {int(s): v["baseline"]["psnr"] for s, v in noarg.items()},
                    {int(s): v["full"]["psnr"] for s, v in noarg.items()}, f"`{NOARG}`"))
    doc = _load(results, DATASETS)
    runs = by_seed(doc["runs"], "psnr", ["best"])
    for key, label, setting in NAMED:
        out.append(_row(label, setting, doc["machine"], runs.get((f"{key}_baseline", None), {}),
                        runs.get((f"{key}_full", None), {}), f"`{DATASETS}`"))
    out.append(_row("Blender lego, 8 views", "best setting: + opacity noise 0.8, SH degree 1, "
                    "`optim.means_lr_final=3.2e-5`, 10,000 it", doc["machine"],
                    runs.get(("lego_8v_baseline", "best"), {}), {}, f"`{DATASETS}`"))
    for name, setting in CAPTURES:
        doc = _load(results, name)
        runs = by_seed(doc["runs"], "psnr")
        cases = sorted({tuple(k.rsplit("_", 2)[:2]) for k, _ in runs})  # (scene, "<N>v")
        for scene, views in cases:
            out.append(_row(f"{scene}, {views[:-1]} views", setting, doc["machine"],
                            runs.get((f"{scene}_{views}_baseline", None), {}),
                            runs.get((f"{scene}_{views}_full", None), {}), f"`{name}`"))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path(__file__).resolve().parents[1] / "results")
    ap.add_argument("--write", type=Path, default=None, help=f"replace the table between {START} and {END} here")
    args = ap.parse_args(argv)
    table = "\n".join(rows(args.results))
    if args.write is None:
        print(table)
        return 0
    try:
        args.write.write_text(replace_between_markers(args.write.read_text(), table, START, END))
    except ValueError as e:
        ap.error(f"{args.write}: {e}")
    print(f"wrote the table into {args.write}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
