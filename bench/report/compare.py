"""A variant against the default, run by run: median [min, max] over seeds of each, and the difference.

    python bench/report/compare.py outputs/sweeps/switches --variant drop0 --variant no-binocular
    python bench/report/compare.py DEFAULT_BATCH VARIANT_BATCH --variant pw02 --metric psnr --metric num_gaussians \\
        --json compare.json --md compare.md

Runs are matched by name. A default run is named ``<key>_s<seed>`` (the batch runner's
``<scene>_<views>v_<method>_s<seed>``); the same run of variant ``V`` is ``<key>_s<seed>_V`` (what a sweep's
``variants`` entry, or ``python -m warpgs.pipelines.batch --variant V``, names it). One row per key and variant:
the default's median [min, max] over its seeds, the variant's over its seeds, the difference of the medians
(variant - default), and the seeds each has.

A SOURCE is a batch folder (``runs/<name>/metrics.json``), a folder of run folders (``<name>/metrics.json``), a
batch's ``results.json``, or a committed summary (``{"runs": {name: metrics}}``, bench/results/quality/*.json).
The runs of every source are pooled; a name found twice with other metrics is an error.

Prints markdown; ``--md`` and ``--json`` write the table and its numbers to files.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from pathlib import Path

SEEDED = re.compile(r"^(?P<key>.+)_s(?P<seed>\d+)$")  # a default run's name: <key>_s<seed>

# ----------------------------------------------------------------------------------------------
# reading runs


def _batch_results(doc: dict) -> dict[str, dict]:
    return {r["name"]: r["metrics"] for r in doc["runs"] if r.get("status") == "finished" and r.get("metrics")}


def read_runs(source: Path) -> dict[str, dict]:
    """{run name: its metrics} of one SOURCE (see the module's docstring)."""
    source = Path(source)
    if source.is_file():
        doc = json.loads(source.read_text())
        runs = doc.get("runs") if isinstance(doc, dict) else None
        if isinstance(runs, dict):
            return runs
        if isinstance(runs, list):
            return _batch_results(doc)
        raise ValueError(f"{source}: neither a batch's results.json nor a summary with a 'runs' mapping")
    if not source.is_dir():
        raise ValueError(f"{source}: no such file or folder")
    folder = source / "runs" if (source / "runs").is_dir() else source
    out = {}
    for m in sorted(folder.glob("*/metrics.json")):
        try:
            out[m.parent.name] = json.loads(m.read_text())
        except ValueError:
            continue  # a run writing it right now
    return out


def pool(sources: list[Path]) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for s in sources:
        for name, m in read_runs(s).items():
            if name in out and out[name] != m:
                raise ValueError(f"run {name} is in two sources with different metrics")
            out[name] = m
    return out


def split_name(name: str, variants: list[str]) -> tuple[str, int, str | None] | None:
    """``<key>_s<seed>[_<variant>]`` -> (key, seed, variant or None for the default); None for another name or
    a variant not in ``variants``."""
    for v in variants:
        if name.endswith("_" + v):
            m = SEEDED.match(name[: -len(v) - 1])
            if m:
                return m["key"], int(m["seed"]), v
    m = SEEDED.match(name)
    return (m["key"], int(m["seed"]), None) if m else None


def by_seed(runs: dict[str, dict], metric: str, variants: list[str] = ()) -> dict[tuple[str, str | None], dict[int, float]]:
    """{(key, variant or None): {seed: the run's ``metric``}} over the runs that have it as a number."""
    out: dict = {}
    for name, m in runs.items():
        parts = split_name(name, list(variants))
        v = m.get(metric) if isinstance(m, dict) else None
        if parts is None or not isinstance(v, (int, float)) or isinstance(v, bool):
            continue
        key, seed, variant = parts
        out.setdefault((key, variant), {})[seed] = float(v)
    return out


# ----------------------------------------------------------------------------------------------
# the numbers and their table


def spread(seeds: dict[int, float]) -> dict | None:
    if not seeds:
        return None
    v = list(seeds.values())
    return {"median": statistics.median(v), "min": min(v), "max": max(v), "seeds": sorted(seeds)}


def cell(s: dict | None, fmt: str = ".2f") -> str:
    """A spread as ``median [min, max]`` (the value alone for one seed; ``-`` for none)."""
    if s is None:
        return "-"
    if len(s["seeds"]) == 1:
        return format(s["median"], fmt)
    return f"{s['median']:{fmt}} [{s['min']:{fmt}}, {s['max']:{fmt}}]"


def seeds_text(seeds: list[int]) -> str:
    if not seeds:
        return "-"
    if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 2:
        return f"{seeds[0]}-{seeds[-1]}"
    return ",".join(map(str, seeds))


def compare(runs: dict[str, dict], variants: list[str], metric: str = "psnr") -> list[dict]:
    """One row per (key, variant) that either side has: ``default`` and ``variant`` spreads (None where that
    side has no run) and ``diff`` (median of the variant - median of the default; None unless both)."""
    groups = by_seed(runs, metric, variants)
    keys = sorted({k for k, _ in groups})
    rows = []
    for v in variants:
        for key in keys:
            d, x = spread(groups.get((key, None), {})), spread(groups.get((key, v), {}))
            if x is None:
                continue
            rows.append({"key": key, "variant": v, "metric": metric, "default": d, "variant_runs": x,
                         "diff": x["median"] - d["median"] if d else None})
    return rows


def markdown(rows: list[dict], fmt: str = ".2f") -> str:
    head = ["run", "variant", "metric", "default", "variant", "variant - default", "seeds (default / variant)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        d, x = r["default"], r["variant_runs"]
        diff = "-" if r["diff"] is None else f"{r['diff']:+{fmt}}"
        lines.append("| " + " | ".join([r["key"], r["variant"], r["metric"], cell(d, fmt), cell(x, fmt), diff,
                                        f"{seeds_text(d['seeds'] if d else [])} / {seeds_text(x['seeds'])}"]) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sources", nargs="+", type=Path, help="batch folders, run folders' parents, results JSON files")
    ap.add_argument("--variant", action="append", required=True, help="the variant's name suffix (repeatable)")
    ap.add_argument("--metric", action="append", default=None, help="metrics.json key (repeatable; default psnr)")
    ap.add_argument("--digits", type=int, default=2, help="decimals in the table (default 2)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows here")
    ap.add_argument("--md", type=Path, default=None, help="write the table here")
    a = ap.parse_args(argv)
    try:
        runs = pool(a.sources)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    rows = [r for metric in (a.metric or ["psnr"]) for r in compare(runs, a.variant, metric)]
    if not rows:
        print(f"error: no run of variant {', '.join(a.variant)} in {', '.join(map(str, a.sources))}", file=sys.stderr)
        return 2
    text = markdown(rows, f".{a.digits}f")
    print(text, end="")
    if a.md:
        a.md.write_text(text)
    if a.json:
        a.json.write_text(json.dumps({"sources": [str(s) for s in a.sources], "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
