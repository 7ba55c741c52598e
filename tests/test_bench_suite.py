"""The benchmark suite (bench/suite.py) end to end on a tiny preset: runs, reuse, JSON, charts, summary."""

import importlib.util
import json
import sys
from pathlib import Path

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
