"""Picks the capture settings from an exploration batch (bench/gpu_session6.sh phase x) by a rule fixed before
the runs: the full method's variant whose worst case against the baseline is >= -0.2 dB with the best mean gain
(the best mean when none is).

    python bench/select_variant.py RUNS_DIR            # prints the variant's --set flags; writes choice.json

Run names: <case>_b (baseline), <case>_<variant> (full); VARIANTS gives each variant's flags.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

CASES = ("c3", "c9", "h3", "h9")
NL = ["full.restart_lr=false"]
STRICT = ["full.densify_config.stereo.min_score=0.8", "full.densify_config.stereo.min_consistent=2"]
VARIANTS = {  # name: flags (each compared with the baseline run <case>_b)
    "f_nl": NL,
    "f_nl_rel": NL + ["full.pseudo_mask=reliable"],
    "f_nl_gb": NL + ["full.growth_budget=1.5"],
    "f_nl_nd": NL + ["full.densify=false"],
    "f_nl_strict": NL + STRICT,
    "f_nl_nodepth": NL + ["full.input_depth_weight=0", "full.depth_weight=0"],
    "f_combo": NL + ["full.pseudo_mask=reliable", "full.growth_budget=1.5"] + STRICT,
}


def psnr(runs: Path, name: str) -> float | None:
    p = runs / name / "metrics.json"
    return json.loads(p.read_text()).get("psnr") if p.is_file() else None


def select(runs: Path) -> dict:
    table = {c: {v: psnr(runs, f"{c}_{v}") for v in ["b", *VARIANTS]} for c in CASES}
    scores = {}
    for v in VARIANTS:
        d = [t[v] - t["b"] for t in table.values() if t[v] is not None and t["b"] is not None]
        if len(d) == len(CASES):
            scores[v] = {"mean": sum(d) / len(d), "worst": min(d), "deltas": d}
    ok = [v for v, s in scores.items() if s["worst"] >= -0.2]
    pool = ok or list(scores)
    best = max(pool, key=lambda v: scores[v]["mean"]) if pool else "f_nl"
    return {"table": table, "scores": scores, "full_variant": best, "full_flags": VARIANTS[best]}


if __name__ == "__main__":
    runs = Path(sys.argv[1])
    choice = select(runs)
    (runs / "choice.json").write_text(json.dumps(choice, indent=2))
    print(json.dumps(choice, indent=1), file=sys.stderr)
    print(" ".join(f"--set {f}" for f in choice["full_flags"]))
