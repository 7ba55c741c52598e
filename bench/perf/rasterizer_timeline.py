"""Where a rasterizer call's time goes on the GPU's timeline: warpgs against gsplat 1.5.3 (CUDA only).

    python bench/perf/rasterizer_timeline.py [--gaussians N --width W --height H --iters K] [--out FILE.json]

Both run forward+backward as bench/perf/rasterizer.py times them (the same random inputs and loss), K calls under
torch.profiler (CUDA activity). From the trace's GPU operations (kernels, memsets, copies) over the middle calls:
the wall time per call (between the calls' host markers), the GPU's busy time per call (union of its operations),
the idle time, and the idle gaps grouped by the operations before and after them, largest total first, so that a
gap behind the forward's one host read (the intersection count) or behind a slow host path shows by name.
The profiler adds its own host cost to every launch, for both rasterizers alike: read the busy time and the gaps,
not the wall time, as the figures to compare.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from bench.perf.rasterizer import calls, gsplat_fn, make_inputs, warpgs_fn, write_result  # noqa: E402

GPU_CATS = ("kernel", "gpu_memset", "gpu_memcpy")


def short(name: str, n: int = 48) -> str:
    """A kernel's name cut to its recognisable head (templates and argument lists dropped)."""
    if name.startswith("void "):
        name = name[5:].split("(")[0]
    return name.split("<")[0].strip()[:n]


def analyse(events: list[dict], marker: str, skip: int = 2) -> dict:
    """Per-call wall / busy / idle (microseconds) and the grouped gaps of a trace's events (chrome-trace dicts),
    over the calls between the ``skip``-th marker and the last one."""
    marks = sorted(e["ts"] for e in events if e.get("name") == marker and e.get("cat") == "user_annotation")
    if len(marks) < skip + 2:
        raise SystemExit(f"timeline: only {len(marks)} '{marker}' markers in the trace")
    t0, t1 = marks[skip], marks[-1]
    ops = sorted((e for e in events if e.get("cat") in GPU_CATS and t0 <= e["ts"] < t1), key=lambda e: e["ts"])
    calls_n = len(marks) - 1 - skip
    busy = 0.0
    gaps: dict = defaultdict(lambda: [0.0, 0])
    end = None
    prev = None
    for e in ops:
        s, d = float(e["ts"]), float(e.get("dur", 0.0))
        if end is None:
            busy += d
        else:
            if s > end:
                g = s - end
                key = (short(prev["name"]), short(e["name"]))
                gaps[key][0] += g
                gaps[key][1] += 1
                busy += d
            else:
                busy += max(0.0, s + d - end)
        if end is None or s + d > end:
            end, prev = s + d, e
    wall = (t1 - t0) / calls_n
    top = sorted(gaps.items(), key=lambda kv: -kv[1][0])[:15]
    kernels: dict = defaultdict(float)
    for e in ops:
        kernels[short(e["name"])] += float(e.get("dur", 0.0)) / calls_n
    return {
        "calls": calls_n,
        "wall_us": wall,
        "gpu_busy_us": busy / calls_n,
        "gpu_idle_us": wall - busy / calls_n,
        "gpu_ops_per_call": len(ops) / calls_n,
        "gaps": [{"after": a, "before": b, "us_per_call": g / calls_n, "count": c} for (a, b), (g, c) in top],
        "gpu_us_per_call": dict(sorted(kernels.items(), key=lambda kv: -kv[1])),
    }


def trace(fn, iters: int) -> list[dict]:
    """Chrome-trace events of ``iters`` calls of ``fn`` under torch.profiler, each inside a 'call' marker."""
    from torch.profiler import ProfilerActivity, profile, record_function

    for _ in range(10):
        fn()
    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        for _ in range(iters):
            with record_function("call"):
                fn()
        with record_function("call"):
            torch.cuda.synchronize()
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "trace.json"
        prof.export_chrome_trace(str(path))
        return json.loads(path.read_text())["traceEvents"]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gaussians", type=int, default=138_766)
    ap.add_argument("--width", type=int, default=648)
    ap.add_argument("--height", type=int, default=420)
    ap.add_argument("--iters", type=int, default=40)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--trace-dir", type=Path, default=None, help="also write each raw trace there (gzip)")
    args = ap.parse_args(argv)
    n, W, H = args.gaussians, args.width, args.height
    inp = make_inputs(n, W, H, "cuda")
    result = {"device": torch.cuda.get_device_name(), "gaussians": n, "width": W, "height": H}
    for name, fn in (("warpgs", warpgs_fn(inp, W, H, 0.999)), ("gsplat", gsplat_fn(inp, W, H))):
        _, _, fb = calls(fn, inp)
        events = trace(fb, args.iters)
        if args.trace_dir is not None:
            args.trace_dir.mkdir(parents=True, exist_ok=True)
            with gzip.open(args.trace_dir / f"{name}_trace.json.gz", "wt") as f:
                json.dump({"traceEvents": events}, f)
        r = result[name] = analyse(events, "call")
        print(f"{name}: wall {r['wall_us']:.0f} us/call, GPU busy {r['gpu_busy_us']:.0f}, idle {r['gpu_idle_us']:.0f}, "
              f"{r['gpu_ops_per_call']:.0f} GPU operations", flush=True)
        for g in r["gaps"][:10]:
            print(f"    gap {g['us_per_call']:7.1f} us/call  after {g['after']:<48} before {g['before']}")
        for k, v in list(r["gpu_us_per_call"].items())[:12]:
            print(f"    {v:8.1f} us  {k}")
    if args.out is not None:
        write_result(args.out, result)
    return result


if __name__ == "__main__":
    main()
