"""The README's session-23 table, generated from the GPU runs' summaries in ``bench/results/s23`` (not typed by hand).

    python bench/session23_table.py [--results bench/results/s23]

Lines ``NAME PSNR GAUSSIANS [per-view PSNRs] [curve]`` as ``bench/gpu_session23.sh`` writes them (``lego.txt``: phase
l, ``lego_full_variants.txt``: v, ``depth_terms.txt``: d, ``depth_terms_e.txt``: e); runs named ``GROUP_sSEED``. One row
per group in ``GROUPS``'s order: what it is, the scene, the seeds, the median [min, max] test PSNR and the median
number of Gaussians.
"""

from __future__ import annotations

import argparse
import re
import statistics
from pathlib import Path

RUN = re.compile(r"^(?P<group>\w+)_s(?P<seed>\d+)$")
# group: (scene, method and setting); the full method's setting is what changes against the config of its dataset
# before session 23 (full.drop_rate 0, Pearson depth terms on inputs and pseudo views)
GROUPS = {
    "l_best": ("lego 8v", "baseline: DropGaussian 0.2, opacity noise 0.8, SH degree 1 (session 17's best)"),
    "l_alpha": ("lego 8v", "that + L1 on the inputs' alpha (loss.alpha_weight 0.5)"),
    "l_full": ("lego 8v", "full, the config before session 23"),
    "l_fullbest": ("lego 8v", "full + the best baseline's settings"),
    "v_nodens": ("lego 8v", "full, no densification (no stereo: no points, no depth priors)"),
    "v_nodepth": ("lego 8v", "full, no depth terms (the stereo's points still added)"),
    "v_budget": ("lego 8v", "full, growth budget 1.0"),
    "v_rel": ("lego 8v", "full, pseudo views on reliable pixels only"),
    "v_pw02": ("lego 8v", "full, pseudo-view weight 0.2 (the inputs' depth term unchanged)"),
    "d_lego_strict": ("lego 8v", "full, the captures' stricter stereo (NCC 0.8, 2 agreeing views)"),
    "d_lego_fullbest_nodepth": ("lego 8v", "full + the best baseline's settings, no depth terms"),
    "d_fern_nodepth": ("fern 3v", "full, no depth terms"),
    "e_fern_nodepth_drop": ("fern 3v", "full, no depth terms, DropGaussian 0.2 (the new default)"),
    "d_dtu_nodepth": ("DTU 65 3v", "full, no depth terms"),
    "d_dtu_strict": ("DTU 65 3v", "full, the captures' stricter stereo"),
    "e_dtu_nodepth_drop": ("DTU 65 3v", "full, no depth terms, DropGaussian 0.2 (the new default)"),
    "e_cap_nodepth_castle_p30_3v_full": ("castle_p30 3v", "full, no depth terms (captures' config otherwise)"),
    "e_cap_nodepth_castle_p30_6v_full": ("castle_p30 6v", "full, no depth terms (captures' config otherwise)"),
    "e_cap_nodepth_herz_jesus_p25_3v_full": ("herz_jesus_p25 3v", "full, no depth terms (captures' config otherwise)"),
}


def load(folder: Path) -> dict:
    """{group: {seed: (psnr, gaussians)}} over every ``*.txt`` of ``folder`` (a later file's run wins)."""
    runs: dict = {}
    for path in sorted(folder.glob("*.txt")):
        for line in path.read_text().splitlines():
            parts = line.split()
            m = RUN.match(parts[0]) if len(parts) >= 3 else None
            if m is None:
                continue
            runs.setdefault(m["group"], {})[int(m["seed"])] = (float(parts[1]), int(parts[2]))
    return runs


def table(runs: dict) -> list[str]:
    lines = ["| scene | setting | seeds | test PSNR | Gaussians |", "|---|---|---|---|---|"]
    for group, (scene, what) in GROUPS.items():
        seeds = runs.get(group)
        if not seeds:
            continue
        p = [v[0] for v in seeds.values()]
        n = statistics.median(v[1] for v in seeds.values())
        spread = f" [{min(p):.2f}, {max(p):.2f}]" if len(p) > 1 else ""
        lines.append(f"| {scene} | {what} | {', '.join(map(str, sorted(seeds)))} | {statistics.median(p):.2f}{spread} "
                     f"| {n:,.0f} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path(__file__).resolve().parent / "results" / "s23")
    args = ap.parse_args(argv)
    print("\n".join(table(load(args.results))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
