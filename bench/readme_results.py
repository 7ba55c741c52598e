"""The README's table of current figures, generated from the committed run summaries (not typed by hand).

    python bench/readme_results.py [--results bench/results] [--write README.md]

``--write``: put the table between the file's ``<!-- readme_results: start -->`` and ``<!-- readme_results: end -->``.

One row per scene and setting: the baseline's and the full method's test PSNR as median [min, max] over seeds 0-2,
the full method's gain (difference of the medians), and where the runs ran. The sources are the latest runs of the
current defaults:
- the no-argument job (synthetic room, 2-core CPU): ``noarg_cpu/seeds_s30.json``;
- fern 3 views, DTU scan65 3 views and lego 8 views (H200, session 31): ``s31/o.txt`` (``o_<scene>_<method>_s<seed>``);
  since session 35 fern's and DTU's baselines stop growing at half the run (``strategy.refine_stop_fraction``):
  ``s35/r.txt`` (``r_<scene>_baseline``),
  and lego's best baseline setting (``o_lego_best``, ``o_lego_best20k``) as rows of their own, and (session 32)
  that setting with the position learning rate decaying to 1.6e-5 (``s32/M.txt`` ``M_lrf``, ``s32/N.txt``
  ``N_lrf20k``) and (session 33) to 3.2e-5 (``s33/a.txt`` ``a_lrf32e6``; session 34 at 15,000 it: ``s34/l_call2.txt``
  ``l_lrf32e6_15k``);
- the captures at 384x256, 3000 it (H100, session 28's runs of today's default: ``s28/c369.txt`` baselines,
  ``s28/m369.txt`` full; the baselines at 6 and 9 views, which stop growing at half the run since session 35, H200:
  ``s35/r.txt``);
- the captures at 768x512, 10,000 it (seed 0 H100, ``s28/i369.txt``; seeds 1-2 H200, ``s31/k369.txt``, and the five
  runs session 31 did not finish in ``s32/k369.txt`` once it exists: bench/gpu_session32.sh k; the baselines at 6
  and 9 views since session 35, H200: ``s35/c69.txt``).
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
    noarg = json.loads((results / "noarg_cpu" / "seeds_s30.json").read_text())["per_seed"]
    out.append(_row("synthetic room, 3 views", "no arguments: 128x96, 1000 it", "2-core AMD EPYC CPU",
                    {int(s): v["baseline"]["psnr"] for s, v in noarg.items()},
                    {int(s): v["full"]["psnr"] for s, v in noarg.items()}, "`noarg_cpu/seeds_s30.json`"))
    o = _psnrs(results / "s31" / "o.txt")
    r = _psnrs(results / "s35" / "r.txt")  # session 35: LLFF's and DTU's baselines stop growing at half the run
    for scene, key, setting in (("LLFF fern, 3 views", "fern", "504x378, 3000 it"),
                                ("DTU scan65, 3 views (masked)", "dtu", "400x300, 3000 it")):
        out.append(_row(scene, setting, "H200", r.get(f"r_{key}_baseline", {}), o.get(f"o_{key}_full", {}),
                        "`s35/r.txt` (baseline), `s31/o.txt` (full)"))
    out.append(_row("Blender lego, 8 views", "400x400, 10,000 it", "H200", o.get("o_lego_baseline", {}),
                    o.get("o_lego_full", {}), "`s31/o.txt`"))
    for key, setting in (("o_lego_best", "10,000 it"), ("o_lego_best20k", "20,000 it")):
        out.append(_row("Blender lego, 8 views", f"baseline + opacity noise 0.8, SH degree 1, {setting}", "H200",
                        o.get(key, {}), {}, "`s31/o.txt`"))
    for name, key, lrf, setting in (("s32/M.txt", "M_lrf", "1.6e-5", "10,000 it"),
                                    ("s32/N.txt", "N_lrf20k", "1.6e-5", "20,000 it"),
                                    ("s33/a.txt", "a_lrf32e6", "3.2e-5", "10,000 it"),
                                    ("s34/l_call2.txt", "l_lrf32e6_15k", "3.2e-5", "15,000 it")):
        path = results / name
        if path.is_file():  # sessions 32-34: that setting with the position learning rate decaying to lrf
            times = f"{float(lrf) / 1.6e-6:.0f}x"  # the default final rate is 1.6e-6
            out.append(_row("Blender lego, 8 views", f"that + `optim.means_lr_final={lrf}` ({times}), {setting}",
                            "H200", _psnrs(path).get(key, {}), {}, f"`{name}`"))
    large_source = ", ".join(f"`{p.parent.name}/{p.name}`" for p in ct.images4_default_files(results))
    # since session 35 the baselines at 6 and 9 views stop growing at half the run (H200 runs of their own); the 3-view
    # baselines (held stereo geometry: no growth either way) and the full method (which keeps growing) stay as they were
    for default, new_base, setting, machine, source, new_source in (
            (ct.session28_default(results), ct.load(results / "s35" / "r.txt", "r"), "384x256, 3000 it", "H100",
             "`s28/c369.txt`, `s28/m369.txt`", "`s35/r.txt` (baseline), `s28/m369.txt` (full)"),
            (ct.images4_default(results), ct.load(results / "s35" / "c69.txt", "c"), "768x512 (images_4), 10,000 it",
             "seed 0 H100, seeds 1-2 H200", large_source, "`s35/c69.txt` (baseline), " + large_source + " (full)")):
        runs = ct.with_baselines(default, new_base)
        for scene, views in sorted({(s, n) for (s, n, _) in runs}):
            new = (scene, views, "baseline") in new_base  # a baseline of session 35's default (H200)
            out.append(_row(f"{scene}, {views} views", setting, "baseline H200, full " + machine if new else machine,
                            runs.get((scene, views, "baseline"), {}), runs.get((scene, views, "full"), {}),
                            new_source if new else source))
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
