"""Every command ends bad input the same way: one ``error: ...`` line naming what was wrong, exit code 2, no
traceback, and no work started (checked before the scene loads or Ray starts)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CASES = {
    "sparse: unknown flag": (["warpgs.pipelines.sparse", "--no-such-flag"], "--no-such-flag"),
    "sparse: no such data": (["warpgs.pipelines.sparse", "--data", "/no/such/scene"], "/no/such/scene"),
    "sparse: a device that does not exist": (["warpgs.pipelines.sparse", "--device", "tpu"], "tpu"),
    "sparse: CUDA asked for where there is none": (["warpgs.pipelines.sparse", "--device", "cuda:7"], "cuda:7"),
    "sparse: a value out of range": (["warpgs.pipelines.sparse", "--set", "train.iterations=-3"], "iterations"),
    "sparse: weights named that are not there": (["warpgs.pipelines.sparse", "--method", "full", "--svd-path",
                                                  "/no/such/svd"], "/no/such/svd"),
    "batch: unknown flag": (["warpgs.pipelines.batch", "--no-such-flag"], "--no-such-flag"),
    "batch: no such sweep file": (["warpgs.pipelines.batch", "--sweep", "/no/such/sweep.yaml", "--list"],
                                  "/no/such/sweep.yaml"),
    "batch: a device Ray cannot give": (["warpgs.pipelines.batch", "--data", "synthetic", "--device", "tpu",
                                         "--list"], "tpu"),
    "pseudo: unknown flag": (["warpgs.pipelines.pseudo", "--model", "run", "--no-such-flag"], "--no-such-flag"),
    "pseudo: no such model": (["warpgs.pipelines.pseudo", "--model", "/no/such/run"], "/no/such/run"),
    "viz: no such file": (["warpgs.viz", "/no/such/cloud.ply"], "/no/such/cloud.ply"),
    "viz: unknown flag": (["warpgs.viz", "cloud.ply", "--no-such-flag"], "--no-such-flag"),
    "view: no such run": (["warpgs.view", "/no/such/run"], "/no/such/run"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_error_line_and_exit_2(case):
    argv, named = CASES[case]
    proc = subprocess.run([sys.executable, "-m", *argv], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL)
    assert proc.returncode == 2, (case, proc.returncode, proc.stderr[-1500:])
    assert "Traceback" not in proc.stderr, proc.stderr[-1500:]
    errors = [line for line in proc.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1 and named in errors[0], (case, proc.stderr[-1500:])
    assert "warpgs: synthetic" not in proc.stderr  # refused before any scene loaded
