"""The benchmark suite (bench/quality/suite.py) end to end on a tiny preset: runs, reuse, JSON, charts, summary; the
same records through the batch runner on Ray; GPU slots; a time limit."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.quality import suite  # noqa: E402


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
    # a run stopped after its checkpoint (a call's time limit) goes on from it instead of starting again
    assert (work / "syn_base_20" / "checkpoint.pt").is_file()
    (work / "syn_base_20" / "metrics.json").unlink()
    again = suite.run_suite("cpu", "tiny", out, work, jobs=1, only=["syn_base_20"], log=lambda *a: None)
    assert again[0]["status"] == "finished" and again[0].get("resumed") and not again[0].get("reused")
    assert again[0]["metrics"]["psnr"] == by["syn_base_20"]["metrics"]["psnr"]
    assert "resum" in (work / "syn_base_20.log").read_text().lower()


def test_runs_are_spread_over_the_visible_gpus_with_each_holding_its_share(tmp_path, monkeypatch):
    """On a machine of several GPUs (two H200s, say) each run gets one GPU through
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


def test_finished_runs_go_through_the_batch_runner_without_starting_ray(tmp_path, monkeypatch):
    """--ray: a suite whose runs finished already gets the same records through the batch runner, and Ray is not
    even started (nothing is left to run)."""
    ray = pytest.importorskip("ray", reason="the batch runner needs Ray: pip install 'warpgs[ray]'")
    tiny = ["--set", "model.init_num=300", "--set", "eval.fps_repeats=1", "--set", "eval.save_images=false"]
    runs = [suite.Run("syn_base_10", "synthetic", "baseline", 10, tiny, "baseline")]
    monkeypatch.setitem(suite.PRESETS, "tiny", runs)
    out, work = tmp_path / "out", tmp_path / "work"
    first = suite.run_suite("cpu", "tiny", out, work, jobs=1, log=lambda *a: None)
    assert first[0]["status"] == "finished"
    again = suite.run_suite("cpu", "tiny", out, work, jobs=1, log=lambda *a: None, ray=True)
    assert again[0].get("reused") and again[0]["metrics"] == first[0]["metrics"]
    assert not ray.is_initialized()


def test_a_setting_the_config_does_not_know_is_a_failed_run_not_a_crash(tmp_path, monkeypatch):
    runs = [suite.Run("syn_unknown_s0", "synthetic", "baseline", 10, ["--set", "train.no_such_switch=true"],
                      "baseline+no_such_key", "synthetic", 0)]
    monkeypatch.setitem(suite.PRESETS, "unknown", runs)
    out, work = tmp_path / "out", tmp_path / "work"
    records = suite.run_suite("cpu", "unknown", out, work, jobs=1, log=lambda *a: None)
    assert records[0]["status"] == "failed" and "unknown key 'no_such_switch'" in records[0]["log_tail"]
    assert not (work / "syn_unknown_s0").exists()  # refused before anything started
    saved = json.loads((out / "results.json").read_text())
    assert saved["records"][0]["status"] == "failed"
