"""Native steps in a child process (warpgs/densify/native.py): a child killed by SIGSEGV or SIGABRT, or one that
hangs, becomes one line and the step's documented fallback, and this process lives on. The faults are real: an
invalid read (a true SIGSEGV), ``os.abort``, a sleep past the time limit, injected through the test hook
``WARPGS_NATIVE_FAULT``. pycolmap is never imported into the process that runs the pipeline."""

import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from warpgs.densify.filter import FilterConfig, filter_cloud, statistical_outliers
from warpgs.densify.native import FAULT_ENV, NativeStepFailed, run_native


def _ratio(a, b):
    return a / b


def _raises(message):
    raise ValueError(message)


def test_a_value_comes_back_and_an_exception_is_raised_here():
    assert run_native("maths", _ratio, 3.0, b=4.0, timeout_s=120) == 0.75
    with pytest.raises(ValueError, match="^the child's own words$"):
        run_native("maths", _raises, "the child's own words", timeout_s=120)


@pytest.mark.parametrize("fault, words", [("segv", "died of SIGSEGV"), ("abort", "died of SIGABRT"),
                                          ("hang", "did not finish within 3 s")])
def test_a_dead_or_hung_child_is_one_line_and_this_process_lives(monkeypatch, fault, words):
    monkeypatch.setenv(FAULT_ENV, f"maths:{fault}")
    with pytest.raises(NativeStepFailed) as e:
        run_native("maths", _ratio, 1.0, 2.0, timeout_s=3 if fault == "hang" else 120)
    assert words in str(e.value) and str(e.value).startswith("maths ") and "\n" not in str(e.value)
    monkeypatch.setenv(FAULT_ENV, f"another step:{fault}")  # the hook names its step
    assert run_native("maths", _ratio, 1.0, 2.0, timeout_s=120) == 0.5


def _cloud(seed=0, n=400, outliers=20):
    g = np.random.default_rng(seed)
    p = g.normal(size=(n, 3)).astype(np.float32)
    p[:outliers] *= 40.0
    return p, g.random((n, 3)).astype(np.float32)


def test_outlier_filter_in_its_child_equals_the_filter_here():
    p, c = _cloud()
    a = filter_cloud(p, c, FilterConfig(voxel=0.3))
    b = filter_cloud(p, c, FilterConfig(voxel=0.3), isolate=False)
    assert a.failure is None and np.array_equal(a.kept, b.kept) and np.array_equal(a.points, b.points)
    assert np.array_equal(a.colors, b.colors) and np.array_equal(a.index, b.index)
    assert 0 < int((~a.kept).sum()) < len(p)
    assert np.array_equal(filter_cloud(p, None, isolate=False).kept, statistical_outliers(p))


@pytest.mark.parametrize("fault", ["segv", "abort"])
def test_outlier_filter_whose_child_dies_keeps_the_cloud_unfiltered(monkeypatch, fault):
    p, c = _cloud()
    p[5] = np.nan
    monkeypatch.setenv(FAULT_ENV, f"open3d:{fault}")
    lines = []
    out = filter_cloud(torch.from_numpy(p), torch.from_numpy(c), log=lines.append)
    finite = np.isfinite(p).all(1)
    assert len(lines) == 1 and "outlier filter" in lines[0] and "unfiltered" in lines[0]
    assert out.failure and out.failure in lines[0]
    assert torch.equal(out.kept, torch.from_numpy(finite))  # every finite point kept, the NaN one not
    assert torch.equal(out.points, torch.from_numpy(p[finite]))
    assert torch.equal(out.colors, torch.from_numpy(c[finite]))


def test_outlier_filter_hanging_is_stopped_at_its_time_limit(monkeypatch):
    p, _ = _cloud()
    monkeypatch.setenv(FAULT_ENV, "open3d:hang")
    out = filter_cloud(p, timeout_s=3, log=lambda line: None)
    assert "did not finish within 3 s" in out.failure and bool(out.kept.all())


# ----------------------------------------------------------------------------------------------------
# SfM: pycolmap only in the child; a dead child is the next initialisation of the chain


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    from warpgs.data.nerfstudio import load_nerfstudio
    from warpgs.data.synthetic import SyntheticConfig, generate_capture, write_dl3dv

    cap = generate_capture(SyntheticConfig(seed=1, width=128, height=96, frames=12, samples_per_side=1, num_points=500),
                           device="cpu")
    return load_nerfstudio(write_dl3dv(cap, tmp_path_factory.mktemp("room") / "scene"), views=4, load_depth=True)


@pytest.mark.parametrize("fault", ["segv", "abort", "hang"])
def test_sfm_whose_child_dies_or_hangs_falls_back_to_stereo_and_records_it(room, monkeypatch, fault):
    import warpgs.points as points
    from warpgs.points import GeometryConfig, StereoInitOptions, initial_geometry
    from warpgs.points.sfm import triangulate

    monkeypatch.setenv(FAULT_ENV, f"sfm:{fault}")
    monkeypatch.setattr(points, "triangulate", lambda cams, opts, log: triangulate(cams, opts, log=log, timeout_s=5))
    lines = []
    geo = initial_geometry(room.train, "sfm", GeometryConfig(stereo=StereoInitOptions(max_width=64)), log=lines.append)
    assert geo.method == "stereo" and len(geo.xyz) >= 100
    assert len(lines) == 1 and "using stereo" in lines[0] and "pycolmap" in lines[0]
    assert len(geo.native_failures) == 1 and geo.summary()["native_failures"] == geo.native_failures
    assert {"segv": "SIGSEGV", "abort": "SIGABRT", "hang": "did not finish"}[fault] in geo.native_failures[0]


def test_the_pipeline_process_never_imports_pycolmap(room, tmp_path):
    """A triangulation run from a fresh interpreter leaves pycolmap out of its sys.modules, and the interpreter's
    SIGTERM and SIGSEGV handlers as Python set them (glog's would print a native crash dump)."""
    code = (
        "import pickle, signal, sys\n"
        "from warpgs.points.sfm import triangulate\n"
        "before = (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGSEGV))\n"
        "cams = pickle.load(open(sys.argv[1], 'rb'))\n"
        "pts = triangulate(cams, log=lambda line: None)\n"
        "after = (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGSEGV))\n"
        "print(len(pts.xyz), 'pycolmap' in sys.modules, before == after)\n"
    )
    import pickle

    (tmp_path / "cams.pkl").write_bytes(pickle.dumps(list(room.train)))
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "cams.pkl")], capture_output=True, text=True,
                         timeout=600, cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert out.returncode == 0, out.stderr[-2000:]
    n, imported, same = out.stdout.split()
    assert int(n) > 20 and imported == "False" and same == "True"


def test_implausible_focal_length_is_refused_before_pycolmap(room):
    from warpgs.points.sfm import SfmInputError, triangulate

    bad = [c for c in room.train]
    K = np.asarray(bad[0].K, np.float64).copy()
    K[0, 0] = -K[0, 0]
    bad[0] = type(bad[0])(bad[0].name, bad[0].viewmat, K, bad[0].width, bad[0].height, bad[0].image)
    with pytest.raises(SfmInputError, match=r"focal lengths fx=-[0-9.]+, fy=[0-9.]+ must be positive"):
        triangulate(bad, log=lambda line: None)


def test_a_child_dies_with_its_parent(tmp_path):
    """A run killed outright (SIGKILL: no finally runs) leaves no native step running behind it."""
    import signal
    import time

    code = ("import os, sys\n"
            f"os.environ['{FAULT_ENV}'] = 'maths:hang'\n"
            "from warpgs.densify.native import run_native\n"
            "from operator import add\n"
            "run_native('maths', add, 1, 2, timeout_s=600)\n")
    parent = subprocess.Popen([sys.executable, "-c", code], cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        children: list[int] = []
        t0 = time.monotonic()
        while not children and time.monotonic() - t0 < 120:
            time.sleep(0.2)
            try:
                with open(f"/proc/{parent.pid}/task/{parent.pid}/children") as f:
                    children = [int(p) for p in f.read().split()]
            except OSError:
                break
        assert children, "the native step's child never started"
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        t0 = time.monotonic()
        while os.path.exists(f"/proc/{children[0]}") and time.monotonic() - t0 < 30:
            try:
                with open(f"/proc/{children[0]}/stat") as f:
                    if f.read().split()[2] == "Z":  # a zombie is dead (its new parent reaps it)
                        break
            except OSError:
                break
            time.sleep(0.1)
        alive = os.path.exists(f"/proc/{children[0]}")
        if alive:
            with open(f"/proc/{children[0]}/stat") as f:
                alive = f.read().split()[2] != "Z"
        assert not alive, "the child outlived its killed parent"
    finally:
        if parent.poll() is None:
            parent.kill()
