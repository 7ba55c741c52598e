"""The benchmark suite (bench/suite.py) end to end on a tiny preset: runs, reuse, JSON, charts, summary; the
switches preset of issue 14 and its table (bench/switch_table.py) on a fake results.json."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench import suite  # noqa: E402


def test_suite_runs_records_and_charts(tmp_path, monkeypatch):
    tiny = ["--set", "model.init_num=300", "--set", "eval.fps_repeats=1", "--set", "eval.save_images=false"]
    runs = [suite.Run("syn_base_10", "synthetic", "baseline", 10, tiny, "baseline"),
            suite.Run("syn_base_20", "synthetic", "baseline", 20, tiny, "baseline"),
            suite.Run("syn_bad", "synthetic", "baseline", 10, tiny + ["--set", "model.init=nonsense"], "broken")]
    monkeypatch.setitem(suite.PRESETS, "tiny", runs)
    out, work = tmp_path / "out", tmp_path / "work"
    records = suite.run_suite("cpu", "tiny", out, work, jobs=2, log=lambda *a: None)
    by = {r["run"]["name"]: r for r in records}
    assert [r["run"]["name"] for r in records] == ["syn_base_10", "syn_base_20", "syn_bad"]
    assert by["syn_bad"]["status"] == "failed" and "nonsense" in by["syn_bad"]["log_tail"]
    for name in ("syn_base_10", "syn_base_20"):
        m = json.loads((work / name / "metrics.json").read_text())
        rec = by[name]["metrics"]
        assert by[name]["status"] == "finished" and rec["psnr"] == m["psnr"] and rec["iterations"] == m["iterations"]
        assert [c["step"] for c in rec["curve"]] == list(range(suite.eval_every(by[name]["run"] and runs[0]),
                                                                m["iterations"] + 1, suite.eval_every(runs[0])))[:len(rec["curve"])]
    saved = json.loads((out / "results.json").read_text())
    assert len(saved["records"]) == 3
    for f in ("psnr_vs_time.png", "psnr_vs_gaussians.png"):
        assert (out / f).stat().st_size > 1000
    summary = (out / "summary.md").read_text()
    assert f"| baseline | 20 | {by['syn_base_20']['metrics']['psnr']:.2f} |" in summary
    assert "syn_bad" in summary  # the failure is listed
    # a second call reuses finished runs instead of training again
    again = suite.run_suite("cpu", "tiny", out, work, jobs=1, only=["syn_base_10"], log=lambda *a: None)
    assert again[0].get("reused") and again[0]["metrics"]["psnr"] == by["syn_base_10"]["metrics"]["psnr"]
    # --ray: the same records through the batch runner (nothing left to run, so Ray is not even started)
    if importlib.util.find_spec("ray") is not None:
        import ray

        again = suite.run_suite("cpu", "tiny", out, work, jobs=1, only=["syn_base_20"], log=lambda *a: None, ray=True)
        assert again[0].get("reused") and again[0]["metrics"] == by["syn_base_20"]["metrics"]
        assert not ray.is_initialized()
    # a run stopped after its checkpoint (a call's time limit) goes on from it instead of starting again
    assert (work / "syn_base_20" / "checkpoint.pt").is_file()
    (work / "syn_base_20" / "metrics.json").unlink()
    again = suite.run_suite("cpu", "tiny", out, work, jobs=1, only=["syn_base_20"], log=lambda *a: None)
    assert again[0]["status"] == "finished" and again[0].get("resumed") and not again[0].get("reused")
    assert again[0]["metrics"]["psnr"] == by["syn_base_20"]["metrics"]["psnr"]
    assert "resum" in (work / "syn_base_20.log").read_text().lower()


def test_runs_are_spread_over_the_visible_gpus_with_each_holding_its_share(tmp_path, monkeypatch):
    """On a machine of several GPUs (bench/gpu_session38.sh's two H200s) each run gets one GPU through
    CUDA_VISIBLE_DEVICES, every GPU is used, and none holds more than its share of --jobs at a time."""
    import threading
    import time

    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "3,5")
    assert suite.visible_gpus() == ["3", "5"] and suite.visible_gpus(1) == ["3"]
    runs = [suite.Run(f"r{i}", "synthetic", "baseline", 10, [], "baseline", seed=i) for i in range(12)]
    monkeypatch.setitem(suite.PRESETS, "tiny", runs)
    lock, busy, peak, seen = threading.Lock(), {}, {}, []

    def fake_execute(run, device, work, data_root, fresh, gpu=None, deadline=None):
        with lock:
            busy[gpu] = busy.get(gpu, 0) + 1
            peak[gpu] = max(peak.get(gpu, 0), busy[gpu])
            seen.append(gpu)
        time.sleep(0.02)
        with lock:
            busy[gpu] -= 1
        return {"run": suite.asdict(run), "device": device, "out": str(work / run.name), "status": "failed",
                "returncode": 1, "log_tail": "", "gpu": gpu}

    monkeypatch.setattr(suite, "execute", fake_execute)
    monkeypatch.setattr(suite, "write_reports", lambda records, info, out: [])
    records = suite.run_suite("cuda", "tiny", tmp_path / "out", tmp_path / "work", jobs=4, log=lambda *a: None)
    assert len(records) == 12 and sorted(set(seen)) == ["3", "5"]
    assert set(peak) == {"3", "5"} and max(peak.values()) == 2 and all(v <= 2 for v in peak.values()), peak  # 4 at a time, 2 per GPU
    assert json.loads((tmp_path / "out" / "results.json").read_text())["info"]["gpus"] == 2
    seen.clear()
    suite.run_suite("cuda", "tiny", tmp_path / "out", tmp_path / "work", jobs=4, log=lambda *a: None, gpus=1)
    assert set(seen) == {None}  # one GPU: the runs see what the suite sees


def test_a_time_limit_stops_the_runs_at_their_checkpoints_and_leaves_the_rest(tmp_path, monkeypatch):
    """--time-limit (a device call's limit): the run still going is stopped as Ctrl-C stops it (it writes its
    checkpoint, and the next call goes on from there), the run not started is left out of this call's records."""
    tiny = ["--set", "model.init_num=300", "--set", "eval.fps_repeats=1", "--set", "eval.save_images=false"]
    runs = [suite.Run("long", "synthetic", "baseline", 100000, tiny, "baseline"),
            suite.Run("queued", "synthetic", "baseline", 10, tiny, "baseline")]
    monkeypatch.setitem(suite.PRESETS, "tiny", runs)
    out, work = tmp_path / "out", tmp_path / "work"
    records = suite.run_suite("cpu", "tiny", out, work, jobs=1, log=lambda *a: None, time_limit=25)
    assert [r["run"]["name"] for r in records] == ["long"]
    assert records[0]["status"] == "stopped" and records[0]["returncode"] == 130, records[0]
    assert (work / "long" / "checkpoint.pt").is_file() and not (work / "long" / "metrics.json").exists()
    assert "Continue with" in (work / "long.log").read_text()
    assert not (work / "queued").exists()


# ----------------------------------------------------------------------------------------------
# issue 14: the switches preset and its table


def test_switches_preset_covers_every_case_switch_and_seed():
    from warpgs.pipelines.sparse import build_parser

    runs = suite.PRESETS["switches"]
    assert len(runs) == len(suite.SWITCH_CASES) * len(suite.SWITCHES) * len(suite.SWITCH_SEEDS) == 510
    assert {(r.case, r.label, r.seed) for r in runs} == {(c, s, k) for c in suite.SWITCH_CASES
                                                          for s in suite.SWITCHES for k in suite.SWITCH_SEEDS}
    assert len({r.name for r in runs}) == len(runs)
    for r in runs:  # the command line parses, and each --set is known to the config or is the co-reg switch
        args = build_parser().parse_args(suite.sparse_args(r, "cuda", "/data"))
        assert args.seed == r.seed and args.method == r.method
        err = suite.config_error(r)
        assert err is None or "co_reg" in err, err
    castle = next(r for r in runs if r.case == "castle_p30_9v")
    assert castle.data == "dl3dv" and castle.iterations == 3000
    assert castle.args[:6] == ["--scene", "castle_p30", "--views", "9", "--downscale", "8"]
    # subsets: switches, scenes, seeds, a smaller budget; a name that selects nothing is an error naming it
    part = suite.select_runs(runs, "switches", only=["baseline", "full+drop"], scenes=["fern_3v", "synthetic"],
                             seeds=[1], iterations=40)
    assert [(r.case, r.label, r.seed, r.iterations) for r in part] == [
        ("synthetic", "baseline", 1, 40), ("synthetic", "full+drop", 1, 40),
        ("fern_3v", "baseline", 1, 40), ("fern_3v", "full+drop", 1, 40)]
    assert part[0].name == "synthetic_baseline_1000_s1_it40"
    with pytest.raises(ValueError, match="--scenes fern: not in preset switches"):
        suite.select_runs(runs, "switches", scenes=["fern"])
    with pytest.raises(ValueError, match="--seeds 7"):
        suite.select_runs(runs, "switches", seeds=[7])


def test_a_switch_the_config_does_not_know_is_a_failed_run_not_a_crash(tmp_path, monkeypatch):
    runs = [suite.Run("syn_unknown_s0", "synthetic", "baseline", 10, ["--set", "train.no_such_switch=true"],
                      "baseline+no_such_switch", "synthetic", 0)]
    monkeypatch.setitem(suite.PRESETS, "unknown", runs)
    out, work = tmp_path / "out", tmp_path / "work"
    records = suite.run_suite("cpu", "unknown", out, work, jobs=1, log=lambda *a: None)
    assert records[0]["status"] == "failed" and "unknown key 'no_such_switch'" in records[0]["log_tail"]
    assert not (work / "syn_unknown_s0").exists()  # refused before anything started
    saved = json.loads((out / "results.json").read_text())
    assert saved["records"][0]["status"] == "failed"


def _fake_record(case, label, method, seed, psnr, status="finished", time_s=100.0):
    rec = {"run": {"name": f"{case}_{label}_s{seed}", "data": "d", "method": method, "iterations": 3000,
                   "args": [], "label": label, "case": case, "seed": seed},
           "device": "cuda", "status": status, "machine": "NVIDIA H200", "date": "2026-12-01 10:00"}
    if status == "finished":
        rec["metrics"] = {"scene": case, "psnr": psnr, "ssim": 0.5, "num_gaussians": 1000 + seed,
                          "train_time_s": time_s, "device": "cuda", "iterations": 3000}
    else:
        rec["log_tail"] = "error: train (from --set train.co_reg=true): unknown key 'co_reg'"
    return rec


def _fake_results():
    """Two scenes, seeds 0-2: 'good' gains +0.5 and -0.2 dB (median +0.15: qualifies), 'harmful' +1.0 and
    -0.5 (a scene loses more than 0.3), 'flat' 0 and 0 (no rise), 'broken' failed everywhere."""
    base = {"a": [20.0, 20.4, 19.8], "b": [15.0, 15.1, 14.9]}
    shift = {"good": {"a": 0.5, "b": -0.2}, "harmful": {"a": 1.0, "b": -0.5}, "flat": {"a": 0.0, "b": 0.0}}
    records = []
    for case in ("a", "b"):
        for seed in range(3):
            records.append(_fake_record(case, "baseline", "baseline", seed, base[case][seed]))
            for label, d in shift.items():
                records.append(_fake_record(case, f"baseline+{label}", "baseline", seed, base[case][seed] + d[case],
                                            time_s=200.0 if label == "harmful" else 100.0))
            records.append(_fake_record(case, "baseline+broken", "baseline", seed, None, status="failed"))
    return {"info": {"preset": "switches", "device": "cuda", "device_name": "NVIDIA H200", "date": "2026-12-01 10:00"},
            "records": records}


def test_switch_table_and_the_default_selection_rule(tmp_path, capsys):
    from bench import switch_table

    data = _fake_results()
    verdicts = {v["switch"]: v for v in switch_table.select_defaults(data["records"])}
    assert set(verdicts) == {"baseline+good", "baseline+harmful", "baseline+flat", "baseline+broken"}
    good = verdicts["baseline+good"]
    assert good["qualifies"] and good["gains_db"] == pytest.approx({"a": 0.5, "b": -0.2})
    assert good["median_gain_db"] == pytest.approx(0.15) and good["worst_scene"] == "b"
    assert not verdicts["baseline+harmful"]["qualifies"] and "b loses 0.50 dB" in verdicts["baseline+harmful"]["why"]
    assert verdicts["baseline+harmful"]["time_ratio"] == pytest.approx(2.0)
    assert not verdicts["baseline+flat"]["qualifies"] and "does not rise" in verdicts["baseline+flat"]["why"]
    assert not verdicts["baseline+broken"]["qualifies"] and "not measured on a, b" in verdicts["baseline+broken"]["why"]
    # the markdown the README quotes: median [min, max] per scene, the gains, the verdict, machine and date
    path = tmp_path / "results.json"
    path.write_text(json.dumps(data))
    table = tmp_path / "table.md"
    assert switch_table.main([str(path), "--out", str(table)]) == 0
    text = table.read_text()
    assert text == capsys.readouterr().out
    assert "| switch | a | b | median gain (dB) | worst scene (dB) | time vs default | default? |" in text
    assert "| baseline | 20.00 [19.80, 20.40] | 15.00 [14.90, 15.10] | (default) |" in text
    assert "| baseline+good | 20.50 [20.30, 20.90] | 14.80 [14.70, 14.90] | +0.15 | -0.20 (b) | 1.00x | yes |" in text
    assert "| baseline+harmful |" in text and "| 2.00x | no |" in text
    assert "| baseline+broken | failed | failed | - | - | - | no |" in text
    assert "seeds 0, 1, 2; NVIDIA H200 (cuda); 2026-12-01" in text
    assert "- baseline+good: qualifies as the baseline default" in text
    # written beside the suite's outputs too
    paths = switch_table.write(data["records"], data["info"], tmp_path)
    assert [p.name for p in paths] == ["switches.md", "switches.json"]
    assert json.loads(paths[1].read_text())["verdicts"][0]["switch"] == "baseline+good"
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert switch_table.main([str(bad)]) == 2


def test_switch_table_replaces_only_the_text_between_the_readme_markers():
    from bench.switch_table import README_END, README_START, replace_between_markers

    doc = f"intro\n{README_START}\nold table\n{README_END}\noutro\n"
    new = replace_between_markers(doc, "| a | b |\n")
    assert new == f"intro\n{README_START}\n| a | b |\n{README_END}\noutro\n"
    assert replace_between_markers(new, "| a | b |\n") == new  # idempotent
    with pytest.raises(ValueError, match="no"):
        replace_between_markers("no markers here", "x")
    with pytest.raises(ValueError):
        replace_between_markers(f"{README_END} {README_START}", "x")


def test_switch_table_marker_names_which_of_two_readme_tables_it_rewrites(tmp_path, capsys):
    from bench import switch_table

    path = tmp_path / "results.json"
    path.write_text(json.dumps(_fake_results()))
    old_start, old_end = switch_table.markers("switch_table_old")
    readme = tmp_path / "README.md"
    doc = (f"{switch_table.README_START}\ncurrent\n{switch_table.README_END}\n"
           f"{old_start}\nold table\n{old_end}\n")
    readme.write_text(doc)
    assert switch_table.main([str(path), "--readme", str(readme), "--marker", "switch_table_old"]) == 0
    text = readme.read_text()
    assert text.startswith(f"{switch_table.README_START}\ncurrent\n{switch_table.README_END}\n")  # untouched
    assert "old table" not in text and "| baseline+good |" in text.split(old_start)[1]
    capsys.readouterr()
    assert switch_table.main([str(path), "--readme", str(readme), "--marker", "no_such_table"]) == 2
    assert "no <!-- no_such_table: start -->" in capsys.readouterr().err
