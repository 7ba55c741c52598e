"""Host (Python) cost of one ``warpgs.render.rasterize`` forward+backward on a tiny problem.

    python bench/perf/host_overhead.py                         # CPU, 200 Gaussians, 32x32, SH degree 3
    python bench/perf/host_overhead.py --device cuda --out bench/results/perf/host_overhead_cuda.json
    python bench/perf/host_overhead.py --profile 20            # plus a cProfile of 200 calls, 20 rows

The problem is bench/perf/rasterizer.py's (``make_inputs``: random Gaussians in front of one pinhole camera) with SH
colours of ``--sh-degree`` ([N, (d+1)^2, 3] random coefficients; -1: RGB colours), rendered and backpropagated as
bench/perf/rasterizer.py's ``calls``/``warpgs_fn`` do (``check_finite=False``, alpha clamp 0.999). It is small enough
that the kernels take little time, so the figure is mostly the Python around them: the time measured is the host's
wall clock per call, the median over ``--rounds`` rounds of ``--iters`` calls each (after ``--warmup`` calls), with
Python's garbage collector paused. On CUDA the rounds issue their calls without a sync (the host's time, as
bench/perf/rasterizer_host.py measures it) and a sync follows each round, outside the timing. On the CPU the kernels run
inside the call, so the figure includes them (small at this size). The JSON (``--out``) holds the arguments, the
per-round times (ms/call), their median, and the versions of Python, torch and Warp.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import io
import json
import platform
import pstats
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from bench.perf.rasterizer import calls, make_inputs, warpgs_fn  # noqa: E402


def make_problem(n: int, width: int, height: int, sh_degree: int, device: str, seed: int = 0) -> dict:
    """bench/perf/rasterizer.py's inputs, with [N, (d+1)^2, 3] SH coefficients as colours where ``sh_degree`` >= 0."""
    inp = make_inputs(n, width, height, device, seed=seed)
    if sh_degree >= 0:
        g = torch.Generator(device="cpu").manual_seed(seed + 1)
        inp["colors"] = (0.3 * torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g)).to(device)
        inp["sh_degree"] = sh_degree
    return inp


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def time_rounds(fb, device: str, iters: int, rounds: int, warmup: int) -> list[float]:
    """ms per call of ``fb`` in each of ``rounds`` rounds of ``iters`` calls (host wall clock, GC paused)."""
    for _ in range(warmup):
        fb()
    _sync(device)
    out = []
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for _ in range(rounds):
            t = time.perf_counter()
            for _ in range(iters):
                fb()
            out.append((time.perf_counter() - t) * 1000 / iters)
            _sync(device)
    finally:
        if gc_was:
            gc.enable()
    return out


def profile(fb, device: str, calls_n: int, rows: int) -> str:
    """cProfile summary (own time, then cumulative) of ``calls_n`` calls of ``fb``."""
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(calls_n):
        fb()
    _sync(device)
    prof.disable()
    text = []
    for order in ("tottime", "cumulative"):
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats(order).print_stats(rows)
        text.append(s.getvalue())
    return "\n".join(text)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu", help="cpu or cuda[:N] (default cpu)")
    ap.add_argument("--gaussians", type=int, default=200)
    ap.add_argument("--width", type=int, default=32)
    ap.add_argument("--height", type=int, default=32)
    ap.add_argument("--sh-degree", type=int, default=3, help="0..3, or -1 for RGB colours (default 3)")
    ap.add_argument("--iters", type=int, default=200, help="calls per round (default 200)")
    ap.add_argument("--rounds", type=int, default=7, help="rounds; the median is reported (default 7)")
    ap.add_argument("--warmup", type=int, default=30)
    ap.add_argument("--profile", type=int, default=0, metavar="ROWS",
                    help="also print a cProfile of 200 calls, ROWS rows per ordering (default 0: none)")
    ap.add_argument("--out", type=Path, help="write the results as JSON here")
    args = ap.parse_args(argv)

    torch.manual_seed(0)
    inp = make_problem(args.gaussians, args.width, args.height, args.sh_degree, args.device)
    _, _, fb = calls(warpgs_fn(inp, args.width, args.height, 0.999), inp)
    per_round = time_rounds(fb, args.device, args.iters, args.rounds, args.warmup)
    med = statistics.median(per_round)
    print(f"warpgs rasterize forward+backward on {args.device}: {med:.3f} ms/call (median of {args.rounds} rounds of "
          f"{args.iters}; range {min(per_round):.3f}-{max(per_round):.3f})", flush=True)
    result = {
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "ms_per_call_rounds": per_round,
        "ms_per_call_median": med,
        "python": platform.python_version(),
        "torch": torch.__version__,
    }
    try:
        import warp as wp

        result["warp"] = wp.config.version
    except Exception:  # noqa: BLE001 - informational only
        pass
    if args.profile:
        print(profile(fb, args.device, 200, args.profile))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    return result


if __name__ == "__main__":
    main()
