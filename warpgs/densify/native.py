"""Native steps that can abort, run in a child process so that they cannot take the run with them.

    value = run_native("sfm", triangulate_here, cameras, opts, timeout_s=1800)
    # NativeStepFailed("sfm died of SIGSEGV in its child process") instead of a dead run

pycolmap (glog installs signal handlers that turn SIGSEGV and SIGTERM into native crash dumps) and open3d can
abort the process on inputs their C++ did not expect. ``run_native`` pickles the function (by reference, so a
module-level one) and its arguments into a temporary folder, runs them in a fresh ``python`` (no fork of the
training process, its threads and CUDA context; the library is imported there and only there), and returns the
value or re-raises the exception the function raised. A child killed by a signal, one that exits without a result,
or one still running after ``timeout_s`` (killed then, with its process group) raises ``NativeStepFailed`` with
one line; the child's own output (a crash dump) is dropped. Callers turn that into their documented fallback and
record the line (``Geometry.native_failures``, ``FilterResult.failure``).

Test hook: ``WARPGS_NATIVE_FAULT=<what>:segv`` (a real invalid read), ``:abort`` or ``:hang`` makes the child of the
step named ``what`` fail that way before it runs the function.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable

FAULT_ENV = "WARPGS_NATIVE_FAULT"

_CHILD = r"""
import os, pickle, sys
try:  # Linux: the child is killed with its parent (a run stopped by SIGTERM or SIGKILL leaves no SfM running)
    import ctypes, signal
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
except Exception:
    pass
src, dst = sys.argv[1], sys.argv[2]
with open(src, "rb") as f:
    what, fn, args, kwargs = pickle.load(f)
fault = os.environ.get("WARPGS_NATIVE_FAULT", "")
if fault.rpartition(":")[0] == what:
    kind = fault.rpartition(":")[2]
    if kind == "segv":
        import ctypes
        ctypes.string_at(0)
    elif kind == "abort":
        os.abort()
    elif kind == "hang":
        import time
        time.sleep(1e6)
try:
    out = ("return", fn(*args, **kwargs))
except BaseException as e:  # handed to the parent, which raises it
    out = ("raise", e)
try:
    data = pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL)
except Exception as e:
    data = pickle.dumps(("raise", RuntimeError(f"{type(out[1]).__name__}: {out[1]}")))
with open(dst + ".part", "wb") as f:
    f.write(data)
os.replace(dst + ".part", dst)
"""


class NativeStepFailed(RuntimeError):
    """The child process of a native step died, hung or left no result; the one-line message says which."""


def _signal_name(rc: int) -> str:
    try:
        return signal.Signals(-rc).name
    except ValueError:
        return f"signal {-rc}"


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1][:200] if lines else ""


def run_native(what: str, fn: Callable, *args: Any, timeout_s: float, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)`` in a child process (module docstring); ``what`` names the step in messages."""
    # the child finds what this process finds (this warpgs, the module of ``fn``), this warpgs first
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [p for p in sys.path if p and p != root]))
    with tempfile.TemporaryDirectory(prefix="warpgs-native-") as d:
        src, dst, log = Path(d) / "in.pkl", Path(d) / "out.pkl", Path(d) / "output.txt"
        with open(src, "wb") as f:
            pickle.dump((what, fn, args, kwargs), f, protocol=pickle.HIGHEST_PROTOCOL)
        with open(log, "wb") as out:
            proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(src), str(dst)], stdin=subprocess.DEVNULL,
                                    stdout=out, stderr=out, env=env, start_new_session=True)
            try:
                rc = proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                rc = None
            finally:
                if proc.poll() is None:  # timed out, or the parent is being interrupted: the child goes too
                    try:
                        os.killpg(proc.pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
                    proc.wait()
        if rc is None:
            raise NativeStepFailed(f"{what} did not finish within {timeout_s:g} s and was stopped")
        if rc < 0:
            raise NativeStepFailed(f"{what} died of {_signal_name(rc)} in its child process")
        if rc != 0 or not dst.exists():
            last = _last_line(log)
            raise NativeStepFailed(f"{what} exited with status {rc} and no result" + (f" ({last})" if last else ""))
        with open(dst, "rb") as f:
            status, value = pickle.load(f)
    if status == "raise":
        raise value
    return value


__all__ = ["FAULT_ENV", "NativeStepFailed", "run_native"]
