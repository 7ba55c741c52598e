"""bench/report: the generic variant-against-default report (compare.py) on synthetic run folders, batch results and
summaries, and the README's table (readme_tables.py) against medians computed here from the committed summaries."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench" / "report"))

import compare  # noqa: E402
import readme_tables  # noqa: E402
from markers import replace_between_markers  # noqa: E402


def _median(xs):
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else (s[n // 2 - 1] + s[n // 2]) / 2


def _run(folder: Path, name: str, **metrics) -> None:
    (folder / name).mkdir(parents=True)
    (folder / name / "metrics.json").write_text(json.dumps({"iterations": 100, **metrics}))


DEFAULT = {0: 20.0, 1: 21.5, 2: 19.0}
VARIANT = {0: 21.0, 1: 22.25}


def _batch(tmp_path: Path) -> Path:
    runs = tmp_path / "batch" / "runs"
    for s, p in DEFAULT.items():
        _run(runs, f"castle_p30_3v_full_s{s}", psnr=p, num_gaussians=1000 + s)
    for s, p in VARIANT.items():
        _run(runs, f"castle_p30_3v_full_s{s}_pw02", psnr=p, num_gaussians=900 + s)
    _run(runs, "castle_p30_3v_full_s0_other", psnr=5.0)  # another variant: not in this report
    _run(runs, "herz_jesus_p25_6v_baseline_s1", psnr=18.0)  # a default without the variant: no row
    (runs / "castle_p30_3v_full_s3").mkdir()  # a run still going: no metrics yet
    return tmp_path / "batch"


def test_a_variant_against_the_default_over_seeds(tmp_path, capsys):
    batch = _batch(tmp_path)
    assert compare.main([str(batch), "--variant", "pw02", "--metric", "psnr", "--metric", "num_gaussians",
                         "--json", str(tmp_path / "c.json"), "--md", str(tmp_path / "c.md")]) == 0
    text = capsys.readouterr().out
    rows = json.loads((tmp_path / "c.json").read_text())["rows"]
    assert [(r["key"], r["variant"], r["metric"]) for r in rows] == [("castle_p30_3v_full", "pw02", "psnr"),
                                                                     ("castle_p30_3v_full", "pw02", "num_gaussians")]
    psnr = rows[0]
    d, v = _median(DEFAULT.values()), _median(VARIANT.values())
    assert psnr["default"]["median"] == d and psnr["variant_runs"]["median"] == v and psnr["diff"] == pytest.approx(v - d)
    assert (psnr["default"]["min"], psnr["default"]["max"]) == (min(DEFAULT.values()), max(DEFAULT.values()))
    assert psnr["default"]["seeds"] == [0, 1, 2] and psnr["variant_runs"]["seeds"] == [0, 1]
    assert rows[1]["diff"] == pytest.approx(_median([900, 901]) - _median([1000, 1001, 1002]))
    line = (f"| castle_p30_3v_full | pw02 | psnr | {d:.2f} [{min(DEFAULT.values()):.2f}, {max(DEFAULT.values()):.2f}] | "
            f"{v:.2f} [{min(VARIANT.values()):.2f}, {max(VARIANT.values()):.2f}] | {v - d:+.2f} | 0-2 / 0,1 |")
    assert line in text and text == (tmp_path / "c.md").read_text()
    assert "other" not in text and "herz_jesus" not in text


def test_batch_results_and_committed_summaries_are_sources_too(tmp_path, capsys):
    batch = _batch(tmp_path)
    runs = compare.read_runs(batch)
    records = [{"name": n, "status": "finished", "metrics": m} for n, m in runs.items()]
    records.append({"name": "castle_p30_3v_full_s5_pw02", "status": "failed", "error": "x"})
    (tmp_path / "results.json").write_text(json.dumps({"runs": records}))
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"machine": "NVIDIA H200", "runs": {"castle_p30_3v_full_s4": {"psnr": 30.0}}}))
    rows = compare.compare(compare.pool([tmp_path / "results.json", summary]), ["pw02"])
    assert rows[0]["default"]["seeds"] == [0, 1, 2, 4] and rows[0]["variant_runs"]["seeds"] == [0, 1]
    assert rows[0]["default"]["median"] == _median([*DEFAULT.values(), 30.0])
    # the same run with other metrics in two sources is an error, not a silent pick
    summary.write_text(json.dumps({"runs": {"castle_p30_3v_full_s0": {"psnr": 1.0}}}))
    assert compare.main([str(batch), str(summary), "--variant", "pw02"]) == 2
    assert "castle_p30_3v_full_s0 is in two sources" in capsys.readouterr().err
    assert compare.main([str(batch), "--variant", "nothing"]) == 2


def test_run_names_split_into_key_seed_and_variant():
    assert compare.split_name("castle_p30_3v_full_s2", ["pw02"]) == ("castle_p30_3v_full", 2, None)
    assert compare.split_name("castle_p30_3v_full_s2_pw02", ["pw02"]) == ("castle_p30_3v_full", 2, "pw02")
    assert compare.split_name("castle_p30_3v_full_s2_pw02", []) is None  # a variant nobody asked for
    assert compare.split_name("lego_8v_baseline_s10_best", ["best", "pw02"]) == ("lego_8v_baseline", 10, "best")
    assert compare.split_name("fern_full", ["pw02"]) is None


def test_the_readme_table_is_the_committed_summaries_medians(tmp_path):
    results = ROOT / "bench" / "results"
    lines = readme_tables.rows(results)
    assert lines[0].startswith("| scene | setting | machine | seeds |") and len(lines) == 2 + 1 + 4 + 12
    by_source: dict[str, list[list[str]]] = {}
    for ln in lines[2:]:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        by_source.setdefault(cells[-1].strip("`"), []).append(cells)
    doc = json.loads((results / "quality" / "captures_384x256_h200.json").read_text())
    row = next(c for c in by_source["quality/captures_384x256_h200.json"] if c[0] == "castle_p30, 9 views")
    base = [m["psnr"] for n, m in doc["runs"].items() if n.startswith("castle_p30_9v_baseline_s")]
    full = [m["psnr"] for n, m in doc["runs"].items() if n.startswith("castle_p30_9v_full_s")]
    assert len(base) == len(full) == 3 and row[2] == doc["machine"] and row[3] == "0-2"
    assert row[4] == f"{_median(base):.2f} [{min(base):.2f}, {max(base):.2f}]"
    assert row[6] == f"{_median(full) - _median(base):+.2f}"
    noarg = json.loads((results / "quality" / "noarg_cpu.json").read_text())
    row = by_source["quality/noarg_cpu.json"][0]
    fulls = [s["full"]["psnr"] for s in noarg["per_seed"].values()]
    assert row[2] == noarg["machine"] and row[5] == f"{_median(fulls):.2f} [{min(fulls):.2f}, {max(fulls):.2f}]"
    best = next(c for c in by_source["quality/datasets_h200.json"] if c[1].startswith("best setting"))
    assert best[5] == "-" and best[6] == "-"
    # --write: only the text between the markers changes
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{readme_tables.START}\nold table\n{readme_tables.END}\nrest\n")
    assert readme_tables.main(["--write", str(readme)]) == 0
    assert readme.read_text() == f"intro\n{readme_tables.START}\n" + "\n".join(lines) + f"\n{readme_tables.END}\nrest\n"
    with pytest.raises(ValueError, match="no <!-- a: start -->"):
        replace_between_markers("no markers", "t", "<!-- a: start -->", "<!-- a: end -->")


def test_the_docs_tables_are_the_committed_results(tmp_path):
    import docs_tables

    results = ROOT / "bench" / "results"
    raster = docs_tables.rasterizer(results)
    doc = json.loads((results / "perf" / "rasterizer_vs_gsplat_fern_h200.json").read_text())
    c = doc["configs"][0]
    p = c["ratio_fwd_bwd_paired"]
    row = next(ln for ln in raster if f"{c['gaussians']:,} trained on fern | {c['width']}x{c['height']}" in ln)
    assert f"| {p['median']:.2f} [{p['min']:.2f}, {p['max']:.2f}] |" in row and doc["device"] in row
    assert len(raster) == 2 + sum(len(json.loads((results / n).read_text())["configs"]) for n, _ in docs_tables.RASTERIZER)
    speed = docs_tables.train_speed(results)
    doc = json.loads((results / "perf" / "train_speed_fern_h200.json").read_text())
    trainer = doc["loops"]["warpgs_trainer"]
    assert any(f"| warpgs_trainer | {trainer['seconds']:.2f} | {trainer['it_per_s']:.1f} |" in ln
               and doc["machine"]["gpu"] in ln for ln in speed)
    # --write fills every table's markers and leaves the rest of the file as it was
    md = tmp_path / "b.md"
    md.write_text("top\n" + "".join(f"{s}\nold\n{e}\nbetween\n" for s, e in map(docs_tables.markers, docs_tables.TABLES)))
    assert docs_tables.main(["--write", str(md)]) == 0
    text = md.read_text()
    assert text.startswith("top\n") and "old" not in text and text.count("between\n") == len(docs_tables.TABLES)
