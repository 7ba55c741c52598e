import os
import sys
from pathlib import Path

# tests/reference.py (the torch oracle) is imported by name from the test files.
sys.path.insert(0, str(Path(__file__).resolve().parent))

import torch

# Small tensors on a shared 2-core machine: torch's intra-op threads only add contention
# (Warp's CPU kernels run on one thread anyway).
torch.set_num_threads(1)

# ``WARPGS_ONLY_CUDA_SKIPS=1`` (set by .ci/run): the session fails when a test or a module skips for any reason that
# does not mention CUDA, so that a missing package, data set or browser cannot turn the suite green by skipping.
ONLY_CUDA_SKIPS = os.environ.get("WARPGS_ONLY_CUDA_SKIPS", "") not in ("", "0")
_skips: list[tuple[str, str]] = []


def _note_skip(report) -> None:
    if report.skipped and not hasattr(report, "wasxfail"):
        lr = report.longrepr
        reason = lr[2] if isinstance(lr, tuple) and len(lr) == 3 else str(lr)
        _skips.append((report.nodeid, reason))


def pytest_runtest_logreport(report):
    _note_skip(report)


def pytest_collectreport(report):
    _note_skip(report)


def _forbidden_skips() -> list[tuple[str, str]]:
    return [(node, reason) for node, reason in _skips if "cuda" not in reason.lower()]


def pytest_terminal_summary(terminalreporter):
    bad = _forbidden_skips() if ONLY_CUDA_SKIPS else []
    if bad:
        terminalreporter.section("skips that are not CUDA's (WARPGS_ONLY_CUDA_SKIPS)", red=True)
        for node, reason in bad:
            terminalreporter.line(f"{node}: {reason}")


def pytest_sessionfinish(session, exitstatus):
    if ONLY_CUDA_SKIPS and _forbidden_skips() and session.exitstatus == 0:
        session.exitstatus = 1
