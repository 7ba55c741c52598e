"""Host-side cost of one rasterizer call on CUDA: warpgs against gsplat 1.5.3 at the smallest configuration of
bench/perf/rasterizer.py (138,766 random Gaussians at 648x420), where both are bound by the host.

    python bench/perf/rasterizer_host.py [--gaussians N --width W --height H] > host_profile.txt

For each: the host's time per forward+backward over 100 calls issued without a sync, and the time until the GPU
has finished them (equal when the GPU keeps up), then a cProfile of 200 calls (warpgs: by own time and by
cumulative time; gsplat: by own time).

    py-spy record --native --idle --threads -r 200 -f raw -o spy.txt -- python bench/perf/rasterizer_host.py --loop 10 --only warpgs
    gzip spy.txt   # (--native at 1000 Hz can fall far behind and write over 16 MB)

``--loop S``: instead of the cProfile (which slows every Python call, and so overstates the Python's share), calls
forward+backward for S seconds (a sync every 100 calls), for a sampling profiler outside the process to split the
host's real time; ``--only`` picks one rasterizer. ``python bench/diagnostics/spy_summary.py spy.txt --under timed_loop`` sums
such a profile over the loop's calls alone, without the warm-up's.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from bench.perf.rasterizer import calls, gsplat_fn, make_inputs, warpgs_fn  # noqa: E402


def timed_loop(fb, seconds: float) -> int:
    """Calls ``fb`` for ``seconds`` (a sync every 100 calls); returns how many calls. A sampling profiler's stacks
    of these calls pass through this function (``bench/diagnostics/spy_summary.py --under timed_loop``)."""
    end, k = time.perf_counter() + seconds, 0
    while time.perf_counter() < end:
        for _ in range(100):
            fb()
        torch.cuda.synchronize()
        k += 100
    return k


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gaussians", type=int, default=138_766)
    ap.add_argument("--width", type=int, default=648)
    ap.add_argument("--height", type=int, default=420)
    ap.add_argument("--loop", type=float, default=0.0, help="call for this many seconds instead of the cProfile")
    ap.add_argument("--only", choices=("warpgs", "gsplat"), default=None)
    args = ap.parse_args(argv)
    n, W, H = args.gaussians, args.width, args.height
    inp = make_inputs(n, W, H, "cuda")
    makers = {"warpgs": lambda: warpgs_fn(inp, W, H, 0.999), "gsplat": lambda: gsplat_fn(inp, W, H)}
    for name, make in makers.items():
        if args.only not in (None, name):
            continue  # not built either: --only warpgs runs where gsplat is not installed
        fn = make()
        _, _, fb = calls(fn, inp)  # forward + backward on its own copy of the inputs, as bench/perf/rasterizer.py times it
        for _ in range(30):
            fb()
        torch.cuda.synchronize()
        t = time.perf_counter()
        for _ in range(100):
            fb()
        host = (time.perf_counter() - t) * 10
        torch.cuda.synchronize()
        total = (time.perf_counter() - t) * 10
        print(f"{name}: host {host:.3f} ms/call, to the end {total:.3f} ms/call", flush=True)
        if args.loop > 0:
            k = timed_loop(fb, args.loop)
            print(f"{name}: {k} calls in {args.loop:.0f} s of --loop", flush=True)
            continue
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(200):
            fb()
        torch.cuda.synchronize()
        prof.disable()
        orders = ("tottime", "cumulative") if name == "warpgs" else ("tottime",)
        for order in orders:
            s = io.StringIO()
            pstats.Stats(prof, stream=s).sort_stats(order).print_stats(30 if order == "tottime" else 35)
            print(s.getvalue()[-9000:])


if __name__ == "__main__":
    main()
