"""Where a training step's host time goes: the Python profile of bench/perf/train_speed.py's loops (issue 15).

    python bench/perf/host_profile.py --data-root ../shared/data --set model.init=frustum     # CUDA: fern, 3 views
    python bench/perf/host_profile.py --device cpu --shrink 16 --iterations 40 --set model.init=frustum \\
        --set model.init_num=300

On CUDA a training step is bound by the host when its kernels are short: the wall time is what Python, torch's
dispatcher, autograd and the launches cost. Each loop of bench/perf/train_speed.py (``--loops``, default the trainer
and the plain warpgs loop) runs ``--warmup`` steps, then ``--iterations`` steps under cProfile, and the functions
with the most time of their own (``--sort cumulative``: with what they call) are printed (``--top``), with the
wall time per step. The text goes to stdout
(and ``--out``); nothing here is a benchmark figure.
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

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT.parent))
sys.path.insert(0, str(ROOT))

import train_speed as ts  # noqa: E402


def busy_share(maker, setup, iterations: int) -> str:
    """One loop's wall time per step without cProfile, and the share of it the GPU spends in kernels (torch.profiler's
    CUDA kernel time, summed, over the wall time of the same steps); kernels of one stream do not overlap."""
    from torch.profiler import ProfilerActivity, profile

    go, *_ = maker(setup, iterations)
    ts.sync("cuda")
    t0 = time.perf_counter()
    go()
    ts.sync("cuda")
    plain = (time.perf_counter() - t0) / iterations
    go, *_ = maker(setup, iterations)
    ts.sync("cuda")
    with profile(activities=[ProfilerActivity.CUDA]) as prof:
        t0 = time.perf_counter()
        go()
        ts.sync("cuda")
        wall = time.perf_counter() - t0
    kernel_us = sum(e.device_time_total if hasattr(e, "device_time_total") else e.cuda_time_total
                    for e in prof.events() if getattr(e, "device_type", None) is not None
                    and str(e.device_type).endswith("CUDA"))
    return (f"    without cProfile: {plain * 1e3:.2f} ms a step; under torch.profiler {wall / iterations * 1e3:.2f} ms a "
            f"step, GPU kernels {kernel_us / 1e3 / iterations:.2f} ms a step: busy {kernel_us / 1e6 / wall:.0%}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="llff")
    ap.add_argument("--scene", default=None)
    ap.add_argument("--views", type=int, default=3)
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--iterations", type=int, default=300)
    ap.add_argument("--warmup", type=int, default=50)
    ap.add_argument("--device", choices=["cuda", "cpu"], default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--loops", default="warpgs_trainer,plain_warpgs")
    ap.add_argument("--shrink", type=int, default=1)
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--sort", default="tottime", help="pstats order: tottime (own time) or cumulative (with callees)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--busy", action="store_true",
                    help="CUDA: also time each loop without cProfile and under torch.profiler, and print the GPU's "
                         "busy share (kernel time / wall time): near 1, the step is bound by the GPU; well below, by "
                         "the host")
    args = ap.parse_args(argv)
    cfg = ts.make_config(args)
    setup = ts.Setup(cfg, ts.load_scene(cfg, args.shrink))
    makers = {"warpgs_trainer": ts.run_warpgs_trainer, "plain_warpgs": ts.run_plain_warpgs,
              "plain_gsplat": ts.run_plain_gsplat}
    text = io.StringIO()
    for name in args.loops.split(","):
        warm, *_ = makers[name](setup, args.warmup)
        warm()
        go, *_ = makers[name](setup, args.iterations)
        ts.sync(args.device)
        prof = cProfile.Profile()
        t0 = time.perf_counter()
        prof.enable()
        go()
        ts.sync(args.device)
        prof.disable()
        dt = time.perf_counter() - t0
        text.write(f"\n=== {name}: {args.iterations} steps, {dt / args.iterations * 1e3:.2f} ms a step under "
                   f"cProfile ({args.device})\n")
        pstats.Stats(prof, stream=text).sort_stats(args.sort).print_stats(args.top)
        if args.busy and args.device == "cuda":
            text.write(busy_share(makers[name], setup, args.iterations) + "\n")
    print(text.getvalue())
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text.getvalue())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
