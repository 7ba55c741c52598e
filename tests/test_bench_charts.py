"""bench/report/charts.py on hand-made batch folders: run names, how a run ended, medians over seeds, the compact
verdict, collecting a folder into a results file, and the one command that draws the charts and writes the
tables."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench" / "report"))

import charts  # noqa: E402


def test_run_names_split_into_scene_views_method_seed_and_variant():
    assert charts.parse_run_name("herz_jesus_p25_3v_full_s2") == \
        {"scene": "herz_jesus_p25", "views": 3, "method": "full", "seed": 2, "variant": ""}
    assert charts.parse_run_name("fern_3v_baseline_s0_no-opacity-decay")["variant"] == "no-opacity-decay"
    assert charts.parse_run_name("synthetic-room-0_baseline_s1_compact") == \
        {"scene": "synthetic-room-0", "views": None, "method": "baseline", "seed": 1, "variant": "compact"}
    with pytest.raises(ValueError):
        charts.parse_run_name("castle_p30_3v_s0")


@pytest.mark.parametrize("run, expected", [
    ({"psnr": 16.0, "initial_psnr": 8.0}, "ok"),
    ({"psnr": 7.5, "initial_psnr": 8.0}, "collapse"),
    ({"psnr": 16.0}, "unchecked"),
    ({"psnr": float("nan"), "initial_psnr": 8.0}, "non-finite"),
    ({"psnr": 12.0, "initial_psnr": 8.0, "stopped_early": {"reason": "out_of_memory", "step": 900}}, "out of memory"),
    ({"status": "failed", "oom": True}, "out of memory"),
    ({"psnr": 12.0, "initial_psnr": 8.0,
      "stopped_early": {"reason": "diverged", "step": 500, "cause": "the loss exploded (40x its median)"}}, "diverged"),
    ({"psnr": 12.0, "initial_psnr": 8.0,
      "stopped_early": {"reason": "diverged", "step": 500, "cause": "non-finite loss for 20 steps"}}, "non-finite"),
    ({"status": "failed", "error": "error: no scene at ../x"}, "failed"),
    ({"status": "failed", "error": "TrainingDiverged: nan gradients"}, "non-finite"),
])
def test_how_a_run_ended(run, expected):
    assert charts.classify(run) == expected


def _run(name, **figures):
    return {**charts.parse_run_name(name), "name": name, "status": "finished", **figures}


def test_points_are_medians_over_seeds_with_their_count():
    runs = [_run("fern_3v_full_s0", psnr=20.0, train_time_s=10.0, num_gaussians=100, param_bytes=2e6),
            _run("fern_3v_full_s1", psnr=23.0, train_time_s=30.0, num_gaussians=300, param_bytes=6e6),
            _run("fern_3v_full_s2", psnr=21.0, train_time_s=20.0, num_gaussians=200, param_bytes=4e6),
            _run("fern_3v_full_s0_drop0", psnr=19.0, train_time_s=12.0, num_gaussians=90),
            {**_run("fern_3v_full_s1_drop0", psnr=25.0), "status": "failed"}]  # not a point
    p = charts.points(runs)["fern 3v"]
    assert p["full"]["n"] == 3 and p["full"]["psnr"] == {"median": 21.0, "min": 20.0, "max": 23.0, "n": 3}
    assert p["full"]["train_time_s"]["median"] == 20.0 and p["full"]["num_gaussians"]["median"] == 200
    assert p["full"]["mb"]["median"] == pytest.approx(4.0)
    assert p["full+drop0"]["n"] == 1 and p["full+drop0"]["mb"] is None
    table = "\n".join(charts.speed_accuracy_table({"fern 3v": ({"machine": "M", "commit": "c0ffee", "file": "f.json",
                                                                  "date": ""}, p)}))
    assert "| fern 3v | full+drop0 | n=1 |" in table and "| fern 3v | full | 3 | 21.00 [20.00, 23.00] |" in table
    assert "M, commit c0ffee" in table


def test_the_compact_verdict_per_scene():
    runs = []
    for seed, (g, p, cg, cp) in enumerate([(100, 20.0, 40, 19.95), (110, 20.1, 50, 20.0), (90, 19.9, 45, 19.8)]):
        runs += [_run(f"castle_p30_3v_baseline_s{seed}", psnr=p, num_gaussians=g, param_bytes=g * 1000, iterations=3000),
                 _run(f"castle_p30_3v_baseline_s{seed}_compact", psnr=cp, num_gaussians=cg, param_bytes=cg * 500,
                      iterations=3000)]
    runs += [_run("fern_3v_baseline_s0", psnr=22.0, num_gaussians=1000, iterations=3000),
             _run("fern_3v_baseline_s0_compact", psnr=21.7, num_gaussians=600, iterations=3000),
             _run("lego_8v_baseline_s0", psnr=22.0, num_gaussians=1000, iterations=10000),   # other iterations:
             _run("lego_8v_baseline_s0_compact", psnr=22.0, num_gaussians=100, iterations=3000)]  # no pair
    by = {v["scene"]: v for v in charts.compact_verdicts(runs)}
    assert set(by) == {"castle_p30 3v", "fern 3v"}
    castle = by["castle_p30 3v"]
    assert castle["reduction"] == pytest.approx(1 - 45 / 100) and castle["psnr_change"] == pytest.approx(19.95 - 20.0)
    assert castle["mb_reduction"] == pytest.approx(1 - 45 * 500 / (100 * 1000))
    assert castle["met"] and castle["n"] == 3 and castle["why"] == ""
    fern = by["fern 3v"]
    assert not fern["met"] and fern["n"] == 1
    assert fern["why"] == "40% fewer Gaussians, short of 50%; loses 0.30 dB, more than 0.1 dB"


def test_stability_counts_leave_out_runs_cut_at_a_deadline():
    runs = [_run("castle_p30_3v_full_s0", psnr=15.0, initial_psnr=8.0),
            _run("castle_p30_3v_full_s1", psnr=7.0, initial_psnr=8.0),
            {**_run("castle_p30_3v_full_s2"), "status": "stopped"},
            {**_run("castle_p30_3v_baseline_s0"), "status": "failed", "oom": True}]
    counts = charts.stability_counts(runs)
    assert counts["full"]["ok"] == 1 and counts["full"]["collapse"] == 1 and sum(counts["full"].values()) == 2
    assert counts["baseline"]["out of memory"] == 1 and sum(counts["baseline"].values()) == 1


def test_the_sparse_inputs_panel_counts_the_newest_code_at_its_defaults():
    """The stability chart's real-input panel: each method's sparse runs at its defaults, of the newest machine and
    commit only: an older commit's runs (another code), a switch's or compact mode's (other settings) and a run of
    more views are left out."""
    def src(commit, date, runs):
        return {"file": f"{commit}.json", "kind": "runs", "machine": "NVIDIA H200", "commit": commit, "date": date,
                "runs": [{**charts.parse_run_name(n), "name": n, "psnr": p, "initial_psnr": 10.0} for n, p in runs]}

    old = src("aaa1111", "2026-11-28", [("castle_p30_3v_baseline_s0", 5.0), ("castle_p30_3v_baseline_s1", 5.0)])
    new = src("bbb2222", "2026-11-29", [("castle_p30_3v_baseline_s0", 15.0), ("herz_jesus_p25_2v_full_s0", 9.0),
                                        ("castle_p30_3v_baseline_s0_drop0", 5.0), ("synthetic_2v_full_s1", 12.0),
                                        ("castle_p30_3v_baseline_s1_compact", 5.0), ("castle_p30_9v_full_s0", 5.0)])
    (panel,) = charts.stability_panels([new, old]).values()
    assert panel["files"] == ["bbb2222.json"]
    assert panel["counts"]["baseline"]["ok"] == 1 and sum(panel["counts"]["baseline"].values()) == 1
    assert panel["counts"]["full"]["ok"] == 1 and panel["counts"]["full"]["collapse"] == 1
    assert sum(panel["counts"]["full"].values()) == 2


def test_each_chart_shows_the_newest_code_on_one_machine():
    """Older results of another commit or machine (a switch screen's scene, a one-seed compact pair) are not drawn
    beside the newest sweep's: the speed-accuracy and compact charts take the newest machine and commit only."""
    def src(machine, commit, when, runs):
        return {"file": f"{commit}.json", "kind": "runs", "machine": machine, "commit": commit, "date": when[:10],
                "when": when, "runs": [{**charts.parse_run_name(n), "name": n, "psnr": 15.0, "train_time_s": 9.0,
                                        "num_gaussians": g, "param_bytes": g} for n, g in runs]}

    old = src("2 x NVIDIA H200", "aaa1111", "2026-11-28 17:37", [("synthetic_baseline_s0", 900),
                                                                  ("synthetic_baseline_s0_compact", 100)])
    cpu = src("x86_64 CPU", "ccc3333", "2026-11-29 09:00", [("lego_8v_baseline_s0", 900)])
    new = src("NVIDIA H200", "bbb2222", "2026-11-29 22:10", [("castle_p30_3v_baseline_s0", 1000),
                                                              ("castle_p30_3v_baseline_s0_compact", 400)])
    assert list(charts.speed_accuracy_scenes([old, cpu, new])) == ["castle_p30 3v"]
    assert [v["scene"] for v in charts.all_compact_verdicts([old, cpu, new])] == ["castle_p30 3v"]
    assert charts.newest_code([old, cpu, new]) == [new]


def _batch_folder(tmp_path: Path) -> Path:
    """A batch folder as warpgs.pipelines.batch leaves it: finished runs, one stopped on running out of memory, one
    whose every attempt died, one cut at the deadline, one never started; each run's compact twin where it has one."""
    d = tmp_path / "sweep"
    runs, logs = d / "runs", d / "logs"
    logs.mkdir(parents=True)

    def finished(name, psnr, gaussians, extra=None):
        (runs / name).mkdir(parents=True)
        m = {"method": "baseline", "scene": "castle_p30", "psnr": psnr, "initial_psnr": 9.0, "num_gaussians": gaussians,
             "param_bytes": gaussians * 236, "train_time_s": 40.0 + gaussians / 1000, "iterations": 3000,
             "resolution": [384, 256], "recoveries": [{"step": 10}], "curve": [1, 2]}
        (runs / name / "metrics.json").write_text(json.dumps({**m, **(extra or {})}))
        (logs / f"{name}.attempts.jsonl").write_text(json.dumps({"attempt": 1, "start": 0}) + "\n"
                                                     + json.dumps({"attempt": 1, "end": 1, "returncode": 0, "oom": False}))
        (logs / f"{name}.log").write_text('Warp 1.9 initialized:\n   Devices:\n     "cpu"      : "x86_64"\n'
                                          '     "cuda:0"   : "NVIDIA H200" (140 GiB, sm_90)\n')

    for seed, (psnr, g) in enumerate([(16.0, 30000), (15.5, 32000), (16.2, 31000)]):
        finished(f"castle_p30_3v_baseline_s{seed}", psnr, g)
    finished("castle_p30_3v_full_s0", 15.0, 40000, {"stopped_early": {"reason": "out_of_memory", "step": 2000}})
    (runs / "castle_p30_3v_full_s1").mkdir(parents=True)  # its every attempt killed, out of memory
    (logs / "castle_p30_3v_full_s1.attempts.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for a in (1, 2, 3) for r in ({"attempt": a, "start": a},
                                                                 {"attempt": a, "end": a, "returncode": -9, "oom": True})))
    (logs / "castle_p30_3v_full_s1.log").write_text("torch.OutOfMemoryError: CUDA out of memory\n")
    (runs / "castle_p30_3v_full_s2").mkdir(parents=True)
    (logs / "castle_p30_3v_full_s2.attempts.jsonl").write_text(
        json.dumps({"attempt": 1, "start": 0}) + "\n" + json.dumps({"attempt": 1, "end": 5, "returncode": 143,
                                                                   "oom": False, "deadline": True}) + "\n")
    (logs / "castle_p30_9v_full_s0.argv.json").write_text("[]")
    (logs / "not a run name.argv.json").write_text("[]")
    return d


def test_collect_reads_every_run_of_a_batch_folder(tmp_path):
    doc = charts.collect(_batch_folder(tmp_path), "speed_accuracy", commit="abc1234")
    runs = doc["runs"]
    assert doc["machine"] == "NVIDIA H200" and doc["commit"] == "abc1234" and doc["seeds"] == [0, 1, 2]
    assert set(runs) == {f"castle_p30_3v_baseline_s{s}" for s in range(3)} | \
        {f"castle_p30_3v_full_s{s}" for s in range(3)} | {"castle_p30_9v_full_s0"}
    b0 = runs["castle_p30_3v_baseline_s0"]
    assert b0["status"] == "finished" and b0["psnr"] == 16.0 and b0["initial_psnr"] == 9.0 and b0["recoveries"] == 1
    assert b0["param_bytes"] == 30000 * 236 and "curve" not in b0 and b0["views"] == 3
    assert [runs[f"castle_p30_3v_full_s{s}"]["status"] for s in range(3)] == ["finished", "failed", "stopped"]
    assert runs["castle_p30_9v_full_s0"]["status"] == "not_started"
    assert [charts.classify(runs[n]) for n in ("castle_p30_3v_baseline_s0", "castle_p30_3v_full_s0",
                                               "castle_p30_3v_full_s1")] == ["ok", "out of memory", "out of memory"]
    assert "OutOfMemoryError" in runs["castle_p30_3v_full_s1"]["error"]


def test_machine_tags_name_the_gpu():
    assert charts.machine_tag("NVIDIA H200") == "h200"
    assert charts.machine_tag("NVIDIA H100 80GB HBM3") == "h100"
    assert charts.machine_tag("NVIDIA GeForce RTX 4090") == "4090"
    assert charts.machine_tag("x86_64 CPU") == "cpu"


def test_one_command_collects_charts_and_writes_the_tables(tmp_path):
    results, img = tmp_path / "results", tmp_path / "img"
    folder = _batch_folder(tmp_path)
    assert charts.main(["--collect", str(folder), "--name", "speed_accuracy", "--results", str(results),
                        "--commit", "abc1234"]) == 0
    # a compact sweep of the same machine and commit: its defaults are the speed-accuracy runs above
    comp = tmp_path / "compact"
    (comp / "logs").mkdir(parents=True)
    search = {"before": {"num_gaussians": 20000, "train_psnr": 20.5, "test_psnr": 15.95}, "best_train_psnr": 20.6,
              "tolerance_db": 0.1, "after": {"num_gaussians": 12000, "train_psnr": 20.52},
              "points": [{"kind": "prune", "ratio": 0.0, "num_gaussians": 20000, "train_psnr": 20.6, "test_psnr": 15.9,
                          "param_bytes": 1, "within_tolerance": True}],
              "pruned_during_training": [{"step": 1500, "removed": 5000}]}
    for seed, g in enumerate((12000, 13000)):
        r = comp / "runs" / f"castle_p30_3v_baseline_s{seed}_compact"
        r.mkdir(parents=True)
        r.joinpath("metrics.json").write_text(json.dumps({"psnr": 15.9, "num_gaussians": g, "param_bytes": g * 56,
                                                          "iterations": 3000, "resolution": [384, 256],
                                                          "compact": search}))
    assert charts.main(["--collect", str(comp), "--name", "compact", "--results", str(results), "--commit", "abc1234",
                        "--machine", "NVIDIA H200"]) == 0
    kept = json.loads((results / "compact_h200.json").read_text())["runs"]["castle_p30_3v_baseline_s0_compact"]["compact"]
    assert kept["before"] == search["before"] and kept["pruned_during_training"] == search["pruned_during_training"]
    assert kept["points"] == [{k: v for k, v in search["points"][0].items() if k != "param_bytes"}]
    assert sorted(p.name for p in results.iterdir()) == ["compact_h200.json", "speed_accuracy_h200.json"]
    doc = tmp_path / "benchmarks.md"
    doc.write_text("intro\n" + "".join(f"{a}\nold\n{b}\ntext\n" for a, b in map(charts.markers, ("speed_accuracy",
                                                                                                   "stability", "compact"))))
    assert charts.main(["--results", str(results), "--img", str(img), "--doc", str(doc)]) == 0
    text = doc.read_text()
    assert "old" not in text and text.startswith("intro\n") and text.count("text\n") == 3
    assert "| castle_p30 3v | baseline | 3 | 16.00 [15.50, 16.20] |" in text
    assert "| castle_p30 3v | full |" not in text  # stopped early (out of memory): its figures are no point
    assert "NVIDIA H200, commit abc1234" in text
    # stability: baseline 3 ok; full: one stopped on out of memory, one dead of it, one cut at the deadline (left out)
    row = next(ln for ln in text.splitlines() if ln.startswith("| captures at 2-3 views, room at 2 (defaults) | full |"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[2] == "2" and cells[3 + charts.CATEGORIES.index("out of memory")] == "2"
    # compact: median 12,500 against 31,000 Gaussians, 15.9 against 16.0 dB, over the 2 seeds both have
    row = next(ln for ln in text.splitlines() if ln.startswith("| castle_p30 3v | baseline | n=2 |"))
    assert f"{100 * (1 - 12500 / 31000):.1f}%" in row and "| -0.10 |" in row and "| met |" in row
    assert "| fern 3v | - | 0 |" in text and "| castle_p30 3v | - |" not in text  # the goal's scenes without a verdict
    assert sorted(p.name for p in img.iterdir()) == ["compact.png", "speed_accuracy_size.png",
                                                      "speed_accuracy_time.png", "stability.png"]


def test_the_committed_results_chart(tmp_path):
    tables, paths = charts.build(charts.RESULTS, tmp_path)
    assert paths and all(p.is_file() for p in paths)
    assert all(len(tables[k].splitlines()) > 2 for k in ("speed_accuracy", "stability", "compact"))


def test_a_compact_pair_of_bench_quality_compact_keeps_its_view_count(tmp_path):
    """bench/quality/compact.py's compact.json: with ``views`` its pair is that scene at that many views (the
    table's "castle_p30 3v" row, where the sweep's runs land too); documents without it are the scene alone."""
    def doc(**extra):
        run = {"psnr": 15.5, "num_gaussians": 4000, "param_bytes": 10, "iterations": 3000, "train_time_s": 1.0}
        return {"scene": "castle_p30", "method": "baseline", "device": "cpu", "default": run,
                "compact": {**run, "psnr": 15.4, "num_gaussians": 1500}, **extra}
    for folder, d in (("with", doc(views=3)), ("without", doc())):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "compact.json").write_text(json.dumps(d))
    sources = {Path(s["file"]).parent.name: s for s in charts.load_sources(tmp_path)}
    assert sorted(r["name"] for r in sources["with"]["runs"]) == ["castle_p30_3v_baseline_s0",
                                                                 "castle_p30_3v_baseline_s0_compact"]
    assert {r["views"] for r in sources["with"]["runs"]} == {3}
    assert {r["views"] for r in sources["without"]["runs"]} == {None}
    by = {v["scene"]: v for v in charts.compact_verdicts(sources["with"]["runs"])}
    assert set(by) == {"castle_p30 3v"}


def test_merge_fills_a_results_file_with_the_runs_of_a_later_call(tmp_path, capsys):
    results = tmp_path / "results"
    folder = _batch_folder(tmp_path)  # baseline s0-s2 finished; full s0 out of memory, s1 failed, s2 stopped
    assert charts.main(["--collect", str(folder), "--name", "sa", "--results", str(results), "--commit", "abc1234"]) == 0
    later = tmp_path / "later"
    for name, psnr in (("castle_p30_3v_full_s0", 17.0), ("castle_p30_3v_full_s2", 17.5)):
        (later / "runs" / name).mkdir(parents=True)
        (later / "runs" / name / "metrics.json").write_text(json.dumps({"psnr": psnr, "num_gaussians": 5}))
    (later / "runs" / "castle_p30_3v_baseline_s0").mkdir(parents=True)  # cut in the later call: the file's is kept
    (later / "logs").mkdir()
    (later / "logs" / "castle_p30_3v_baseline_s0.attempts.jsonl").write_text(json.dumps({"attempt": 1}) + "\n")
    assert charts.main(["--collect", str(later), "--name", "sa", "--results", str(results), "--commit", "abc1234",
                        "--machine", "NVIDIA H200", "--merge"]) == 0
    doc = json.loads((results / "sa_h200.json").read_text())
    runs = doc["runs"]
    assert runs["castle_p30_3v_full_s0"]["psnr"] == 17.0 and "stopped_early" not in runs["castle_p30_3v_full_s0"]
    assert runs["castle_p30_3v_full_s2"]["status"] == "finished" and runs["castle_p30_3v_full_s1"]["status"] == "failed"
    assert runs["castle_p30_3v_baseline_s0"]["psnr"] == 16.0  # the complete run is not replaced by a cut one
    assert len(runs) == 7 and len(doc["dates"]) == 2 and doc["commit"] == "abc1234"
    p = charts.points(list({**r, "name": n} for n, r in runs.items()))["castle_p30 3v"]
    assert p["full"]["n"] == 2 and p["full"]["psnr"]["median"] == 17.25
    # another commit is not merged into this file: one line, nothing written
    before = (results / "sa_h200.json").read_text()
    with pytest.raises(SystemExit):
        charts.main(["--collect", str(later), "--name", "sa", "--results", str(results), "--commit", "def5678",
                     "--machine", "NVIDIA H200", "--merge"])
    assert "the file's commit is 'abc1234'" in capsys.readouterr().err
    assert (results / "sa_h200.json").read_text() == before
