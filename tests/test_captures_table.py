"""bench/captures_table.py: medians, spreads, gains and collapses from run summaries."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import captures_table as ct  # noqa: E402


def test_table_takes_medians_per_case_and_the_full_methods_gain(tmp_path):
    lines = []
    for seed, (b, f) in enumerate([(20.0, 21.0), (22.0, 21.5), (21.0, 17.0)]):
        lines.append(f"d_castle_p30_9v_baseline_s{seed} {b} 100 [1.0] [2.0]")
        lines.append(f"d_castle_p30_9v_full_s{seed} {f} 100 [1.0] [2.0]")
    lines.append("d_castle_p30_9v_full_s9_r10 99.0 1")  # another prefix's ratio: not this column's
    p = tmp_path / "runs.txt"
    p.write_text("\n".join(lines) + "\n")
    runs = ct.load(p, "d")
    assert runs[("castle_p30", 9, "baseline")] == {0: 20.0, 1: 22.0, 2: 21.0}
    assert runs[("castle_p30", 9, "full")] == {0: 21.0, 1: 21.5, 2: 17.0}
    out = "\n".join(ct.table([("x", runs)]))
    assert "| castle_p30 | 9 | 21.00 [20.00, 22.00] | 21.00 [17.00, 21.50] | +0.00 |" in out
    assert "mean +0.00 dB, worst +0.00 dB over 1 cases" in out
    assert "collapses (more than 2 dB below the column's median): 1" in out
    assert "x castle_p30 9v full seed 2: 17.00 (median 21.00)" in out


def test_merged_joins_cases_and_seeds_from_several_files():
    a = {("castle_p30", 3, "baseline"): {0: 14.0}}
    b = {("castle_p30", 3, "baseline"): {1: 15.0}, ("castle_p30", 6, "full"): {0: 19.0}}
    m = ct.merged(a, b)
    assert m == {("castle_p30", 3, "baseline"): {0: 14.0, 1: 15.0}, ("castle_p30", 6, "full"): {0: 19.0}}
    assert a == {("castle_p30", 3, "baseline"): {0: 14.0}}  # the inputs stay as they were
