"""SIGTERM from outside (what ``timeout``, SLURM, Kubernetes and Ray's cancel send) stops the main job gracefully,
with the SfM initialisation through pycolmap and the svd backend in the run. pycolmap runs in a child process
(``warpgs.densify.native``): glog's native failure-signal handlers, which it installs, never reach the run's
process (imported there, its bundled zlib also frees PIL's PNG buffers twice: a native abort at the first PNG), and
the run's own handler takes SIGTERM. During training and during pseudo-view generation the run
during training and during pseudo-view generation the run finishes its step or trajectory, writes the checkpoint
and the model so far, says how to resume, and exits 143 without a native stack dump; ``--resume`` then ends with
the same metrics and the same PLY, byte for byte, as a run that was never stopped.

The child signals where it stands through marker files (``WARPGS_TEST_HOLD``): it writes ``<name>.at`` and waits for
``<name>.go``, so that the test's SIGTERM arrives exactly in the phase under test."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

DRIVER = r"""
import os, sys, time
from pathlib import Path
import warpgs.pseudo.backends as backends
from warpgs.engine.loop import Trainer
from warpgs.pipelines.sparse import main

hold, phase = os.environ.get("WARPGS_TEST_HOLD"), os.environ.get("WARPGS_TEST_PHASE")

def wait_here():
    Path(hold + ".at").write_text("")
    while not Path(hold + ".go").exists():
        time.sleep(0.02)

if phase == "training":
    step = Trainer.train_step
    def train_step(self):
        if self.step == 5 and not Path(hold + ".at").exists():
            wait_here()
        return step(self)
    Trainer.train_step = train_step
elif phase == "pseudo":
    denoise = backends.SVDBackend.denoise_batch  # the sampler's one UNet call per step
    def first_denoise(self, *a, **k):
        if not Path(hold + ".at").exists():
            wait_here()
        return denoise(self, *a, **k)
    backends.SVDBackend.denoise_batch = first_denoise
code = main(sys.argv[1:])
print(f"pycolmap in the run's process: {'pycolmap' in sys.modules}", file=sys.stderr)
sys.exit(code)
"""


@pytest.fixture(scope="module")
def tiny_svd(tmp_path_factory):
    from test_svd_tiny import build_tiny_svd

    return build_tiny_svd(tmp_path_factory.mktemp("svd") / "tiny")


def _args(out: Path, svd: Path, tmp: Path) -> list[str]:
    return ["--method", "full", "--device", "cpu", "--iterations", "30", "--seed", "0", "--no-progress",
            "--out", str(out), "--pseudo-backend", "svd", "--svd-path", str(svd),
            "--set", "train.checkpoint_every=5", "--set", "pseudo.svd.width=32", "--set", "pseudo.svd.height=32",
            "--set", "pseudo.trajectory.n_frames=4", "--set", "pseudo.sampler.steps=2", "--set", "full.cycles=1",
            "--set", "model.init=sfm", "--set", "model.init_num=300", "--set", "full.flythrough_frames=2", "--set", "eval.fps_repeats=1",
            "--set", "eval.save_images=false", "--set", f"eval.lpips_weights={tmp / 'none.pth'}"]


def _start(args: list[str], tmp: Path, phase: str | None) -> subprocess.Popen:
    env = dict(os.environ, WARPGS_TEST_HOLD=str(tmp / "hold"), WARPGS_TEST_PHASE=phase or "")
    return subprocess.Popen([sys.executable, "-c", DRIVER, *args], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _result(out: Path) -> tuple:
    m = json.loads((out / "metrics.json").read_text())
    return m["psnr"], m["ssim"], m["num_gaussians"], hashlib.sha256((out / "point_cloud.ply").read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def uninterrupted(tiny_svd, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("whole")
    proc = _start(_args(tmp / "run", tiny_svd, tmp), tmp, None)
    _, err = proc.communicate(timeout=900)
    assert proc.returncode == 0, err[-3000:]
    return _result(tmp / "run")


@pytest.mark.parametrize("phase", ["training", "pseudo"])
def test_sigterm_stops_gracefully_and_the_resumed_run_is_bit_exact(phase, tiny_svd, uninterrupted, tmp_path):
    out = tmp_path / "run"
    proc = _start(_args(out, tiny_svd, tmp_path), tmp_path, phase)
    marker = tmp_path / "hold.at"
    deadline = time.monotonic() + 600
    while not marker.exists():
        assert proc.poll() is None, proc.communicate()[1][-3000:]
        assert time.monotonic() < deadline, "the run never reached the phase under test"
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    time.sleep(0.3)  # the handler has run before the step or trajectory goes on
    (tmp_path / "hold.go").write_text("")
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 143, err[-3000:]
    for dump in ("*** Aborted", "SIGTERM received by PID", "*** SIG", "Traceback"):
        assert dump not in err, err[-3000:]
    assert "SIGTERM" in err and f"--resume {out}" in err, err[-3000:]
    assert "init sfm" in err and "pycolmap in the run's process: False" in err, err[-3000:]
    if phase == "pseudo":
        assert "pseudo-view generation stopped" in err, err[-3000:]
    assert (out / "checkpoint.pt").is_file() and (out / "point_cloud.ply").is_file()
    assert not (out / "metrics.json").exists()  # the run is not finished: a batch runner must resume it

    resumed = subprocess.run([sys.executable, "-m", "warpgs.pipelines.sparse", "--resume", str(out), "--no-progress"],
                             cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert _result(out) == uninterrupted
