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


def test_variant_table_gives_each_variants_full_median_and_gain_over_the_default_baseline(tmp_path):
    p = tmp_path / "variants.txt"
    p.write_text("# a comment line\n"
                 "w_pw02_castle_p30_3v_full_s0 14.0 10 [1.0] [2.0]\n"
                 "w_pw02_castle_p30_3v_full_s1 15.0 10 [1.0] [2.0]\n"
                 "w_pw02_castle_p30_3v_full_s2 14.5 10 [1.0] [2.0]\n"
                 "w_rel_herz_jesus_p25_9v_full_s0 22.0 10 [1.0] [2.0]\n"
                 "x_rel_herz_jesus_p25_9v_full_s1 99.0 10\n")  # another prefix
    variants = ct.load_variants(p, "w")
    assert variants == {"pw02": {("castle_p30", 3, "full"): {0: 14.0, 1: 15.0, 2: 14.5}},
                        "rel": {("herz_jesus_p25", 9, "full"): {0: 22.0}}}
    default = {("castle_p30", 3, "baseline"): {0: 14.0, 1: 14.2}, ("castle_p30", 3, "full"): {0: 13.9},
               ("herz_jesus_p25", 9, "baseline"): {0: 21.0}, ("herz_jesus_p25", 9, "full"): {0: 21.5}}
    out = ct.variant_table(default, variants)
    assert out[2] == "| default (session 21) | 13.90 (-0.20) | 21.50 (+0.50) | +0.15 | -0.20 | 2 |"
    assert out[3] == "| pw02 | 14.50 (+0.40) | - | +0.40 | +0.40 | 1 |"
    assert out[4] == "| rel | - | 22.00 (+1.00) | +1.00 | +1.00 | 1 |"


def test_session23_table_gives_each_groups_median_spread_and_gaussians(tmp_path):
    import session23_table as st

    (tmp_path / "a.txt").write_text("# a comment\n"
                                    "d_fern_nodepth_s0 21.0 300 [1.0] [2.0]\n"
                                    "d_fern_nodepth_s1 20.0 100 [1.0] [2.0]\n"
                                    "l_best_s0 24.0 50 [1.0] [2.0]\n"
                                    "unknown_group_s0 99.0 1 [1.0] [2.0]\n"
                                    "syn_nodepth_s0 22.0\n")  # no Gaussians: not a run summary
    (tmp_path / "b.txt").write_text("d_fern_nodepth_s2 23.0 200 [1.0] [2.0]\n")
    runs = st.load(tmp_path)
    assert runs["d_fern_nodepth"] == {0: (21.0, 300), 1: (20.0, 100), 2: (23.0, 200)}
    assert "syn_nodepth" not in runs
    out = st.table(runs)
    assert "| fern 3v | full, no depth terms | 0, 1, 2 | 21.00 [20.00, 23.00] | 200 |" in out
    assert any(row.startswith("| lego 8v |") and "| 0 | 24.00 | 50 |" in row for row in out)  # one seed: no spread
    assert not any("99.00" in row for row in out)  # only the named groups, in their order


def test_seed_table_gives_each_cases_before_and_after_and_the_mean_change():
    before = {("castle_p30", 3, "baseline"): {0: 15.0}, ("castle_p30", 3, "full"): {0: 14.5},
              ("herz_jesus_p25", 9, "baseline"): {0: 21.0}, ("herz_jesus_p25", 9, "full"): {0: 22.0},
              ("herz_jesus_p25", 6, "baseline"): {0: 19.0}}  # no after: not a row
    after = {("castle_p30", 3, "baseline"): {0: 14.0}, ("castle_p30", 3, "full"): {0: 15.0},
             ("herz_jesus_p25", 9, "baseline"): {0: 21.5}}  # herz 9 views full missing: "-"
    out = ct.seed_table(before, after)
    assert out[2] == "| castle_p30 | 3 | 15.00 -> 14.00 | 14.50 -> 15.00 |"
    assert out[3] == "| herz_jesus_p25 | 9 | 21.00 -> 21.50 | - |"
    assert len(out) == 6 and out[-1] == "- mean change: baseline -0.25 dB, full +0.50 dB"


def test_seed_medians_groups_runs_by_name_without_the_seed(tmp_path):
    from bench import seed_medians

    f = tmp_path / "o.txt"
    f.write_text("o_lego_full_s0 23.2 100 [1.0] [2.0]\no_lego_full_s2 23.6 300 [] []\no_lego_full_s1 22.0 200 [] []\n"
                 "o_dtu_baseline_s0 20.5 50 [] []\nnot a run line\n")
    rows = seed_medians.read([f])
    assert rows == {"o_lego_full": {0: (23.2, 100), 2: (23.6, 300), 1: (22.0, 200)}, "o_dtu_baseline": {0: (20.5, 50)}}
    lines = seed_medians.table(rows)
    assert lines[2] == "| o_lego_full | 23.20 [22.00, 23.60] | 0, 1, 2 | 200 |"
    assert lines[3] == "| o_dtu_baseline | 20.50 [20.50, 20.50] | 0 | 50 |"


def test_readme_results_rows_from_summaries(tmp_path):
    import json

    from bench import readme_results as rr

    (tmp_path / "noarg_cpu").mkdir()
    (tmp_path / "noarg_cpu" / "seeds_s37.json").write_text(json.dumps({"machine": "a 2-core test CPU", "per_seed": {
        str(s): {"baseline": {"psnr": 20.0 + s}, "full": {"psnr": 22.0 + s}} for s in range(3)}}))
    (tmp_path / "s36").mkdir()
    # session 36's defaults: fern / DTU / lego's best setting in c.txt, lego's defaults in e.txt (baseline; its
    # interrupted full runs are not read) and f.txt (full), the captures in b_all.txt (the "db" runs only) and g.txt
    (tmp_path / "s36" / "c.txt").write_text("c_fern_db_s0 22.0 10\nc_fern_db_s1 22.4 10\nc_fern_full_db_s0 22.5 9\n"
                                           "c_fern_full_dec_s0 99.0 9\nc_dtu_full_db_s0 98.0 5\nc_lego_db_s0 25.5 5\n")
    (tmp_path / "s36" / "e.txt").write_text("e_lego_baseline_db_s0 24.8 5\ne_lego_full_db_s0 99.0 5\n")
    (tmp_path / "s36" / "f.txt").write_text("f_lego_full_s0 24.4 5\n")
    (tmp_path / "s36" / "b_all.txt").write_text("b_castle_p30_3v_baseline_db_s0 15.9 1\nb_castle_p30_3v_full_db_s0 15.8 1\n"
                                               "b_castle_p30_3v_baseline_dec_s0 99.0 1\nb_castle_p30_3v_full_db_s1 16.0 1\n")
    (tmp_path / "s36" / "g.txt").write_text("g_herz_jesus_p25_9v_baseline_s0 23.0 1\ng_herz_jesus_p25_9v_full_s0 22.5 1\n")
    # session 37: the full method of DTU and the captures at 384x256 with full.pseudo_weight=0.2 ("t_p_" runs only)
    (tmp_path / "s37").mkdir()
    (tmp_path / "s37" / "t.txt").write_text("t_p_dtu_full_s0 25.0 5\nt_s_dtu_full_s0 99.0 5\n"
                                            "t_p_castle_p30_3v_full_s0 16.2 1\nt_p_castle_p30_3v_full_s1 16.4 1\n"
                                            "t_sp_castle_p30_3v_full_s0 99.0 1\nt_r_fern_full_s0 23.0 9\n"
                                            "t_r_castle_p30_3v_full_s0 99.0 1\n")
    # session 38: fern's full method with its growth stopped at half the run (seed 0 above, seeds 1-2 here), lego's
    # with pseudo weight 0.2, the captures at images_4 (seeds 0-2; the baseline's seed 0 is g.txt's)
    (tmp_path / "s38").mkdir()
    (tmp_path / "s38" / "l.txt").write_text("l_fern_full_rs05_s1 23.2 9\nl_lego_full_pw02_s0 24.7 5\n")
    (tmp_path / "s38" / "i.txt").write_text("i_herz_jesus_p25_9v_baseline_s1 23.4 1\ni_herz_jesus_p25_9v_full_s0 22.9 1\n"
                                            "i_herz_jesus_p25_9v_full_s1 23.1 1\ni_herz_jesus_p25_9v_full_s2 23.3 1\n")
    out = rr.rows(tmp_path)
    assert out[2].startswith("| synthetic room, 3 views |") and "| 21.00 [20.00, 22.00] | 23.00 [22.00, 24.00] | +2.00 |" in out[2]
    assert "| a 2-core test CPU |" in out[2] and "`noarg_cpu/seeds_s37.json`" in out[2]
    fern = next(r for r in out if r.startswith("| LLFF fern"))
    assert "| 22.20 [22.00, 22.40] (2 seeds) | 23.10 [23.00, 23.20] (2 seeds) | +0.90 |" in fern
    dtu = next(r for r in out if r.startswith("| DTU"))  # no baseline run in this folder: none shown
    assert "| - | 25.00 [25.00, 25.00] (1 seed) | - | `s36/c.txt`, `s37/t.txt` |" in dtu
    lego = next(r for r in out if r.startswith("| Blender lego, 8 views | 400x400"))
    assert "| 24.80 [24.80, 24.80] (1 seed) | 24.70 [24.70, 24.70] (1 seed) | -0.10 |" in lego
    assert any(r.startswith("| Blender lego, 8 views | best setting") and "25.50" in r for r in out)
    castle = next(r for r in out if r.startswith("| castle_p30, 3 views | 384x256"))
    assert "| 15.90 [15.90, 15.90] (1 seed) | 16.30 [16.20, 16.40] (2 seeds) | +0.40 |" in castle
    herz = next(r for r in out if r.startswith("| herz_jesus_p25, 9 views | 768x512"))
    # the baseline's seeds 0 (g.txt) and 1 (i.txt); g.txt's full run (session 36's pseudo weight 1) is not read
    assert "| 23.20 [23.00, 23.40] (2 seeds) | 23.10 [22.90, 23.30] | -0.10 | `s36/g.txt`, `s38/i.txt` |" in herz


def test_with_baselines_replaces_only_the_baselines_it_has():
    from bench.captures_table import with_baselines

    default = {("a", 3, "baseline"): {0: 1.0}, ("a", 3, "full"): {0: 2.0}, ("a", 6, "baseline"): {0: 3.0},
               ("a", 6, "full"): {0: 4.0}}
    new = {("a", 6, "baseline"): {1: 5.0}, ("a", 6, "full"): {1: 9.0}, ("b", 9, "baseline"): {0: 6.0}}
    assert with_baselines(default, new) == {("a", 3, "baseline"): {0: 1.0}, ("a", 3, "full"): {0: 2.0},
                                            ("a", 6, "baseline"): {1: 5.0}, ("a", 6, "full"): {0: 4.0},
                                            ("b", 9, "baseline"): {0: 6.0}}


def test_readme_current_figures_match_the_committed_summaries():
    """The README's table between its readme_results markers is what bench/readme_results.py makes of the committed
    run summaries: a figure typed by hand, or a summary changed without regenerating the table, fails here."""
    from bench import readme_results as rr

    root = Path(__file__).resolve().parents[1]
    doc = (root / "README.md").read_text()
    i, j = doc.index(rr.START) + len(rr.START), doc.index(rr.END)
    assert doc[i:j].strip("\n").splitlines() == rr.rows(root / "bench" / "results")


def test_load_weights_reads_the_pseudo_weight_from_the_run_name(tmp_path):
    p = tmp_path / "w.txt"
    p.write_text("w0.1_castle_p30_9v_full_s0 24.0 10 [1.0] [2.0]\n"
                 "w0.05_castle_p30_9v_full_s0 23.5 10 [1.0] [2.0]\n"
                 "w0.05_herz_jesus_p25_3v_full_s1 18.0 10 [1.0] [2.0]\n"
                 "t_p_castle_p30_9v_full_s0 99.0 10\n")  # another prefix
    assert ct.load_weights(p) == {"pseudo_weight=0.1": {("castle_p30", 9, "full"): {0: 24.0}},
                                  "pseudo_weight=0.05": {("castle_p30", 9, "full"): {0: 23.5},
                                                         ("herz_jesus_p25", 3, "full"): {1: 18.0}}}


def test_session37_default_keeps_session36s_baselines_and_takes_the_weighted_full_runs(tmp_path):
    (tmp_path / "s36").mkdir()
    (tmp_path / "s37").mkdir()
    (tmp_path / "s36" / "b_all.txt").write_text("b_castle_p30_3v_baseline_db_s0 15.0 1\n"
                                                "b_castle_p30_3v_full_db_s0 14.0 1\n"
                                                "b_castle_p30_3v_baseline_dec_s0 99.0 1\n")  # another switch
    (tmp_path / "s37" / "t.txt").write_text("t_p_castle_p30_3v_full_s0 16.0 1\n"
                                            "t_s_castle_p30_3v_baseline_s0 98.0 1\n"  # another variant
                                            "t_p_dtu_full_s0 26.0 1\n")  # not a capture
    assert ct.session37_default(tmp_path) == {("castle_p30", 3, "baseline"): {0: 15.0},
                                              ("castle_p30", 3, "full"): {0: 16.0}}


def test_session40_tables_put_each_partner_run_beside_the_default_it_changes(tmp_path, capsys):
    for d in ("s36", "s37", "s38", "s40"):
        (tmp_path / d).mkdir()
    (tmp_path / "s36" / "b_all.txt").write_text("b_castle_p30_6v_baseline_db_s0 20.0 1\nb_castle_p30_6v_baseline_db_s1 20.2 1\n"
                                               "b_castle_p30_6v_full_db_s0 99.0 1\n")
    (tmp_path / "s36" / "c.txt").write_text("c_dtu_db_s0 26.4 5\nc_fern_db_s0 22.8 9\nc_dtu_full_dec_s0 99.0 5\n")
    (tmp_path / "s37" / "t.txt").write_text("t_p_castle_p30_6v_full_s0 20.7 1\nt_p_dtu_full_s0 26.6 5\n"
                                            "t_r_fern_full_s0 23.0 9\n")
    (tmp_path / "s38" / "l.txt").write_text("l_fern_full_rs05_s1 22.9 9\n")
    (tmp_path / "s36" / "g.txt").write_text("g_castle_p30_9v_baseline_s0 24.3 1\n")
    (tmp_path / "s38" / "i.txt").write_text("i_castle_p30_9v_full_s0 24.6 1\n")
    assert ct.main(["--results", str(tmp_path), "--session", "40"]) == 0
    assert capsys.readouterr().out.strip() == "no s40 summaries yet"
    (tmp_path / "s40" / "p.txt").write_text("p_castle_p30_6v_baseline_s0 20.5 1\np_castle_p30_6v_full_s0 21.5 1\n"
                                            "p_dtu_baseline_s0 26.0 5\np_dtu_full_s0 27.5 5\np_fern_full_s0 23.1 9\n")
    (tmp_path / "s40" / "i.txt").write_text("i_castle_p30_9v_baseline_s0 24.0 1\ni_castle_p30_9v_full_s0 25.0 1\n")
    tables = ct.session40_tables(tmp_path)
    assert len(tables) == 3  # p's captures, p's DTU and fern, i's captures (no h.txt)
    row = next(r for r in tables[0] if r.startswith("| castle_p30 | 6 |"))
    # session 37's default (baseline median 20.10, full 20.70), then the path partner's, and its full - baseline
    assert row == ("| castle_p30 | 6 | 20.10 [20.00, 20.20] | 20.70 [20.70, 20.70] | 20.50 [20.50, 20.50] | "
                   "21.50 [21.50, 21.50] | +1.00 |")
    named = "\n".join(tables[1])
    for name in ("dtu baseline (default)", "dtu full (default)", "p_dtu_baseline", "p_dtu_full",
                 "fern baseline (default)", "fern full (default)", "p_fern_full"):
        assert f"| {name} |" in named
    # fern's default full method: seed 0 of s37/t.txt and seeds 1-2 of s38/l.txt (NAMED_DEFAULTS)
    assert "| fern full (default) | 22.95 [22.90, 23.00] | 0, 1 |" in named
    assert "c_dtu_full_dec" not in named and "castle" not in named
    row = next(r for r in tables[2] if r.startswith("| castle_p30 | 9 |"))
    assert row.endswith("| 24.00 [24.00, 24.00] | 25.00 [25.00, 25.00] | +1.00 |")
    # the changes against the default: baseline 20.10 -> 20.50, full 20.70 -> 21.50; the variant's full method
    # against the default's baseline 21.50 - 20.10
    assert "- mean change of the medians against the default (path partner): baseline +0.40 dB (worst +0.40), " \
           "full +0.80 dB (worst +0.80)" in tables[0]
    assert ("- path partner in the full method only, against the default baseline: mean +1.40 dB, worst +1.40 dB "
            "over 1 cases") in tables[0]
    # at images_4 the default's full method has its seed 0 only (24.6), the baseline's from s36/g.txt (24.3)
    assert "- path partner in the full method only, against the default baseline: mean +0.70 dB, worst +0.70 dB " \
           "over 1 cases" in tables[2]


def write_session37_default(results, *more_dirs):
    """Fake summaries of session 37's default (castle_p30 6 views: baseline 20.0 / 20.2, full 20.7; DTU's and fern's
    named defaults) under ``results``, and the empty folders ``more_dirs``."""
    for d in ("s36", "s37", "s38", *more_dirs):
        (results / d).mkdir()
    (results / "s36" / "b_all.txt").write_text("b_castle_p30_6v_baseline_db_s0 20.0 1\nb_castle_p30_6v_baseline_db_s1 20.2 1\n")
    (results / "s36" / "c.txt").write_text("c_dtu_db_s0 26.4 5\nc_fern_db_s0 22.8 9\n")
    (results / "s37" / "t.txt").write_text("t_p_castle_p30_6v_full_s0 20.7 1\nt_p_dtu_full_s0 26.6 5\n")
    (results / "s38" / "l.txt").write_text("")


def test_session41_tables_put_each_weight_beside_the_default_baseline(tmp_path):
    write_session37_default(tmp_path, "s41")
    (tmp_path / "s36" / "g.txt").write_text("g_castle_p30_9v_baseline_s0 24.3 1\n")
    (tmp_path / "s38" / "i.txt").write_text("i_castle_p30_9v_full_s0 24.6 1\n")
    assert ct.session41_tables(tmp_path) == []
    (tmp_path / "s41" / "c.txt").write_text("c_pc10_castle_p30_6v_full_s0 21.0 1\nc_pc10_castle_p30_6v_full_s1 21.4 1\n"
                                            "c_pc03_castle_p30_6v_full_s0 20.5 1\nc_pc10_dtu_full_s0 27.5 5\n")
    (tmp_path / "s41" / "i.txt").write_text("i_castle_p30_9v_full_s0 25.3 1\n")
    tables = ct.session41_tables(tmp_path)
    assert len(tables) == 3
    text = "\n".join(tables[0])
    # the baseline's median 20.10: 1.0 gives 21.20 (+1.10), 0.3 gives 20.50 (+0.40); the default's full 20.70 (+0.60)
    assert "| default (session 37) | 20.70 (+0.60) |" in text
    assert "| path_consistency=1.0 | 21.20 (+1.10) |" in text and "| path_consistency=0.3 | 20.50 (+0.40) |" in text
    assert "| c_pc10_dtu_full |" in "\n".join(tables[1]) and "| dtu full (default) |" in "\n".join(tables[1])
    assert "| path_consistency=1.0 | 25.30 (+1.00) |" in "\n".join(tables[2])
    # the baseline with the term too: the pair's gain over its own baseline, and the changes against the default
    (tmp_path / "s41" / "b.txt").write_text("b_pc10_castle_p30_6v_baseline_s0 20.6 1\nb_pc10_castle_p30_6v_baseline_s1 20.8 1\n"
                                            "b_pc10_dtu_baseline_s0 26.9 5\n")
    tables = ct.session41_tables(tmp_path)
    assert len(tables) == 5
    both = "\n".join(tables[2])
    assert both.startswith("path_consistency=1.0 in both methods (train.path_consistency in the baseline)")
    assert "| castle_p30 | 6 | 20.10 [20.00, 20.20] | 20.70 [20.70, 20.70] | 20.70 [20.60, 20.80] | " \
           "21.20 [21.00, 21.40] | +0.50 |" in both
    assert "baseline +0.60 dB (worst +0.60), full +0.50 dB (worst +0.50)" in both
    assert "| b_pc10_dtu_baseline |" in "\n".join(tables[3])


def test_session42_tables_merge_the_screens_seed_0_into_the_depth_variant(tmp_path):
    write_session37_default(tmp_path, "s41", "s42")
    summaries = {  # castle_p30 6 views; the screen's seed 0 of the depth variant, seeds 1-2 from session 42
        "s41/s.txt": ["s_depth_weight_castle_p30_6v_full_s0 20.9 1", "s_densify_castle_p30_6v_full_s0 20.1 1"],
        "s42/d.txt": ["d_castle_p30_6v_full_s1 21.3 1", "d_castle_p30_6v_full_s2 21.1 1", "d_dtu_full_s1 26.8 5"],
        "s42/w.txt": ["w_rw50_castle_p30_6v_full_s0 20.2 1", "w_rw50_dtu_full_s0 27.0 5",
                      "w_rw25_castle_p30_6v_full_s0 20.4 1"],
    }
    (tmp_path / "s41/s.txt").write_text("\n".join(summaries["s41/s.txt"]))
    assert ct.session42_tables(tmp_path) == []  # the screen alone is session 41's
    for name in ("s42/d.txt", "s42/w.txt"):
        (tmp_path / name).write_text("\n".join(summaries[name]))
    variants, dtu = ("\n".join(t) for t in ct.session42_tables(tmp_path))
    # the baseline's median 20.10; depth_weight=0 has seeds 0 (the screen's 20.9), 1 and 2: median 21.10 (+1.00)
    assert "| depth_weight=0 | 21.10 (+1.00) |" in variants and "| reliable_weight=5 | 20.20 (+0.10) |" in variants
    assert "| reliable_weight=2.5 | 20.40 (+0.30) |" in variants
    # DTU's runs in one table; w_rw25 has no DTU run here
    assert "| w_rw50_dtu_full |" in dtu and "| w_rw25_dtu_full |" not in dtu and "| d_dtu_full |" in dtu


def test_session42_tables_put_the_growth_schedules_side_by_side(tmp_path):
    """x: cycle_iterations and its control against the default's baseline; g: the default full method against a
    baseline that grows as it does; h: the default baseline against a full method that grows as the baseline does."""
    write_session37_default(tmp_path, "s41", "s42")
    (tmp_path / "s42/x.txt").write_text("x_castle_p30_6v_full_s0 20.5 1\nx_castle_p30_6v_full_s1 20.9 1\n"
                                        "xc_castle_p30_6v_full_s0 20.3 1\nx_dtu_full_s0 27.1 5\n")
    (tmp_path / "s42/g.txt").write_text("g_castle_p30_6v_baseline_s0 20.4 1\ng_castle_p30_6v_baseline_s1 20.6 1\n"
                                        "g_dtu_baseline_s0 26.2 5\n")
    (tmp_path / "s42/h.txt").write_text("h_castle_p30_6v_full_s0 20.3 1\nh_dtu_full_s0 26.7 5\n")
    x, g, h, dtu = ("\n".join(t) for t in ct.session42_tables(tmp_path))
    # against the baseline's median 20.10: cycle_iterations 20.70 (+0.60), its control 20.30 (+0.20)
    assert "| cycle_iterations=1000 | 20.70 (+0.60) |" in x and "| its control, seed 0 | 20.30 (+0.20) |" in x
    # the default full 20.70 against the growing baseline's 20.50: +0.20; its baseline moved +0.40, the full method not
    assert g.splitlines()[4].endswith("| +0.20 |") and "baseline +0.40 dB" in g and "full +0.00 dB" in g
    # the full method growing as the baseline: 20.30 against the default baseline's 20.10
    assert h.splitlines()[4].endswith("| +0.20 |") and "full -0.40 dB" in h
    for name in ("x_dtu_full", "xc_dtu_full", "g_dtu_baseline", "h_dtu_full"):
        assert (f"| {name} |" in dtu) == (name != "xc_dtu_full"), name


def test_session43_tables_compare_growth_and_the_pair_with_the_default(tmp_path):
    """m: both methods stopping growth at 0.75, beside the default; b and c: seed-0 variants of the full method against
    the default's seed 0 (and, for b, its seeds 0-2); DTU's runs in one table."""
    write_session37_default(tmp_path, "s43")
    assert ct.session43_tables(tmp_path) == []
    (tmp_path / "s43/m.txt").write_text("m_castle_p30_6v_baseline_s0 20.5 1\nm_castle_p30_6v_baseline_s1 20.3 1\n"
                                        "m_castle_p30_6v_full_s0 20.9 1\nm_dtu_full_s0 26.5 5\n")
    (tmp_path / "s43/b.txt").write_text("b_gb20_castle_p30_6v_full_s0 20.6 1\nb_gb20_dtu_full_s0 26.6 5\n")
    (tmp_path / "s43/c.txt").write_text("c_cr_castle_p30_6v_full_s0 19.9 1\nc_cr_dtu_baseline_s0 26.4 5\n")
    m, b, c, dtu = ("\n".join(t) for t in ct.session43_tables(tmp_path))
    # the late-stopping pair: baseline median 20.40, full 20.90: +0.50; both moved against the default (20.10 / 20.70)
    assert m.splitlines()[4].endswith("| +0.50 |") and "baseline +0.30 dB" in m and "full +0.20 dB" in m
    # growth_budget=2.0 at seed 0 against the default's seed-0 baseline 20.0 (+0.60), then its median 20.10 (+0.50)
    assert "| growth_budget=2.0 | 20.60 (+0.60) |" in b and "| growth_budget=2.0 | 20.60 (+0.50) |" in b
    assert "| co_reg=true | 19.90 (-0.10) |" in c
    for name in ("m_dtu_full", "b_gb20_dtu_full", "c_cr_dtu_baseline"):
        assert f"| {name} |" in dtu, name
    assert "| c_cr_dtu_full |" not in dtu and "| m_dtu_baseline |" not in dtu


def test_session44_tables_put_dtu_variants_beside_its_defaults(tmp_path):
    """Session 44's DTU runs, median [min, max] over their seeds, in one table under DTU's defaults; runs of other
    names in the summaries are not listed."""
    write_session37_default(tmp_path, "s44")
    assert ct.session44_tables(tmp_path) == []
    (tmp_path / "s44/a.txt").write_text("a_off5_dtu_full_s0 26.4 5\na_off5_dtu_full_s1 26.6 5\na_off5_dtu_full_s2 26.5 5\n"
                                        "a_bxy_dtu_baseline_s0 26.1 5\na_zzz_dtu_full_s0 30.0 5\n")
    (tmp_path / "s44/c.txt").write_text("c_off5pw5_dtu_full_s0 25.8 5\n")
    (dtu,) = ct.session44_tables(tmp_path)
    text = "\n".join(dtu)
    assert "| dtu full (default) | 26.60 [26.60, 26.60] |" in text
    assert "| a_off5_dtu_full | 26.50 [26.40, 26.60] | 0, 1, 2 |" in text
    assert "| a_bxy_dtu_baseline | 26.10 [26.10, 26.10] | 0 |" in text and "| c_off5pw5_dtu_full | 25.80" in text
    assert "a_zzz" not in text and "a_off10" not in text
