"""bench/perf/rasterizer_timeline.py's analysis of a trace, on a hand-made timeline whose busy time and gaps are known."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.perf.rasterizer_timeline import analyse, short  # noqa: E402


def _trace():
    """Four calls of 100 us (markers at 0, 100, 200, 300, 400). Each call: kernel A 10-30, kernel B 25-60 (overlaps A
    by 5), a memset 80-90; so busy 60 us, gaps 60 -> 80 (B -> memset, 20 us) and 90 -> 110 (memset -> next A,
    20 us), idle 40 us a call. A CPU-side event and a kernel outside the markers must not count."""
    ev = [{"name": "call", "cat": "user_annotation", "ts": t, "dur": 90} for t in (0, 100, 200, 300, 400)]
    for c in range(5):
        o = 100 * c
        ev += [{"name": "void kernA<float>(int)", "cat": "kernel", "ts": o + 10, "dur": 20},
               {"name": "kernB_cuda_kernel_forward", "cat": "kernel", "ts": o + 25, "dur": 35},
               {"name": "Memset (Device)", "cat": "gpu_memset", "ts": o + 80, "dur": 10},
               {"name": "cudaLaunchKernel", "cat": "cuda_runtime", "ts": o + 5, "dur": 3}]
    return ev


def test_busy_idle_and_gaps_of_a_known_timeline():
    r = analyse(_trace(), "call", skip=1)  # the calls at 100, 200, 300 (the one at 400 closes the window)
    assert r["calls"] == 3
    assert r["wall_us"] == 100.0
    assert abs(r["gpu_busy_us"] - 60.0) < 1e-9
    assert abs(r["gpu_idle_us"] - 40.0) < 1e-9
    assert r["gpu_ops_per_call"] == 3.0
    gaps = {(g["after"], g["before"]): g["us_per_call"] for g in r["gaps"]}
    assert abs(gaps[("kernB_cuda_kernel_forward", "Memset (Device)")] - 20.0) < 1e-9
    # the first call's gap into its A lies before the window's first operation; the others are counted
    assert abs(gaps[("Memset (Device)", "kernA")] - 20.0 * 2 / 3) < 1e-9
    assert abs(r["gpu_us_per_call"]["kernA"] - 20.0) < 1e-9


def test_short_names():
    assert short("void gsplat::rasterize_to_pixels_fwd_kernel<3u, float>(int, float*)") == \
        "gsplat::rasterize_to_pixels_fwd_kernel"
    assert short("rasterize_fwd_cuda_ab26ef40_cuda_kernel_forward") == "rasterize_fwd_cuda_ab26ef40_cuda_kernel_forward"
