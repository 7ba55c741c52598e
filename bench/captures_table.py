"""The README's capture tables of sessions 20 and 21, generated from the GPU runs' summaries (not typed by hand).

    python bench/captures_table.py [--session 21] [--results bench/results]

Lines ``NAME PSNR GAUSSIANS [per-view PSNRs] [curve]`` as ``bench/gpu_session19.sh p`` / ``gpu_session20.sh c`` /
``gpu_session21.sh`` print them; a markdown table of medians [min, max] over the seeds per scene, views and
method, with the full method's gain over the baseline and the collapses (a run over 2 dB below its column's
median).
- session 20: ``s20/path_floaters.txt`` (the previous default, ``_r0``, and with ``train.path_floaters`` 10,
  ``_r10``) and ``s20/captures_d.txt`` (with the path floaters and ``train.prune_unseen_at_end``);
- session 21: that default, then the one with ``train.hold_geometry: stereo`` (``s21/captures_default3.txt``,
  the 3-view runs it changes, and ``s21/captures_default69.txt``, the 6- and 9-view runs repeated with it);
- session 22: the full method's variants (``s22/weak_part1.txt``, ``x_VARIANT_...``; ``s22/wide_full.txt``,
  ``w_VARIANT_...``) against session 21's default: one row per variant, the full method's median per case and its
  gain over session 21's baseline, the mean and worst gain over the cases measured; then 3 views at 768x512
  (10,000 it) from SfM's points (``s21/a768_10k_3v.txt`` seed 0, ``s22/a768_sfm.txt`` seeds 1-2) and from held
  stereo (``geometry.sfm_min_views`` 4, ``s22/a768_views.txt``);
- session 26: session 21's default as recorded then, and the current default re-run (``s26/a3.txt``: 3 views with
  ``geometry.extend_far``; ``s26/c69.txt``: 6 and 9 views); then ``full.pseudo_mask=reliable`` (``s26/r3.txt``,
  ``s26/r69.txt``) against the current default;
- session 27 (``bench/gpu_session27.sh``): first the default re-run after the CUDA forward's skip test was fixed
  (``s27/h.txt``) beside session 26's (measured with session 24's forward); then, all measured with session 24's
  forward and against session 26's default, the full method's variants
  ``full.pseudo_mask=all`` (``s27/m3.txt``, ``s27/m369.txt``) and ``full.cycles=1`` (``s27/y369.txt``), then
  ``train.far_field_blur=1`` for both methods (``s27/f3.txt``, ``s27/f369.txt``; with ``pseudo_mask=all`` at 3 views,
  ``s27/g3.txt``) and ``train.opacity_noise=0.8`` at 3 views (``s27/n3.txt``); ``s27/k3.txt`` is session 26's
  castle_p30 3-view baseline seed 0 re-run (the same 14.824);
- session 28 (``bench/gpu_session28.sh``): session 27's default (``s27/h.txt``) beside the far field on a cylinder
  (``train.far_field_proxy=auto``, ``s28/c369.txt``) and beside session 28's default, which adds
  ``full.pseudo_mask=all`` for the captures (its full runs ``s28/m369.txt``, its baseline runs those of ``c369``: the
  option touches only the full method); then ``pseudo_mask=all`` as a variant against the cylinder's runs;
- session 29 (``bench/gpu_session29.sh``): the full method's variants ``full.cycles=3`` and
  ``full.baseline_fraction=0.3`` (``s29/v369.txt``, ``v_c3_...`` / ``v_bf03_...``) and ``full.pseudo_weight=0.5``
  (``s29/w_pw05.txt``, ``v_pw05_...``) against session 28's default;
- session 30 (``bench/gpu_session30.sh``): session 28's default beside the path-floater pass on both paths with 9
  poses (``train.path_floaters_paths=both``, ``train.path_floaters_poses=9``; ``s30/b369.txt``, both methods), then
  the full method's 3-view variants ``pseudo.trajectory.n_frames=17`` and ``full.pseudo_weight=2``
  (``s30/x3.txt``, ``x_n17_...`` / ``x_pw2_...``) against session 28's default; then the images_4 runs (768x512,
  10,000 it, seed 0) of session 28 (``s28/i369.txt``) -> those with session 30's default (``s30/i369.txt``);
- session 31 (``bench/gpu_session31.sh j``): images_4, seeds 0-2, session 28's path-floater pass
  (``images4_default``: seed 0 ``s28/i369.txt``, seeds 1-2 ``s31/k369.txt``, later ``s32/k369.txt``) beside session
  30's (``s30/i369.txt``, ``s31/j369.txt``);
- session 33 (``bench/gpu_session33.sh d``): images_4, the full method's pseudo-view phase from step 2000
  (``full.baseline_fraction=0.2``, ``s33/d369.txt``) against that default;
- session 34 (``bench/gpu_session34.sh p``): 384x256, the full method with SYN3R's perturbed pseudo-view poses
  (``pseudo.trajectory.perturb_candidates=5``, translation sigma 0.1 / 0.3: ``p_pert10_...`` / ``p_pert30_...`` in
  ``s34/p369.txt``) against session 28's default.
- session 35 (``bench/gpu_session35.sh``): both methods with growth stopped at half the run
  (``strategy.refine_stop_iter``): at 384x256 at step 1500 of 3000 (``s35/r.txt``, 6 and 9 views) beside session
  28's default, and at images_4 at step 5000 of 10,000 (``s35/c69.txt``) beside the images_4 default.
- session 36 (``bench/gpu_session36.sh``): Binocular3DGS's opacity decay (``train.opacity_decay=0.005``) and binocular
  consistency (``train.binocular=1``), each alone and both (``b_..._{dec,bin,db}_s0`` in ``s36/b_all.txt``, both at
  seeds 0-2), at 384x256 beside session 28's default with session 35's baselines; at images_4, seed 0, with both
  as the new default (``s36/g.txt``) beside the images_4 default's seed 0.
- session 37 (``bench/gpu_session37.sh t`` and ``w``): the full method's variants against session 36's default at
  384x256 (``s37/t.txt``, ``t_VARIANT_...``: ``s`` the binocular term from 0.2 of the run, for both methods; ``p``
  ``full.pseudo_weight=0.2``; ``sp`` both; ``bf`` ``full.baseline_fraction=0.6``; ``r``
  ``full.refine_stop_fraction=0.5``; ``p`` and ``sp`` at seeds 0-2, the rest at seed 0), the pseudo weights 0.1 and
  0.05 at seed 0 (``s37/w.txt``, ``w<weight>_...``), and session 36's default beside session 37's
  (``full.pseudo_weight=0.2``: the full runs of ``t_p_...``, the baselines unchanged).
- session 38 (``bench/gpu_session38.sh q``, two H200s): ``full.cycles=3`` and ``full.baseline_fraction=0.6`` against
  session 37's default at 384x256, seeds 0-2 (``s38/v.txt``, ``v_c3_...``, ``v_bf6_...``); session 37's default at
  images_4 (768x512, 10,000 it, ``s38/i.txt``; the baseline's seed 0 is ``s36/g.txt``: the captures' baseline did not
  change); DTU at 10,000 it (``s38/d.txt``), lego's full method at pseudo weight 0.2 and fern's with its growth
  stopped at half the run (``s38/l.txt``, fern's seed 0 in ``s37/t.txt``).
- session 40 (``bench/gpu_session40.sh``, prepared in session 39): the binocular term's partner on the capture path
  (``train.binocular_partner=path``), both methods, seeds 0-2: at 384x256 against session 37's default (``s40/p.txt``,
  ``p_...``; ``s40/h.txt``, ``h_...``: reach 0.25; ``s40/b.txt``, ``b_...``: the term from 0.25 of the run, no fern),
  DTU and fern beside their defaults; at images_4 against session
  38's (``s40/i.txt``, ``i_...``). The tables of the files present are printed.
- session 41 (``bench/gpu_session41.sh``, prepared in session 40): the full method with ``full.path_consistency`` 1.0
  and 0.3 against session 37's default at 384x256, seeds 0-2 (``s41/c.txt``, ``c_pc10_...``, ``c_pc03_...``; DTU and
  fern beside their defaults), the baseline with ``train.path_consistency`` at the same weights (``s41/b.txt``,
  ``b_pc10_...``: the term in both methods), and 1.0 at images_4 against session 38's (``s41/i.txt``, ``i_...``);
  a seed-0 screen of the full method's parts (``s41/s.txt``, ``s_densify_...``, ``s_depth_weight_...``,
  ``s_guidance_...``: no densification, no depth term on the pseudo views, renders for guidance) against session
  37's default at seed 0, DTU beside its defaults.
- session 42 (``bench/gpu_session42.sh``, prepared in session 41): the full method with ``full.reliable_weight`` 5 and
  2.5 (``s42/w.txt``, ``w_rw50_...``, ``w_rw25_...``) and ``full.depth_weight=0`` (``s42/d.txt``, ``d_...``, seeds 1-2; seed 0 from
  session 41's screen) against session 37's default at 384x256; DTU beside its defaults. Then (written during the
  session) ``full.cycle_iterations=1000`` over seeds 0-2 and its control at seed 0 (``s42/x.txt``, ``x_...``,
  ``xc_...``), the baseline with the full method's growth schedule (``s42/g.txt``, ``g_...``) and the full method
  with the baseline's (``s42/h.txt``, ``h_...``), seeds 0-2.
- session 43 (``bench/gpu_session43.sh``, prepared in session 42): both methods stopping growth at 0.75 of the run
  (``s43/m.txt``, ``m_...``, seeds 0-2, fern and DTU too) beside session 37's default; the full method's
  ``full.growth_budget`` 0 and 2.0 and ``strategy.grow_grad2d=0.0003`` (``s43/b.txt``, ``b_gb0_...``, ``b_gb20_...``,
  ``b_gg3_...``, seed 0); then (written during the session) CoR-GS's pair, ``train.co_reg=true`` (``s43/c.txt``,
  ``c_cr_...``: DTU in both methods, seeds 0-2; the captures' full method, seed 0).
- session 44 (``bench/gpu_session44.sh``): DTU only, seeds 0-2, beside DTU's and fern's defaults: the full method's
  pseudo views also on copies of the path moved up and down (``pseudo.trajectory.offsets``: ``s44/a.txt``,
  ``a_off5_...``, ``a_off10_...``), the binocular term's partner moved in any direction of the image plane
  (``train.binocular_axes=xy``, both methods: ``a_bxy_...``), both (``a_both_...``), and the moved copies weighing
  more (``s44/c.txt``, ``c_off5rw5_...``, ``c_off5pw5_...``).
- session 39 (the last 290 s of two H200s): the full method at pseudo weight 0.1 against session 37's default (0.2)
  at 384x256, seeds 0-2 (``s39/x.txt``, ``x_...``; DTU's ``x_dtu_full_sK`` beside ``s37/t.txt``'s).
"""

from __future__ import annotations

import argparse
import re
import statistics
from pathlib import Path

NAME = re.compile(r"^(?P<prefix>[a-z]+)_(?P<scene>\w+?_p\d+)_(?P<views>\d+)v_(?P<method>baseline|full)_s(?P<seed>\d+)"
                  r"(?:_r(?P<ratio>\d+))?$")


def load(path: Path, prefix: str, ratio: str | None = None) -> dict:
    """{(scene, views, method): {seed: psnr}} of the runs named ``prefix_...`` (and ``_r{ratio}`` where given)."""
    runs: dict = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        m = NAME.match(parts[0]) if parts else None
        if m is None or m["prefix"] != prefix or m["ratio"] != ratio:
            continue
        runs.setdefault((m["scene"], int(m["views"]), m["method"]), {})[int(m["seed"])] = float(parts[1])
    return runs


SWITCHED = re.compile(r"^(?P<prefix>[a-z]+)_(?P<scene>\w+?_p\d+)_(?P<views>\d+)v_(?P<method>baseline|full)"
                      r"_(?P<switch>[a-z]+)_s(?P<seed>\d+)$")


def load_switched(path: Path, prefix: str) -> dict:
    """{switch: {(scene, views, method): {seed: psnr}}} of runs named ``prefix_scene_Nv_method_SWITCH_sK``."""
    out: dict = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        m = SWITCHED.match(parts[0]) if parts else None
        if m is None or m["prefix"] != prefix:
            continue
        key = (m["scene"], int(m["views"]), m["method"])
        out.setdefault(m["switch"], {}).setdefault(key, {})[int(m["seed"])] = float(parts[1])
    return out


def seed0(runs: dict) -> dict:
    return {k: {0: v[0]} for k, v in runs.items() if 0 in v}


def load_variants(path: Path, prefix: str) -> dict:
    """{variant: {(scene, views, method): {seed: psnr}}} of runs named ``prefix_VARIANT_scene_...`` (variant names
    hold no underscore)."""
    out: dict = {}
    for (name, views, method), seeds in load(path, prefix).items():
        variant, _, scene = name.partition("_")
        out.setdefault(variant, {}).setdefault((scene, views, method), {}).update(seeds)
    return out


def variant_table(default: dict, variants: dict, label: str = "default (session 21)") -> list[str]:
    """One row per variant: the full method's median per case (its gain over ``default``'s baseline median), then
    the mean and worst gain over the cases it has; the default's own row first."""
    cases = sorted({(s, n) for (s, n, _) in default})
    head = ["variant"] + [f"{s} {n}v" for s, n in cases] + ["mean gain", "worst gain", "cases"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, runs in [(label, default)] + sorted(variants.items()):
        row, gains = [name], []
        for s, n in cases:
            f, b = runs.get((s, n, "full")), default.get((s, n, "baseline"))
            if not f or not b:
                row.append("-")
                continue
            g = statistics.median(f.values()) - statistics.median(b.values())
            gains.append(g)
            row.append(f"{statistics.median(f.values()):.2f} ({g:+.2f})")
        row += [f"{sum(gains) / len(gains):+.2f}", f"{min(gains):+.2f}", str(len(gains))] if gains else ["-"] * 3
        lines.append("| " + " | ".join(row) + " |")
    return lines


def cell(seeds: dict) -> str:
    v = list(seeds.values())
    return f"{statistics.median(v):.2f} [{min(v):.2f}, {max(v):.2f}]" if v else "-"


def table(columns: list[tuple[str, dict]]) -> list[str]:
    keys = sorted({(s, n) for _, runs in columns for (s, n, _) in runs})
    head = ["scene", "views"] + [f"{label} {m}" for label, _ in columns for m in ("baseline", "full")]
    head += [f"full - baseline ({columns[-1][0]})"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    gains, collapses = [], []
    for s, n in keys:
        row = [s, str(n)]
        for label, runs in columns:
            for m in ("baseline", "full"):
                seeds = runs.get((s, n, m), {})
                row.append(cell(seeds))
                if seeds:
                    med = statistics.median(seeds.values())
                    collapses += [f"{label} {s} {n}v {m} seed {k}: {v:.2f} (median {med:.2f})"
                                  for k, v in seeds.items() if v < med - 2]
        last = columns[-1][1]
        b, f = last.get((s, n, "baseline")), last.get((s, n, "full"))
        g = statistics.median(f.values()) - statistics.median(b.values()) if b and f else None
        row.append("-" if g is None else f"{g:+.2f}")
        if g is not None:
            gains.append(g)
        lines.append("| " + " | ".join(row) + " |")
    if gains:
        lines.append("")
        lines.append(f"- full - baseline ({columns[-1][0]}, medians): mean {sum(gains) / len(gains):+.2f} dB, "
                     f"worst {min(gains):+.2f} dB over {len(gains)} cases")
    lines.append(f"- collapses (more than 2 dB below the column's median): {len(collapses)}"
                 + "".join(f"\n  - {c}" for c in collapses))
    return lines


def seed_table(before: dict, after: dict) -> list[str]:
    """Runs of one seed each (images_4, seed 0), before -> after per case and method, and the mean change per method."""
    keys = sorted({(s, n) for (s, n, _) in before} & {(s, n) for (s, n, _) in after})
    lines = ["| scene | views | baseline | full |", "|---|---|---|---|"]
    change: dict = {"baseline": [], "full": []}
    for s, n in keys:
        row = [s, str(n)]
        for m in ("baseline", "full"):
            b, a = before.get((s, n, m)), after.get((s, n, m))
            if not b or not a:
                row.append("-")
                continue
            (vb,), (va,) = b.values(), a.values()
            change[m].append(va - vb)
            row.append(f"{vb:.2f} -> {va:.2f}")
        lines.append("| " + " | ".join(row) + " |")
    lines.append("")
    lines.append("- mean change: " + ", ".join(f"{m} {sum(v) / len(v):+.2f} dB" for m, v in change.items() if v))
    return lines


def merged(*parts: dict) -> dict:
    out: dict = {}
    for runs in parts:
        for key, seeds in runs.items():
            out.setdefault(key, {}).update(seeds)
    return out


def session28_default(results: Path) -> dict:
    """The captures' default since session 28 at 384x256, 3000 it, seeds 0-2: the baselines of ``s28/c369.txt`` (the
    far field on a cylinder) and the full runs of ``s28/m369.txt`` (that and ``full.pseudo_mask=all``)."""
    cyl = load(results / "s28" / "c369.txt", "c")
    return merged({k: v for k, v in cyl.items() if k[2] == "baseline"}, load(results / "s28" / "m369.txt", "m"))


def images4_default_files(results: Path) -> list[Path]:
    """The summaries of the captures' default (spline path, 3 poses) at images_4, 10,000 it: seed 0 (``s28/i369.txt``),
    seeds 1-2 (``s31/k369.txt``) and the runs session 31 did not finish (``s32/k369.txt``, once it exists)."""
    later = results / "s32" / "k369.txt"
    return [results / "s28" / "i369.txt", results / "s31" / "k369.txt"] + ([later] if later.is_file() else [])


def images4_default(results: Path) -> dict:
    """{(scene, views, method): {seed: psnr}} of ``images4_default_files``."""
    return merged(*[load(f, "i" if f.parent.name == "s28" else "k") for f in images4_default_files(results)])


WEIGHTED = re.compile(r"^w(?P<weight>[\d.]+)_(?P<rest>.+)$")


def load_weights(path: Path) -> dict:
    """{"pseudo_weight=W": {(scene, views, method): {seed: psnr}}} of runs named ``w<W>_scene_Nv_method_sK``."""
    out: dict = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        w = WEIGHTED.match(parts[0]) if parts else None
        m = NAME.match("w_" + w["rest"]) if w else None
        if m is not None:
            key = (m["scene"], int(m["views"]), m["method"])
            out.setdefault(f"pseudo_weight={w['weight']}", {}).setdefault(key, {})[int(m["seed"])] = float(parts[1])
    return out


def session36_default(results: Path) -> dict:
    """Session 36's default at 384x256, 3000 it, seeds 0-2 (decay + binocular, ``s36/b_all.txt``)."""
    return load_switched(results / "s36" / "b_all.txt", "b")["db"]


def session37_default(results: Path) -> dict:
    """Session 37's default at 384x256: session 36's baselines (unchanged) and the full runs with
    ``full.pseudo_weight=0.2`` (``t_p_...`` in ``s37/t.txt``)."""
    s36 = session36_default(results)
    p = load_variants(results / "s37" / "t.txt", "t")["p"]
    return merged({k: v for k, v in s36.items() if k[2] == "baseline"}, {k: v for k, v in p.items() if k[2] == "full"})


def named_variant_table(results: Path, names: dict) -> list[str]:
    """Fern and DTU in session 37: session 36's default (``s36/c.txt``) and each variant of ``s37/t.txt`` and
    ``s37/w.txt``, median [min, max] over the seeds each has (which the row names)."""
    import seed_medians as sm

    s36 = sm.read([results / "s36" / "c.txt"])
    s37 = sm.read([results / "s37" / "t.txt", results / "s37" / "w.txt"])
    rows = [("baseline (session 36 default)", "c_{}_db", s36), ("full (session 36 default)", "c_{}_full_db", s36)]
    rows += [(f"{m}, {label}", f"t_{v}_{{}}_{m}", s37) for v, label in names.items() for m in ("baseline", "full")]
    rows += [(f"full, pseudo_weight={w}", f"w{w}_{{}}_full", s37) for w in ("0.1", "0.05")]
    lines = ["| run | seeds | fern 3 views | DTU scan65 3 views |", "|---|---|---|---|"]
    for label, pattern, runs in rows:
        got = [runs.get(pattern.format(scene), {}) for scene in ("fern", "dtu")]
        if any(got):
            seeds = sorted(set().union(*got))
            lines.append(f"| {label} | {', '.join(map(str, seeds))} | "
                         + " | ".join(cell({k: p for k, (p, _) in g.items()}) if g else "-" for g in got) + " |")
    return lines


def session38_images4(results: Path) -> dict:
    """Session 37's default at images_4 (768x512, 10,000 it), seeds 0-2: ``s38/i.txt``, with the baseline's seed 0
    from ``s36/g.txt`` (the captures' baseline has not changed since session 36)."""
    g = load(results / "s36" / "g.txt", "g")
    return merged({k: {0: v[0]} for k, v in g.items() if k[2] == "baseline" and 0 in v}, load(results / "s38" / "i.txt", "i"))


# The runs of today's defaults on fern, DTU and lego: (summary file under bench/results, run name without its seed),
# later entries adding seeds (bench/readme_results.py's table and the session tables beside which variants are put)
NAMED_DEFAULTS = {
    ("fern", "baseline"): [("s36/c.txt", "c_fern_db")],
    ("fern", "full"): [("s37/t.txt", "t_r_fern_full"), ("s38/l.txt", "l_fern_full_rs05")],  # seed 0, seeds 1-2
    ("dtu", "baseline"): [("s36/c.txt", "c_dtu_db")],
    ("dtu", "full"): [("s37/t.txt", "t_p_dtu_full")],
    ("lego", "baseline"): [("s36/e.txt", "e_lego_baseline_db")],
    ("lego", "full"): [("s38/l.txt", "l_lego_full_pw02")],
}


def named_default(results: Path, scene: str, method: str) -> dict[int, tuple[float, int]]:
    """{seed: (test PSNR, Gaussians)} of today's default on ``scene`` (fern, dtu, lego) for ``method``."""
    import seed_medians as sm

    out: dict = {}
    for file, name in NAMED_DEFAULTS[(scene, method)]:
        out.update(sm.read([results / file]).get(name, {}))
    return out


def named_beside_defaults(results: Path, path: Path | list[Path], names: list[str]) -> list[str]:
    """``seed_medians.table`` of fern's and DTU's defaults (both methods), then the runs ``names`` of summary ``path``
    (or of the summaries listed)."""
    import seed_medians as sm

    rows = {f"{scene} {method} (default)": named_default(results, scene, method)
            for scene in ("dtu", "fern") for method in ("baseline", "full")}
    rows = {k: v for k, v in rows.items() if v}
    runs = sm.read(path if isinstance(path, list) else [path])
    rows.update({n: runs[n] for n in names if n in runs})
    return sm.table(rows)


def session38_named_table(results: Path) -> list[str]:
    """DTU, lego and fern in session 38 beside the defaults they compare with, median [min, max] over the seeds each
    row names."""
    import seed_medians as sm

    runs = sm.read([results / "s36" / "c.txt", results / "s36" / "e.txt", results / "s36" / "f.txt",
                    results / "s37" / "t.txt", results / "s38" / "d.txt", results / "s38" / "l.txt",
                    results / "s38" / "v.txt"])
    fern_rs = named_default(results, "fern", "full")
    rows = [("fern 3 views, 3000 it", "baseline (default)", named_default(results, "fern", "baseline")),
            ("fern 3 views, 3000 it", "full (session 37 default, pseudo weight 1)", runs.get("c_fern_full_db")),
            ("fern 3 views, 3000 it", "full, full.refine_stop_fraction=0.5", fern_rs),
            ("lego 8 views, 10,000 it", "baseline (default)", named_default(results, "lego", "baseline")),
            ("lego 8 views, 10,000 it", "full (session 37 default, pseudo weight 1)", runs.get("f_lego_full")),
            ("lego 8 views, 10,000 it", "full, full.pseudo_weight=0.2", named_default(results, "lego", "full")),
            ("DTU scan65 3 views, 3000 it", "baseline (default)", named_default(results, "dtu", "baseline")),
            ("DTU scan65 3 views, 3000 it", "full (default, pseudo weight 0.2)", named_default(results, "dtu", "full")),
            ("DTU scan65 3 views, 3000 it", "full, full.cycles=3", runs.get("v_c3_dtu_full")),
            ("DTU scan65 3 views, 3000 it", "full, full.baseline_fraction=0.6", runs.get("v_bf6_dtu_full")),
            ("DTU scan65 3 views, 10,000 it", "baseline (default)", runs.get("d_dtu10k_baseline")),
            ("DTU scan65 3 views, 10,000 it", "full (default)", runs.get("d_dtu10k_full"))]
    lines = ["| scene | run | seeds | test PSNR |", "|---|---|---|---|"]
    for scene, label, got in rows:
        if got:
            lines.append(f"| {scene} | {label} | {', '.join(map(str, sorted(got)))} | "
                         f"{cell({k: p for k, (p, _) in got.items()})} |")
    return lines


def change_lines(default: dict, variant: dict, label: str) -> list[str]:
    """Over the cases both have: the mean change of each method's median from ``default`` to ``variant``, and the
    variant's full method against the default's baseline (the comparison issue 13 makes when only the full method
    takes the variant), mean and worst."""
    keys = sorted({(s, n) for (s, n, _) in default} & {(s, n) for (s, n, _) in variant})
    med = statistics.median
    change = {m: [med(variant[(s, n, m)].values()) - med(default[(s, n, m)].values()) for s, n in keys
                  if default.get((s, n, m)) and variant.get((s, n, m))] for m in ("baseline", "full")}
    mixed = [med(variant[(s, n, "full")].values()) - med(default[(s, n, "baseline")].values()) for s, n in keys
             if variant.get((s, n, "full")) and default.get((s, n, "baseline"))]
    lines = ["- mean change of the medians against the default (" + label + "): "
             + ", ".join(f"{m} {sum(v) / len(v):+.2f} dB (worst {min(v):+.2f})" for m, v in change.items() if v)]
    if mixed:
        lines.append(f"- {label} in the full method only, against the default baseline: mean {sum(mixed) / len(mixed):+.2f} dB, "
                     f"worst {min(mixed):+.2f} dB over {len(mixed)} cases")
    return lines


def session40_tables(results: Path) -> list[list[str]]:
    """Session 40's tables (module docstring), for the summaries present: each variant of the binocular partner
    beside the default it changes, both methods (their full - baseline in the last column), then DTU's and fern's
    runs beside their defaults."""
    d40 = results / "s40"
    out = []
    for prefix, label in (("p", "path partner"), ("h", "path partner, reach 0.25"),
                          ("b", "binocular term from 0.25 of the run")):
        path = d40 / f"{prefix}.txt"
        if path.is_file():
            default, variant = session37_default(results), load(path, prefix)
            out.append([f"{label}, 384x256, 3000 it, seeds 0-2, against session 37's default:", ""]
                       + table([("session 37 default", default), (label, variant)]) + change_lines(default, variant, label))
            out.append(named_beside_defaults(results, path, [f"{prefix}_{scene}_{m}" for scene in ("dtu", "fern")
                                                             for m in ("baseline", "full")]))
    if (d40 / "i.txt").is_file():
        default, variant = session38_images4(results), load(d40 / "i.txt", "i")
        out.append(["path partner at images_4 (768x512, 10,000 it), seeds 0-2, against session 38's default:", ""]
                   + table([("session 38 default", default), ("path partner", variant)])
                   + change_lines(default, variant, "path partner"))
    return out


SCREEN41 = {"densify": "densify=false", "depth_weight": "depth_weight=0", "guidance": "guidance=render"}


def screen41(results: Path) -> dict:
    """{screen key: {(scene, views, method): {seed: psnr}}} of session 41's seed-0 screen (``s41/s.txt``, runs named
    ``s_KEY_scene_Nv_full_s0``; a key may hold an underscore)."""
    out: dict = {}
    for (name, views, method), seeds in load(results / "s41" / "s.txt", "s").items():
        key = next(k for k in SCREEN41 if name.startswith(k + "_"))
        out.setdefault(key, {})[(name[len(key) + 1:], views, method)] = seeds
    return out


def session43_tables(results: Path) -> list[list[str]]:
    """Session 43's tables (module docstring), for the summaries present: both methods stopping growth at 0.75 of the
    run (``m``) beside session 37's default; the full method's ``growth_budget`` 0 and 2.0 and
    ``strategy.grow_grad2d=0.0003`` (``b``, seed 0) and CoR-GS's pair (``c``, seed 0) as variants against it; DTU's
    and fern's runs beside their defaults."""
    d43 = results / "s43"
    out, names = [], []
    default = session37_default(results)
    if (d43 / "m.txt").is_file():
        late = load(d43 / "m.txt", "m")
        label = "growth stops at 0.75 of the run in both"
        out.append(["both methods stopping growth at 0.75 of the run (strategy.refine_stop_fraction=0.75 in the baseline, "
                    "full.refine_stop_fraction=0.75 in the full method), 384x256, 3000 it, seeds 0-2:", ""]
                   + table([("session 37 default", default), (label, late)]) + change_lines(default, late, label))
        names += [(d43 / "m.txt", f"m_{scene}_{m}") for scene in ("dtu", "fern") for m in ("baseline", "full")]
    if (d43 / "b.txt").is_file():
        labels = {"gb0": "growth_budget=0", "gb20": "growth_budget=2.0", "gg3": "grow_grad2d=0.0003"}
        variants = {labels.get(k, k): v for k, v in load_variants(d43 / "b.txt", "b").items()}
        out.append(["the full method with full.growth_budget 0 (no cap) and 2.0, and strategy.grow_grad2d=0.0003, "
                    "384x256, 3000 it, seed 0, against session 37's default (seed 0 and seeds 0-2):", ""]
                   + variant_table(seed0(default), variants, "default (session 37), seed 0")
                   + [""] + variant_table(default, variants, "default (session 37), seeds 0-2"))
        names += [(d43 / "b.txt", f"b_{k}_dtu_full") for k in labels]
    if (d43 / "c.txt").is_file():  # CoR-GS's pair
        variants = {"co_reg=true": load_variants(d43 / "c.txt", "c").get("cr", {})}
        out.append(["the full method with CoR-GS's pair (train.co_reg=true), 384x256, 3000 it, seed 0, against session 37's "
                    "default (seed 0):", ""] + variant_table(seed0(default), variants, "default (session 37), seed 0"))
        names += [(d43 / "c.txt", f"c_cr_dtu_{m}") for m in ("baseline", "full")]
    if names:
        out.append(named_beside_defaults(results, sorted({p for p, _ in names}), [n for _, n in names]))
    return out


S44_NAMES = [("a.txt", "a_off5_dtu_full"), ("a.txt", "a_off10_dtu_full"), ("a.txt", "a_bxy_dtu_baseline"),
             ("a.txt", "a_bxy_dtu_full"), ("a.txt", "a_both_dtu_full"), ("c.txt", "c_off5rw5_dtu_full"),
             ("c.txt", "c_off5pw5_dtu_full")]


def session44_tables(results: Path) -> list[list[str]]:
    """Session 44's DTU runs (module docstring) beside DTU's and fern's defaults, for the summaries present."""
    d44 = results / "s44"
    files = sorted({d44 / f for f, _ in S44_NAMES if (d44 / f).is_file()})
    if not files:
        return []
    return [named_beside_defaults(results, files, [n for _, n in S44_NAMES])]


def session42_tables(results: Path) -> list[list[str]]:
    """Session 42's tables (module docstring), for the summaries present: ``full.reliable_weight`` 5 and 2.5 and
    ``full.depth_weight=0`` (seed 0 from session 41's screen) against session 37's default, DTU beside its defaults."""
    d42 = results / "s42"
    variants, names = {}, []
    if (d42 / "w.txt").is_file():
        weights = {"rw50": "reliable_weight=5", "rw25": "reliable_weight=2.5"}
        variants.update({weights.get(k, k): v for k, v in load_variants(d42 / "w.txt", "w").items()})
        names += [(d42 / "w.txt", f"w_{k}_dtu_full") for k in weights]
    if (d42 / "d.txt").is_file():
        depth0 = {k: dict(v) for k, v in screen41(results).get("depth_weight", {}).items()}
        for key, seeds in load(d42 / "d.txt", "d").items():
            depth0.setdefault(key, {}).update(seeds)
        variants["depth_weight=0"] = depth0
        names.append((d42 / "d.txt", "d_dtu_full"))
    out = []
    default = session37_default(results)
    if variants:
        out.append(["the full method with full.reliable_weight (5, 2.5) and full.depth_weight=0, 384x256, 3000 it, the "
                    "seeds each has, against session 37's default:", ""] + variant_table(default, variants, "default (session 37)"))
    if (d42 / "x.txt").is_file():  # the paper's schedule, and its control without pseudo views
        out.append(["the full method with full.cycle_iterations=1000 (3000 baseline steps, then two cycles of 1000: 5000 "
                    "steps), seeds 0-2, and its control (the same 5000 steps without pseudo views, densification or the "
                    "inputs' depth prior), seed 0, against session 37's default (3000 steps):", ""]
                   + variant_table(default, {"cycle_iterations=1000": load(d42 / "x.txt", "x"),
                                             "its control, seed 0": load(d42 / "x.txt", "xc")}, "default (session 37)"))
        names.append((d42 / "x.txt", "x_dtu_full"))
        names.append((d42 / "x.txt", "xc_dtu_full"))
    if (d42 / "g.txt").is_file():  # the baseline with the full method's growth schedule
        both = with_baselines(default, load(d42 / "g.txt", "g"))
        label = "growth to strategy.refine_stop_iter in both"
        out.append(["both methods growing as the full method does (the baseline with strategy.refine_stop_fraction=0), "
                    "384x256, 3000 it, seeds 0-2:", ""] + table([("session 37 default", default), (label, both)])
                   + change_lines(default, both, label))
        names.append((d42 / "g.txt", "g_dtu_baseline"))
    if (d42 / "h.txt").is_file():  # the full method with the baseline's growth schedule
        half = merged({k: v for k, v in default.items() if k[2] == "baseline"}, load(d42 / "h.txt", "h"))
        label = "growth stops at half the run in both"
        out.append(["both methods growing as the baseline does (the full method with full.refine_stop_fraction=0.5), "
                    "384x256, 3000 it, seeds 0-2:", ""] + table([("session 37 default", default), (label, half)])
                   + change_lines(default, half, label))
        names.append((d42 / "h.txt", "h_dtu_full"))
    if names:  # DTU's runs in one table
        out.append(named_beside_defaults(results, sorted({p for p, _ in names}), [n for _, n in names]))
    return out


def session41_tables(results: Path) -> list[list[str]]:
    """Session 41's tables (module docstring), for the summaries present: each weight of ``full.path_consistency``
    as a variant of the full method against the default's baseline, then DTU's and fern's runs beside their defaults."""
    d41 = results / "s41"
    names = {"pc10": "path_consistency=1.0", "pc03": "path_consistency=0.3"}
    out = []
    if (d41 / "c.txt").is_file():
        variants = {names.get(k, k): v for k, v in load_variants(d41 / "c.txt", "c").items()}
        out.append(["the full method with full.path_consistency, 384x256, 3000 it, seeds 0-2, against session 37's "
                    "default:", ""] + variant_table(session37_default(results), variants, "default (session 37)"))
        out.append(named_beside_defaults(results, d41 / "c.txt",
                                         [f"c_{k}_{scene}_full" for k in names for scene in ("dtu", "fern")]))
    if (d41 / "b.txt").is_file() and (d41 / "c.txt").is_file():  # the term in both methods
        default, full = session37_default(results), load_variants(d41 / "c.txt", "c")
        for k, base in sorted(load_variants(d41 / "b.txt", "b").items()):
            both = merged(base, full.get(k, {}))
            label = f"{names.get(k, k)} in both methods"
            out.append([f"{label} (train.path_consistency in the baseline), 384x256, 3000 it, seeds 0-2:", ""]
                       + table([("session 37 default", default), (label, both)]) + change_lines(default, both, label))
        out.append(named_beside_defaults(results, d41 / "b.txt",
                                         [f"b_{k}_{scene}_baseline" for k in names for scene in ("dtu", "fern")]))
    if (d41 / "s.txt").is_file():  # the seed-0 screen of the full method's parts
        variants = {SCREEN41[k]: v for k, v in screen41(results).items()}
        out.append(["the full method's parts, seed 0 (full.densify=false, full.depth_weight=0, full.guidance=render), "
                    "384x256, 3000 it, against session 37's default at seed 0:", ""]
                   + variant_table(seed0(session37_default(results)), variants, "default (session 37), seed 0"))
        out.append(named_beside_defaults(results, d41 / "s.txt", [f"s_{k}_dtu_full" for k in SCREEN41]))
    if (d41 / "i.txt").is_file():
        out.append(["the full method with full.path_consistency=1.0 at images_4 (768x512, 10,000 it), seeds 0-2, against "
                    "session 38's default:", ""]
                   + variant_table(session38_images4(results), {names["pc10"]: load(d41 / "i.txt", "i")},
                                   "default (session 38)"))
    return out


def with_baselines(default: dict, baselines: dict) -> dict:
    """``default`` with its baseline runs replaced by ``baselines``' where those have the case (the full runs and the
    other cases' baselines stay)."""
    out = {k: v for k, v in default.items() if not (k[2] == "baseline" and k in baselines)}
    out.update({k: v for k, v in baselines.items() if k[2] == "baseline"})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument("--session", type=int, choices=(20, 21, 22, 26, 27, 28, 29, 30, 31, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44),
                    default=21)
    args = ap.parse_args(argv)
    tables = {40: session40_tables, 41: session41_tables, 42: session42_tables, 43: session43_tables, 44: session44_tables}
    if args.session in tables:
        got = tables[args.session](Path(args.results))
        print("\n\n".join("\n".join(t) for t in got) or f"no s{args.session} summaries yet")
        return 0
    if args.session == 39:
        import seed_medians as sm
        res = Path(args.results)
        print("the full method at pseudo weight 0.1 against session 37's default, 0.2 (384x256, 3000 it, seeds 0-2):")
        print()
        print("\n".join(variant_table(session37_default(res), {"pseudo_weight=0.1": load(res / "s39" / "x.txt", "x")},
                                    "default (session 37)")))
        runs = sm.read([res / "s36" / "c.txt", res / "s37" / "t.txt", res / "s39" / "x.txt"])
        print()
        print("\n".join(sm.table({k: v for k, v in runs.items() if "dtu" in k})))
        return 0
    if args.session == 38:
        res = Path(args.results)
        default = session37_default(res)
        names = {"c3": "cycles=3", "bf6": "baseline_fraction=0.6"}
        variants = load_variants(res / "s38" / "v.txt", "v")
        print("the full method's variants against session 37's default (384x256, 3000 it, seeds 0-2):")
        print()
        print("\n".join(variant_table(default, {names[k]: v for k, v in variants.items()}, "default (session 37)")))
        print()
        print("images_4 (768x512, 10,000 it), seeds 0-2: session 36's default (full at pseudo weight 1, seed 0) and "
              "session 37's:")
        print()
        print("\n".join(seed_table(seed0(load(res / "s36" / "g.txt", "g")),
                                  seed0(session38_images4(res)))))
        print()
        print("\n".join(table([("images_4, session 37 default", session38_images4(res))])))
        print()
        print("\n".join(session38_named_table(res)))
        return 0
    if args.session == 37:
        res = Path(args.results)
        default = session36_default(res)
        names = {"s": "binocular_start=0.2 (both methods)", "p": "pseudo_weight=0.2", "bf": "baseline_fraction=0.6",
                 "sp": "binocular_start=0.2 + pseudo_weight=0.2", "r": "full refine_stop_fraction=0.5"}
        variants = load_variants(res / "s37" / "t.txt", "t")
        print("variants against session 36's default (384x256, 3000 it; p and sp seeds 0-2, the rest seed 0):")
        print()
        print("\n".join(variant_table(default, {names[k]: v for k, v in variants.items()}, "default (session 36)")))
        print()
        print("seed 0 only, against session 36's default at seed 0:")
        print()
        seed0_variants = {names[k]: seed0(v) for k, v in variants.items()}
        seed0_variants.update(load_weights(res / "s37" / "w.txt"))
        print("\n".join(variant_table(seed0(default), seed0_variants, "default (session 36), seed 0")))
        print()
        print("\n".join(table([("session 36 default", default), ("session 37 default", session37_default(res))])))
        print()
        print("\n".join(named_variant_table(res, names)))
        return 0
    if args.session == 36:
        res = Path(args.results)
        before = with_baselines(session28_default(res), load(res / "s35" / "r.txt", "r"))
        switched = load_switched(res / "s36" / "b_all.txt", "b")
        print("\n".join(table([("session 35 default", before), ("decay + binocular", switched["db"])])))
        print()
        print("seed 0, each switch alone and both (384x256, 3000 it):")
        print()
        for sw, label in (("dec", "opacity decay"), ("bin", "binocular"), ("db", "both")):
            print(f"{label}:")
            print("\n".join(seed_table(seed0(before), seed0(switched[sw]))))
            print()
        before4 = with_baselines(images4_default(res), load(res / "s35" / "c69.txt", "c"))
        print("images_4 (768x512, 10,000 it), seed 0: the session 35 default -> decay + binocular:")
        print()
        print("\n".join(seed_table(seed0(before4), load(res / "s36" / "g.txt", "g"))))
        return 0
    if args.session == 35:
        r35 = Path(args.results) / "s35"
        print("\n".join(table([("session 28 default", session28_default(Path(args.results))),
                               ("growth stopped at 1500", load(r35 / "r.txt", "r"))])))
        if (r35 / "c69.txt").is_file():
            print()
            print("\n".join(table([("images_4 default", images4_default(Path(args.results))),
                                   ("growth stopped at 5000", load(r35 / "c69.txt", "c"))])))
        return 0
    if args.session == 34:
        variants = load_variants(Path(args.results) / "s34" / "p369.txt", "p")
        names = {"pert10": "perturb_candidates=5, sigma 0.1", "pert30": "perturb_candidates=5, sigma 0.3"}
        print("\n".join(variant_table(session28_default(Path(args.results)),
                                       {names.get(k, k): v for k, v in variants.items()}, "default (session 28)")))
        return 0
    if args.session == 33:
        d = load(Path(args.results) / "s33" / "d369.txt", "d")
        print("\n".join(variant_table(images4_default(Path(args.results)), {"baseline_fraction=0.2": d},
                                       "default (images_4)")))
        return 0
    if args.session == 31:
        r30, r31 = (Path(args.results) / f"s{n}" for n in (30, 31))
        new = merged(load(r30 / "i369.txt", "i"), load(r31 / "j369.txt", "j"))
        print("\n".join(table([("spline, 3 poses (session 28)", images4_default(Path(args.results))),
                               ("both paths, 9 poses (session 30)", new)])))
        return 0
    r20, r21 = Path(args.results) / "s20", Path(args.results) / "s21"
    s20 = ("session 20 default", load(r20 / "captures_d.txt", "d"))
    s21 = merged(load(r21 / "captures_default3.txt", "d"), load(r21 / "captures_default69.txt", "d"))
    if args.session == 22:
        r22 = Path(args.results) / "s22"
        x, w = load_variants(r22 / "weak_part1.txt", "x"), load_variants(r22 / "wide_full.txt", "w")
        variants = {v: merged(x.get(v, {}), w.get(v, {})) for v in x.keys() | w.keys()}
        print("\n".join(variant_table(s21, variants)))
        print()
        print("\n".join(table([("SfM start (session 21)", merged(load(r21 / "a768_10k_3v.txt", "a"),
                                                                 load(r22 / "a768_sfm.txt", "n"))),
                               ("stereo start, held (session 22)", load(r22 / "a768_views.txt", "m"))])))
        return 0
    if args.session == 26:
        r26 = Path(args.results) / "s26"
        s26 = merged(load(r26 / "a3.txt", "a"), load(r26 / "c69.txt", "c"))
        print("\n".join(table([("session 21 default", s21), ("session 26 default", s26)])))
        print()
        rel = merged(load(r26 / "r3.txt", "r"), load(r26 / "r69.txt", "r"))
        print("\n".join(variant_table(s26, {"pseudo_mask=reliable": rel}, "default (session 26)")))
        return 0
    if args.session in (28, 29, 30):
        r27, r28 = Path(args.results) / "s27", Path(args.results) / "s28"
        default = session28_default(Path(args.results))
        if args.session == 30:
            r30 = Path(args.results) / "s30"
            print("\n".join(table([("session 28 default", default), ("both paths, 9 poses", load(r30 / "b369.txt", "b"))])))
            print()
            names = {"n17": "n_frames=17", "pw2": "pseudo_weight=2"}
            variants = load_variants(r30 / "x3.txt", "x")
            print("\n".join(variant_table(default, {names[k]: v for k, v in variants.items()}, "default (session 28)")))
            print()
            print("\n".join(seed_table(load(r28 / "i369.txt", "i"), load(r30 / "i369.txt", "i"))))
            return 0
        if args.session == 29:
            r29 = Path(args.results) / "s29"
            variants = merged(load_variants(r29 / "v369.txt", "v"), load_variants(r29 / "w_pw05.txt", "v"))
            names = {"c3": "cycles=3", "bf03": "baseline_fraction=0.3", "pw05": "pseudo_weight=0.5"}
            print("\n".join(variant_table(default, {names[k]: v for k, v in variants.items()},
                                           "default (session 28)")))
            return 0
        cyl = load(r28 / "c369.txt", "c")
        print("\n".join(table([("session 27 default", load(r27 / "h.txt", "h")),
                               ("far_field_proxy=auto", cyl), ("session 28 default", default)])))
        print()
        print("\n".join(variant_table(cyl, {"pseudo_mask=all": load(r28 / "m369.txt", "m")}, "far_field_proxy=auto")))
        return 0
    if args.session == 27:
        r26, r27 = Path(args.results) / "s26", Path(args.results) / "s27"
        s26 = merged(load(r26 / "a3.txt", "a"), load(r26 / "c69.txt", "c"))
        blur = merged(load(r27 / "f3.txt", "f"), load(r27 / "f369.txt", "f"))
        fixed = load(r27 / "h.txt", "h")
        print("\n".join(table([("session 26 default (session 24's forward)", s26),
                               ("session 27 default (forward fixed)", fixed)])))
        print()
        variants = {"pseudo_mask=all": merged(load(r27 / "m3.txt", "m"), load(r27 / "m369.txt", "m")),
                    "cycles=1": load(r27 / "y369.txt", "y")}
        print("\n".join(variant_table(s26, variants, "default (session 26)")))
        print()
        print("\n".join(table([("session 26 default", s26),
                               ("far_field_blur=1, pseudo_mask=all", load(r27 / "g3.txt", "g")),
                               ("far_field_blur=1", blur)])))
        print()
        print("\n".join(table([("session 26 default", {k: v for k, v in s26.items() if k[1] == 3}),
                               ("opacity_noise=0.8", load(r27 / "n3.txt", "n"))])))
        return 0
    if args.session == 20:
        cols = [("session 19 default", load(r20 / "path_floaters.txt", "p", "0")),
                ("+ path floaters", load(r20 / "path_floaters.txt", "p", "10")), s20]
    else:
        cols = [s20, ("session 21 default", s21)]
    print("\n".join(table(cols)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
