"""Issue 14's switch table from a suite's results.json, and its rule for which switch may become a default.

    python bench/switch_table.py                                   # bench/results/suite_cuda_switches/results.json
    python bench/switch_table.py RESULTS.json --out TABLE.md        # also write the markdown to a file
    python bench/switch_table.py --readme README.md                 # replace the README's table with it
    python bench/switch_table.py OLD.json --readme README.md --marker switch_table_h100_s12   # another table of it

The table (markdown, what the README quotes): one row per switch (run label), one column per scene (run
case), each cell the test PSNR's median over seeds with its [min, max]; then each switch's gain against
the default it would change, and the machine(s), date(s) and seeds of the runs. Nothing in it is typed by
hand: rerun this after the suite (``bench/suite.py --preset switches`` writes switches.md with it).

The default-selection rule (issue 14): a switch qualifies only if it raises the median over all scenes and
costs no scene more than 0.3 dB against the current default. Here, per scene, a switch's gain is the
median PSNR over seeds minus the default's (the default of a switch is the label named after its method:
``baseline`` for ``baseline+drop``, ``full`` for ``full+co_reg``); it qualifies when the median of its
gains over the scenes is above 0 and its smallest gain is at least -0.3 dB, with every scene the default
was measured on measured for it too (a failed or missing run leaves the switch unqualified, said so).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from warpgs.pipelines.batch_report import med_range, spread  # noqa: E402  (the batch runner's table's cells)

# the table of today's code (session 39, two H200s); sessions 11-13's (one H100, older code) is suite_cuda_switches
DEFAULT_RESULTS = ROOT / "bench" / "results" / "suite_cuda_h200_switches_s39" / "results.json"
MAX_LOSS_DB = 0.3  # the most a default may cost any scene


def seed_stats(records: list[dict]) -> dict:
    """{(scene, label): {"method", "seeds", "psnr", "train_time_s", "num_gaussians"}} of the finished runs,
    each metric a list over the seeds, in the records' order (scene: the run's case, else its metrics'
    scene)."""
    stats: dict = {}
    for r in records:
        if r.get("status") != "finished":
            continue
        run, m = r["run"], r["metrics"]
        st = stats.setdefault((run.get("case") or m["scene"], run["label"]),
                              {"method": run["method"], "seeds": [], "psnr": [], "train_time_s": [],
                               "num_gaussians": []})
        st["seeds"].append(run.get("seed"))
        for k in ("psnr", "train_time_s", "num_gaussians"):
            st[k].append(m[k])
    return stats


def cell(xs: list[float], fmt: str = ".2f") -> str:
    """median [min, max] of ``xs`` (the median alone for one value), as the batch runner's table writes it."""
    return med_range(spread(xs), fmt)


def _order(records: list[dict]):
    """Scenes and labels in the order the records first name them (the preset's), finished or not."""
    scenes, labels = {}, {}
    for r in records:
        run = r["run"]
        scene = run.get("case") or (r.get("metrics") or {}).get("scene") or run["data"]
        scenes.setdefault(scene, None)
        labels.setdefault(run["label"], run["method"])
    return list(scenes), labels


def select_defaults(records: list[dict], max_loss_db: float = MAX_LOSS_DB) -> list[dict]:
    """Issue 14's rule, per switch (every label but the defaults, which are the labels named after their
    method): its per-scene gains against the default (median PSNR over seeds minus the default's), their
    median and the worst, and whether it qualifies (median gain > 0, worst >= -``max_loss_db``, every scene
    of the default measured). One dict per switch, in the records' order."""
    stats = seed_stats(records)
    scenes, labels = _order(records)
    verdicts = []
    for label, method in labels.items():
        if label == method:
            continue
        base_scenes = [s for s in scenes if (s, method) in stats]
        gains = {s: statistics.median(stats[(s, label)]["psnr"]) - statistics.median(stats[(s, method)]["psnr"])
                 for s in base_scenes if (s, label) in stats}
        missing = [s for s in base_scenes if s not in gains]
        v = {"switch": label, "default": method, "gains_db": gains, "missing": missing,
             "median_gain_db": statistics.median(gains.values()) if gains else None,
             "worst_gain_db": min(gains.values()) if gains else None,
             "worst_scene": min(gains, key=gains.get) if gains else None}
        times = [statistics.median(stats[(s, label)]["train_time_s"]) / statistics.median(stats[(s, method)]["train_time_s"])
                 for s in gains if statistics.median(stats[(s, method)]["train_time_s"]) > 0]
        v["time_ratio"] = statistics.median(times) if times else None
        if not base_scenes:
            v["qualifies"], v["why"] = False, f"the default {method} has no finished run"
        elif missing:
            v["qualifies"], v["why"] = False, f"not measured on {', '.join(missing)}"
        elif v["median_gain_db"] <= 0:
            v["qualifies"], v["why"] = False, f"the median over the scenes does not rise ({v['median_gain_db']:+.2f} dB)"
        elif v["worst_gain_db"] < -max_loss_db:
            v["qualifies"], v["why"] = False, (f"{v['worst_scene']} loses {-v['worst_gain_db']:.2f} dB "
                                               f"(more than {max_loss_db:g})")
        else:
            v["qualifies"], v["why"] = True, (f"median {v['median_gain_db']:+.2f} dB over {len(gains)} scene{'s' * (len(gains) > 1)}, "
                                              f"worst {v['worst_gain_db']:+.2f} dB ({v['worst_scene']})")
        verdicts.append(v)
    return verdicts


def verdict_lines(records: list[dict]) -> list[str]:
    """One line per switch: whether it may become its method's default, and why."""
    return [f"{v['switch']}: {'qualifies as' if v['qualifies'] else 'does not qualify as'} the {v['default']} "
            f"default: {v['why']}" for v in select_defaults(records)]


def _machines(records: list[dict]) -> str:
    names = sorted({f"{r.get('machine') or '?'} ({r.get('device') or '?'})" for r in records
                    if r.get("status") == "finished"})
    return ", ".join(names) or "none"


def _dates(records: list[dict], info: dict) -> str:
    dates = sorted({(r.get("date") or info.get("date") or "?")[:10] for r in records if r.get("status") == "finished"})
    return dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}" if dates else info.get("date", "?")[:10]


def markdown(records: list[dict], info: dict | None = None) -> str:
    """The table: PSNR median [min, max] per switch (rows) and scene (columns), the gain against the default
    and the rule's verdict per switch, and where and when the runs were made."""
    info = info or {}
    stats = seed_stats(records)
    scenes, labels = _order(records)
    verdicts = {v["switch"]: v for v in select_defaults(records)}
    seeds = sorted({s for st in stats.values() for s in st["seeds"] if s is not None})
    its = {}
    for r in records:
        its.setdefault(r["run"].get("case") or r["run"]["data"], set()).add(r["run"]["iterations"])
    lines = [f"Test PSNR (dB), median [min, max] over seeds {', '.join(map(str, seeds)) or 'as configured'}; "
             f"{_machines(records)}; {_dates(records, info)}. Iterations: "
             + ", ".join(f"{s} {'/'.join(map(str, sorted(its.get(s, []))))}" for s in scenes) + ".", "",
             "| switch | " + " | ".join(scenes) + " | median gain (dB) | worst scene (dB) | time vs default | default? |",
             "|---|" + "---|" * (len(scenes) + 4)]
    for label in labels:
        cells = [cell(stats[(s, label)]["psnr"]) if (s, label) in stats else "failed" if any(
            r["run"]["label"] == label and (r["run"].get("case") or r["run"]["data"]) == s for r in records)
            else "-" for s in scenes]
        v = verdicts.get(label)
        if v is None:
            tail = ["(default)", "", "", ""]
        else:
            tail = ["-" if v["median_gain_db"] is None else f"{v['median_gain_db']:+.2f}",
                    "-" if v["worst_gain_db"] is None else f"{v['worst_gain_db']:+.2f} ({v['worst_scene']})",
                    "-" if v["time_ratio"] is None else f"{v['time_ratio']:.2f}x",
                    "yes" if v["qualifies"] else "no"]
        lines.append(f"| {label} | " + " | ".join(cells + tail) + " |")
    lines += ["", f"Rule (issue 14): a switch may become its method's default only if the median of its per-scene "
                  f"gains is above 0 and no scene loses more than {MAX_LOSS_DB:g} dB.", ""]
    lines += [f"- {line}" for line in verdict_lines(records)]
    failed = [r for r in records if r.get("status") != "finished"]
    if failed:
        lines += ["", f"{len(failed)} runs did not finish (`failed` above); the first: `{failed[0]['run']['name']}`: "
                      + ((failed[0].get('log_tail') or '').strip().splitlines() or ['no log'])[-1]]
    return "\n".join(lines) + "\n"


def write(records: list[dict], info: dict, out: Path) -> list[Path]:
    """switches.md (``markdown``) and switches.json (per-scene statistics and the verdicts) in ``out``."""
    md = out / "switches.md"
    md.write_text("# Weight-free switches (issue 14)\n\n" + markdown(records, info))
    js = out / "switches.json"
    stats = {f"{scene}|{label}": st for (scene, label), st in seed_stats(records).items()}
    js.write_text(json.dumps({"info": info, "stats": stats, "verdicts": select_defaults(records)}, indent=1))
    return [md, js]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", nargs="?", type=Path, default=DEFAULT_RESULTS, help="a suite's results.json")
    ap.add_argument("--out", type=Path, default=None, help="also write the table to this file")
    ap.add_argument("--readme", type=Path, default=None,
                    help=f"replace the text between {README_START!r} and {README_END!r} in this file with the table")
    ap.add_argument("--marker", default=MARKER,
                    help="the markers' name, for a README holding several tables: <!-- NAME: start --> ... "
                         "<!-- NAME: end --> (default %(default)s)")
    a = ap.parse_args(argv)
    try:
        data = json.loads(a.results.read_text())
        records, info = data["records"], data.get("info", {})
    except (OSError, ValueError, KeyError, TypeError) as e:
        print(f"error: {a.results}: not a suite's results.json ({type(e).__name__}: {e})", file=sys.stderr)
        return 2
    text = markdown(records, info)
    if a.out:
        a.out.write_text(text)
    if a.readme:
        try:
            a.readme.write_text(replace_between_markers(a.readme.read_text(), text, *markers(a.marker)))
        except (OSError, ValueError) as e:
            print(f"error: {a.readme}: {e}", file=sys.stderr)
            return 2
    print(text, end="")
    return 0


MARKER = "switch_table"


def markers(name: str = MARKER) -> tuple[str, str]:
    """The README's start and end markers of the table named ``name``."""
    return f"<!-- {name}: start -->", f"<!-- {name}: end -->"


README_START, README_END = markers()


def replace_between_markers(doc: str, table: str, start: str = README_START, end: str = README_END) -> str:
    """``doc`` with the text between the markers ``start`` and ``end`` (kept; the switch table's by default)
    replaced by ``table``; a ValueError when the markers are missing or out of order."""
    i, j = doc.find(start), doc.find(end)
    if i < 0 or j < i:
        raise ValueError(f"no {start} ... {end} pair to put the table between")
    return doc[:i + len(start)] + "\n" + table.rstrip("\n") + "\n" + doc[j:]


if __name__ == "__main__":
    sys.exit(main())
