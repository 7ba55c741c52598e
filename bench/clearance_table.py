"""The README's path-clearance table: session 14's runs on the captures against the earlier defaults.

    python bench/clearance_table.py                       # the committed records (defaults below)
    python bench/clearance_table.py --runs RUNS.json --suite RESULTS.json
    python bench/clearance_table.py --variants            # session 15's variants against the default

Prints markdown: one row per capture and view count (castle_p30, herz_jesus_p25 at 3, 6, 9 views; images_8,
3000 iterations), each PSNR cell the median [min, max] over the seeds present (``-`` with none), for
  - plain baseline, session-13 baseline and session-13 full: the suite's labels ``baseline`` (3D-GS, no
    dropout), ``baseline+drop`` and ``full`` (bench/results/suite_cuda_switches/results.json, runs with
    no metrics skipped);
  - baseline and full with ``train.path_clearance 0.2`` (session 14's group ``pc``) and with path clearance
    and far field, the new default for captures (group ``pcff``), from
    bench/results/real_captures/session14_runs.json (bench/gpu_session14.sh; run names
    ``<group>_<case>_<method>_s<seed>``, case ``castle3`` .. ``herz9``, method ``base`` or ``full``; the
    file's other groups (d, ab, pc0.1, pc0.2) are other experiments and are left out);
then the default's gain (median of the full method's runs minus the baseline's) and its per-seed gains
(seeds 0, 1, 2 run by both). Below it: the mean and the worst over the cases of five differences of
medians, and the "collapses" of each column, its runs more than 2 dB below their own case's median.
Nothing in it is typed by hand.

``--variants``: sessions 15 and 16's runs (bench/results/real_captures/session15_runs.json, bench/gpu_session15.sh a,
c, d; session16_runs.json, bench/gpu_session16.sh v; same setting, over the session-14 defaults) beside the
default's two columns: view clearance for both methods, and eight changes of the full method (VARIANTS). Below it, each variant's mean and worst difference of
medians against the default baseline (what issue 13 asks of the full method: mean >= +0.5, none below -0.2)
and against its own method's default.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.real_captures_table import _cell as median_range  # noqa: E402
DEFAULT_RUNS = ROOT / "bench" / "results" / "real_captures" / "session14_runs.json"
DEFAULT_SUITE = ROOT / "bench" / "results" / "suite_cuda_switches" / "results.json"

SCENES = {"castle": "castle_p30", "herz": "herz_jesus_p25"}
CASES = [f"{scene}_{v}v" for scene in SCENES.values() for v in (3, 6, 9)]  # the table's rows, in order
GROUPS = ("pc", "pcff")  # session 14: path clearance 0.2; path clearance 0.2 + far field (the default)
METHODS = ("base", "full")
LABELS = ("baseline", "baseline+drop", "full", "full+far_field")  # the suite's labels read
COLLAPSE_DB = 2.0  # a run this far below its case's median (same column) is a collapse

# (column header, config key): config keys are the suite's labels and session 14's ``<group>_<method>``
COLUMNS = [("plain baseline", "baseline"), ("session-13 baseline", "baseline+drop"), ("session-13 full", "full"),
           ("baseline (clearance)", "pc_base"), ("full (clearance)", "pc_full"),
           ("baseline (default: far field + clearance)", "pcff_base"), ("full (default)", "pcff_full")]
# (what, minuend, subtrahend): the differences of medians summarised below the table
DIFFS = [("default full - default baseline", "pcff_full", "pcff_base"),
         ("full (clearance) - baseline (clearance)", "pc_full", "pc_base"),
         ("default full - session-13 baseline", "pcff_full", "baseline+drop"),
         ("default baseline - session-13 baseline", "pcff_base", "baseline+drop"),
         ("session-13 full - session-13 baseline", "full", "baseline+drop")]

_CASE = re.compile(r"^([a-z]+?)(\d+)$")  # castle3, herz9
_SEED = re.compile(r"^s(\d+)$")


def _parse_name(name: str) -> tuple[str, str, str, int] | None:
    """(group, case, method, seed) of ``<group>_<case>_<method>_s<seed>``, split from the right (groups may
    hold dots, pc0.1, and underscores); None for a name not of that form."""
    parts = name.split("_")
    if len(parts) < 4 or not _SEED.match(parts[-1]):
        return None
    return "_".join(parts[:-3]), parts[-3], parts[-2], int(parts[-1][1:])


def load_groups(path, groups) -> dict:
    """{<group>_<method>: {case: {seed: (run name, psnr)}}} of the runs of ``groups`` in a runs file."""
    runs = json.loads(Path(path).read_text())["runs"]
    out: dict = {}
    for name, rec in runs.items():
        parsed = _parse_name(name)
        if parsed is None:
            continue
        group, case, method, seed = parsed
        m = _CASE.match(case)
        if group not in groups or method not in METHODS or not m or m.group(1) not in SCENES:
            continue
        if not isinstance(rec, dict) or rec.get("psnr") is None:
            continue
        out.setdefault(f"{group}_{method}", {}).setdefault(f"{SCENES[m.group(1)]}_{m.group(2)}v", {})[seed] = \
            (name, float(rec["psnr"]))
    return out


def load_session14(path) -> dict:
    """{config: {case: {seed: (run name, psnr)}}} of session 14's groups ``pc`` and ``pcff`` (config
    ``<group>_<method>``, case as the suite names it: ``castle_p30_3v``); other runs are left out."""
    return load_groups(path, GROUPS)


def load_suite(path) -> dict:
    """{label: {case: {seed: (run name, psnr)}}} of the suite's runs with metrics, for the labels in LABELS
    and the cases in CASES."""
    records = json.loads(Path(path).read_text())["records"]
    out: dict = {}
    for r in records:
        run, metrics = r.get("run") or {}, r.get("metrics")
        label, case = run.get("label"), run.get("case")
        if label not in LABELS or case not in CASES or not metrics or metrics.get("psnr") is None:
            continue
        seed = int(run.get("seed", 0))
        name = run.get("name") or f"{label}/{case}/s{seed}"
        out.setdefault(label, {}).setdefault(case, {})[seed] = (name, float(metrics["psnr"]))
    return out


def _psnrs(configs: dict, key: str, case: str) -> dict:
    """{seed: psnr} of one column and case ({} when not run)."""
    return {s: p for s, (_, p) in configs.get(key, {}).get(case, {}).items()}


def _cell(xs) -> str:
    """median [min, max] of ``xs`` (the captures table's cell), ``-`` when empty."""
    return median_range(xs) if xs else "-"


def _median_diff(configs: dict, a: str, b: str, case: str) -> float | None:
    pa, pb = _psnrs(configs, a, case), _psnrs(configs, b, case)
    if not pa or not pb:
        return None
    return statistics.median(pa.values()) - statistics.median(pb.values())


def _case_label(case: str) -> tuple[str, str]:
    scene, views = case.rsplit("_", 1)
    return scene, views.rstrip("v")


def table(session14: dict, suite: dict) -> str:
    """The markdown table and the summary bullets below it, from ``load_session14`` and ``load_suite``."""
    configs = {**suite, **session14}
    lines = ["| scene | views | " + " | ".join(h for h, _ in COLUMNS)
             + " | full - baseline (default) | per-seed gains |",
             "|---|---|" + "---|" * len(COLUMNS) + "---|---|"]
    for case in CASES:
        scene, views = _case_label(case)
        cells = [_cell(list(_psnrs(configs, key, case).values())) for _, key in COLUMNS]
        gain = _median_diff(configs, "pcff_full", "pcff_base", case)
        b, f = _psnrs(configs, "pcff_base", case), _psnrs(configs, "pcff_full", case)
        per = ", ".join(f"{f[s] - b[s]:+.2f}" for s in (0, 1, 2) if s in b and s in f) or "-"
        lines.append(f"| {scene} | {views} | " + " | ".join(cells)
                     + f" | {'-' if gain is None else f'{gain:+.2f}'} | {per} |")
    lines.append("")
    for what, a, b in DIFFS:
        d = [x for x in (_median_diff(configs, a, b, c) for c in CASES) if x is not None]
        if d:
            lines.append(f"- {what} (medians): mean {sum(d) / len(d):+.2f} dB, worst {min(d):+.2f} dB "
                         f"over {len(d)} of {len(CASES)} cases")
        else:
            lines.append(f"- {what} (medians): no case with both")
    for header, key in COLUMNS:
        low, n = [], 0
        for case in CASES:
            runs = configs.get(key, {}).get(case, {})
            if not runs:
                continue
            n += len(runs)
            med = statistics.median(p for _, p in runs.values())
            low += [f"{name} ({p:.2f} vs median {med:.2f})" for s, (name, p) in sorted(runs.items())
                    if p < med - COLLAPSE_DB]
        lines.append(f"- collapses (more than {COLLAPSE_DB:g} dB below the case's median), {header}: "
                     f"{len(low)} of {n} runs" + (": " + ", ".join(low) if low else ""))
    return "\n".join(lines)


SESSION15_RUNS = DEFAULT_RUNS.parent / "session15_runs.json"
# (column header, session 15's <group>_<method>, the default it changes): bench/gpu_session15.sh
VARIANTS = [("baseline + view clearance 0.5", "vc_base", "pcff_base"),
            ("full + view clearance 0.5", "vc_full", "pcff_full"),
            ("full, early input depth", "ed_full", "pcff_full"),
            ("full, no depth terms", "nd_full", "pcff_full"),
            ("full, no input depth term", "ni_full", "pcff_full"),
            ("full, pseudo weight 2", "pw_full", "pcff_full"),
            ("full, pseudo views from step 750", "bf_full", "pcff_full"),
            ("full, unguided pseudo views (session 16)", "rg_full", "pcff_full"),
            ("full, delta 0.25 (session 16)", "d25_full", "pcff_full"),
            ("full without pseudo views or densification (session 16)", "np_full", "pcff_full")]
SESSION16_RUNS = DEFAULT_RUNS.parent / "session16_runs.json"


def variants_table(session14=DEFAULT_RUNS, session15=SESSION15_RUNS, session16=SESSION16_RUNS) -> str:
    """Sessions 15 and 16's variants (VARIANTS) beside the session-14 default, and their mean / worst differences
    of medians against the default baseline and against their method's default."""
    groups = {k.split("_")[0] for _, k, _ in VARIANTS}
    configs = {**load_session14(session14), **load_groups(session15, groups), **load_groups(session16, groups)}
    cols = [("default baseline", "pcff_base"), ("default full", "pcff_full")] + [(h, k) for h, k, _ in VARIANTS]
    lines = ["| scene | views | " + " | ".join(h for h, _ in cols) + " |", "|---|---|" + "---|" * len(cols)]
    for case in CASES:
        scene, views = _case_label(case)
        lines.append(f"| {scene} | {views} | "
                     + " | ".join(_cell(list(_psnrs(configs, k, case).values())) for _, k in cols) + " |")
    lines.append("")
    for header, key in cols[1:]:
        ref = next((r for _, k, r in VARIANTS if k == key), "pcff_full")
        parts = []
        against = [("vs the default baseline", "pcff_base")]
        if ref not in ("pcff_base", key):
            against.append(("vs the default full", ref))
        for what, other in against:
            d = [x for x in (_median_diff(configs, key, other, c) for c in CASES) if x is not None]
            if d:
                parts.append(f"{what}: mean {sum(d) / len(d):+.2f} dB, worst {min(d):+.2f} dB ({len(d)} cases)")
        lines.append(f"- {header}: " + ("; ".join(parts) if parts else "no case with both"))
    return "\n".join(lines)


SESSION7_SEED0 = (DEFAULT_RUNS.parent / "session7_runs.json", DEFAULT_RUNS.parent / "session6_runs_y.json")


def i4_table(path=DEFAULT_RUNS, session7=SESSION7_SEED0) -> str:
    """The images_4 (768x512), 10,000-iteration runs of seed 0: the session-14 default (``i4_<case>_<method>_s0``)
    and with ``train.view_clearance`` 0.5 (``vc_i4_...``), beside session 7's seed 0 (its baseline's seed 0 is
    session 6's ``<c>_baseline_i4`` run). Per run: PSNR, the four test views' PSNRs, Gaussians, training s."""
    runs = json.loads(Path(path).read_text())["runs"]
    old = {}
    for f in session7:
        if Path(f).is_file():
            for k, v in json.loads(Path(f).read_text()).items():
                old.setdefault(k, (v.get(".") or {}).get("psnr"))
    lines = ["| scene | views | method | session 7 (seed 0) | default (far field + path clearance) | per test view | "
             "Gaussians | training s | + view clearance 0.5 | per test view |", "|---|---|---|---|---|---|---|---|---|---|"]
    for scene in ("castle", "herz"):
        for v in (3, 6, 9):
            for m in ("baseline", "full"):
                r = runs.get(f"i4_{scene}{v}_{m}_s0")
                if r is None:
                    continue
                vc = runs.get(f"vc_i4_{scene}{v}_{m}_s0")
                o = old.get(f"{scene[0]}{v}_{m}_i4_s0") or old.get(f"{scene[0]}{v}_{m}_i4")
                views = lambda x: ", ".join(f"{t['psnr']:.2f}" for t in x["test_views"])
                lines.append(f"| {SCENES.get(scene, scene)} | {v} | {m} | {'-' if o is None else f'{o:.2f}'} | "
                             f"{r['psnr']:.2f} | {views(r)} | {r['num_gaussians']} | {r['train_time_s']:.0f} | "
                             f"{'-' if vc is None else format(vc['psnr'], '.2f')} | {'-' if vc is None else views(vc)} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=Path, default=DEFAULT_RUNS, help="session 14's run records (gather_runs.py)")
    ap.add_argument("--suite", type=Path, default=DEFAULT_SUITE, help="the switches suite's results.json")
    ap.add_argument("--i4", action="store_true", help="the images_4, 10,000-iteration table of seed 0 instead")
    ap.add_argument("--variants", action="store_true", help="session 15's variants against the default instead")
    ap.add_argument("--session15", type=Path, default=SESSION15_RUNS, help="session 15's run records")
    args = ap.parse_args(argv)
    if args.variants:
        print(variants_table(args.runs, args.session15))
    else:
        print(i4_table(args.runs) if args.i4 else table(load_session14(args.runs), load_suite(args.suite)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
