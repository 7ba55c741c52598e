"""What the main job says when its outputs cannot be written: a file system that fills during the run, an ``--out``
whose name is longer than the file system allows. Each ends with one ``error:`` line naming the path, exit code 2,
no traceback, and no partial checkpoint or temporary file left behind as if complete."""

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUN = [sys.executable, "-m", "warpgs.pipelines.sparse", "--method", "baseline", "--iterations", "30", "--device",
       "cpu", "--no-progress"]


def _sparse(*args, limit_bytes: int | None = None) -> subprocess.CompletedProcess:
    def small_files():  # the child may write no file larger than limit_bytes (EFBIG instead of SIGXFSZ)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return subprocess.run([*RUN, *args], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          preexec_fn=small_files if limit_bytes else None)


def _one_error_line(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-2000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, proc.stderr[-2000:]
    return errors[0]


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MB file system (tmpfs, as root); where mounting is not allowed, a 2 MB limit on each file the run writes
    (the same OS error path, EFBIG instead of ENOSPC)."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    mounted = os.geteuid() == 0 and subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
                                                   capture_output=True).returncode == 0
    yield mnt, (None if mounted else 2 << 20)
    if mounted:
        subprocess.run(["umount", str(mnt)], capture_output=True)


def test_a_run_on_a_full_file_system_ends_with_one_line_and_no_partial_checkpoint(small_disk):
    mnt, limit = small_disk
    out = mnt / "run"
    line = _one_error_line(_sparse("--out", str(out), limit_bytes=limit))
    assert str(out) in line and "cannot write" in line, line
    assert ("no space left" in line) if limit is None else ("larger than" in line or "write failed" in line), line
    left = sorted(p.name for p in out.iterdir())
    assert "checkpoint.pt" not in left and not any(".tmp" in name for name in left), left
    assert "metrics.json" not in left and "point_cloud.ply" not in left, left  # nothing that reads as complete


def test_an_out_folder_name_longer_than_the_file_system_allows_is_refused_before_any_work(tmp_path):
    out = tmp_path / ("x" * 300)
    proc = _sparse("--out", str(out))
    line = _one_error_line(proc)
    assert "longer than the file system allows" in line and "--out" in line, line
    assert "warpgs: synthetic" not in proc.stderr  # refused before the scene loaded


def test_a_read_only_out_folder_is_refused_naming_it(tmp_path):
    if os.geteuid() == 0:  # root writes through permission bits: a read-only bind is what stops it
        ro = tmp_path / "ro"
        ro.mkdir()
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(ro)],
                          capture_output=True).returncode != 0:
            pytest.fail("mount is not allowed here, and root ignores permission bits: nothing read-only to test")
        try:
            line = _one_error_line(_sparse("--out", str(ro / "run")))
        finally:
            subprocess.run(["umount", str(ro)], capture_output=True)
        assert "read-only" in line and str(ro / "run") in line, line
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        line = _one_error_line(_sparse("--out", str(ro / "run")))
        assert "permission denied" in line and str(ro / "run") in line, line
