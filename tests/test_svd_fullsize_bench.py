"""bench/perf/svd_fullsize.py's pure parts (the GPU phases run on the device machine): its phases' arguments,
the run summary from a metrics.json, and the table of the JSON it wrote."""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.perf import svd_fullsize as bench  # noqa: E402


def test_phases_and_their_arguments():
    a = bench.parse(["stages"])
    assert a.offloads == ["none", "model", "sequential"] and (a.height, a.width, a.frames) == (576, 1024, 25)
    a = bench.parse(["stages", "model", "--size", "320x576"])
    assert a.offloads == ["model"] and (a.height, a.width) == (320, 576)
    with pytest.raises(SystemExit):
        bench.parse(["stages", "disk"])
    a = bench.parse(["run", "castle_p30", "9", "--offload", "model", "--set", "pseudo.sampler.steps=10"])
    assert (a.scene, a.views, a.offload, a.iterations, a.set) == ("castle_p30", 9, "model", 10000,
                                                                 ["pseudo.sampler.steps=10"])
    assert bench.parse(["runs9"]).offload is None


def test_run_summary_and_table(tmp_path, monkeypatch):
    monkeypatch.setenv("OUT", str(tmp_path))
    metrics = {"psnr": 21.5, "num_gaussians": 1000, "peak_cuda_allocated_mb": 9000.0, "train_time_s": 200.0,
               "cycles": [{"cycle": 0, "train_s": 80.0},
                          {"cycle": 1, "pseudo_views_s": 40.0, "pseudo_trajectories": 8, "pseudo_per_trajectory_s": 4.9,
                           "pseudo_denoise_s": 30.0, "densify_s": 3.0, "train_s": 50.0, "psnr": 20.0}]}
    row = bench.summarise_run(metrics, 280.04)
    assert row["wall_s"] == 280.0 and row["peak_mb"] == 9000.0 and len(row["cycles"]) == 1
    assert row["cycles"][0] == {"pseudo_views_s": 40.0, "pseudo_trajectories": 8, "pseudo_per_trajectory_s": 4.9,
                                "pseudo_denoise_s": 30.0, "densify_s": 3.0, "train_s": 50.0}
    assert bench.summarise_run(None, 5.0) == {"wall_s": 5.0, "metrics": False}
    bench.write("run_castle_p30_9v.json", {"scene": "castle_p30", "views": 9, "offload": "none", "exit_code": 0, **row})
    traj = {"total_s": 30.0, "denoise_s": 25.0, "denoise_peak_mb": 12000.0, "decode_s": 2.0, "decode_peak_mb": 8000.0}
    bench.write("stages_none.json", {"options": {"none": {"trajectories": [traj], "peak_mb": 12000.0}}})
    table = bench.summary()
    assert "| none | 0.0 / 0 | 0.0 / 0 | 25.0 / 12000 | 2.0 / 8000 | 30.0 | 12000 |" in table
    assert "| castle_p30 9v none | 0 | 280.0 | 21.5 | 9000.0 | 40.0 | 4.9 |" in table
