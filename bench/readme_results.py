"""The README's table of current figures, generated from the committed run summaries (not typed by hand).

    python bench/readme_results.py [--results bench/results] [--write README.md]

``--write``: put the table between the file's ``<!-- readme_results: start -->`` and ``<!-- readme_results: end -->``.

One row per scene and setting: the baseline's and the full method's test PSNR as median [min, max] over seeds 0-2
(fewer are marked), the full method's gain (difference of the medians), and where the runs ran. The sources are the
latest runs of the current defaults:
- the no-argument job (synthetic room, 2-core CPU): ``noarg_cpu/seeds_s37.json`` (``bench/noarg_seeds.py``; since
  session 37 CPU runs use MKL's reproducible branch, so the session 30 figures of ``seeds_s30.json`` are history);
- since session 36 LLFF, DTU, Blender and the captures train with opacity decay and binocular consistency
  (``train.opacity_decay``, ``train.binocular``; H200): fern and DTU ``s36/c.txt`` (``c_<scene>_db``,
  ``c_<scene>_full_db``; DTU's full method since session 37 with ``full.pseudo_weight: 0.2``, ``s37/t.txt``,
  ``t_p_dtu_full``), lego ``s36/e.txt`` (``e_lego_baseline_db``) and ``s36/f.txt`` (``f_lego_full``), lego's
  best setting (opacity noise 0.8, SH degree 1, ``optim.means_lr_final=3.2e-5``) ``s36/c.txt`` (``c_lego_db``);
- since session 38 fern's full method stops growing at half the run (``full.refine_stop_fraction: 0.5`` in llff.yaml:
  ``t_r_fern_full`` in ``s37/t.txt``, seed 0, and ``l_fern_full_rs05`` in ``s38/l.txt``, seeds 1-2) and lego's weighs
  its pseudo views x 0.2 (``full.pseudo_weight: 0.2`` in blender.yaml: ``l_lego_full_pw02`` in ``s38/l.txt``);
- the captures at 384x256, 3000 it: the baselines of ``s36/b_all.txt`` (``b_<scene>_<N>v_baseline_db``), the full
  method since session 37 with ``full.pseudo_weight: 0.2`` (``s37/t.txt``, ``t_p_<scene>_<N>v_full``);
- the captures at 768x512, 10,000 it, seeds 0-2: ``s38/i.txt`` (the baseline's seed 0: ``s36/g.txt``;
  ``captures_table.session38_images4``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import captures_table as ct  # noqa: E402
import seed_medians as sm  # noqa: E402

START, END = "<!-- readme_results: start -->", "<!-- readme_results: end -->"

NOARG = "noarg_cpu/seeds_s37.json"  # the no-argument job over seeds 0-2 (bench/noarg_seeds.py)

HEAD = ["scene", "setting", "machine", "baseline", "full", "full - baseline", "source"]


def _cell(seeds: dict) -> str:
    n = len(seeds)
    return ct.cell(seeds) + ("" if n >= 3 else f" ({n} seed{'s' if n > 1 else ''})")


def _row(scene: str, setting: str, machine: str, base: dict, full: dict, source: str) -> str:
    gain = (f"{statistics.median(full.values()) - statistics.median(base.values()):+.2f}"
            if base and full else "-")
    return "| " + " | ".join([scene, setting, machine, _cell(base) if base else "-", _cell(full) if full else "-",
                              gain, source]) + " |"


def _psnrs(path: Path) -> dict[str, dict[int, float]]:
    """{run name without its seed: {seed: test PSNR}} of a summary file (``seed_medians.read``)."""
    return {name: {s: p for s, (p, _) in seeds.items()} for name, seeds in sm.read([path]).items()}


def rows(results: Path) -> list[str]:
    out = ["| " + " | ".join(HEAD) + " |", "|" + "---|" * len(HEAD)]
    doc = json.loads((results / NOARG).read_text())
    noarg = doc["per_seed"]
    out.append(_row("synthetic room, 3 views", "no arguments: 128x96, 1000 it", doc["machine"],
                    {int(s): v["baseline"]["psnr"] for s, v in noarg.items()},
                    {int(s): v["full"]["psnr"] for s, v in noarg.items()}, f"`{NOARG}`"))
    for scene, label, setting in (("fern", "LLFF fern, 3 views", "504x378, 3000 it"),
                                  ("dtu", "DTU scan65, 3 views (masked)", "400x300, 3000 it"),
                                  ("lego", "Blender lego, 8 views", "400x400, 10,000 it")):
        base, full = (ct.named_default(results, scene, m) for m in ("baseline", "full"))
        files = dict.fromkeys(f for m in ("baseline", "full") for f, _ in ct.NAMED_DEFAULTS[(scene, m)])
        out.append(_row(label, setting, "H200", {k: p for k, (p, _) in base.items()},
                        {k: p for k, (p, _) in full.items()}, ", ".join(f"`{f}`" for f in files)))
    out.append(_row("Blender lego, 8 views", "best setting: + opacity noise 0.8, SH degree 1, "
                    "`optim.means_lr_final=3.2e-5`, 10,000 it", "H200",
                    _psnrs(results / "s36" / "c.txt").get("c_lego_db", {}), {}, "`s36/c.txt`"))
    for runs, setting, source in (
            (ct.session37_default(results), "384x256, 3000 it", "`s36/b_all.txt`, `s37/t.txt`"),
            (ct.session38_images4(results), "768x512 (images_4), 10,000 it", "`s36/g.txt`, `s38/i.txt`")):
        for scene, views in sorted({(s, n) for (s, n, _) in runs}):
            out.append(_row(f"{scene}, {views} views", setting, "H200", runs.get((scene, views, "baseline"), {}),
                            runs.get((scene, views, "full"), {}), source))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path(__file__).resolve().parent / "results")
    ap.add_argument("--write", type=Path, default=None, help=f"replace the table between {START} and {END} here")
    args = ap.parse_args(argv)
    table = "\n".join(rows(args.results))
    if args.write is None:
        print(table)
        return 0
    from switch_table import replace_between_markers  # (it imports warpgs, and so torch: only here)

    try:
        args.write.write_text(replace_between_markers(args.write.read_text(), table, START, END))
    except ValueError as e:
        ap.error(f"{args.write}: {e}")
    print(f"wrote the table into {args.write}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
