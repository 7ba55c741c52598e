"""Sums a py-spy profile in its raw (collapsed stacks) format: per thread, the share of samples by the function
they were in (own) and by every function on their stack (inclusive), the file's line numbers dropped.

    py-spy record --native --idle --threads -r 1000 -f raw -o spy.txt -- python bench/perf/rasterizer_host.py --loop 10 --only warpgs
    python bench/diagnostics/spy_summary.py spy.txt[.gz] [--rows 40] [--under f_b] [--at rasterizer_host.py:67]
        [--children _bin_gaussians --children Launcher.__call__]

``--under NAME``: count only the samples whose stack passes through a function named NAME (the timed calls).
``--at FILE:LINE``: count only the samples whose stack passes through that line (with rasterizer_host.py's
``--loop``, its call in the loop: the timed calls without the warm-up's, whose first calls compile the kernels);
threads whose stacks never pass through it are kept whole (the autograd engine's device thread runs the backward).
``--children NAME``: also, for each function named NAME, the samples under it by the function it called (what its
inclusive time is made of); repeatable.
A line of the raw format is ``frame;frame;...;frame COUNT``, the outermost frame first; with ``--threads`` the first
frame names the thread.
"""

from __future__ import annotations

import argparse
import gzip
import re
from collections import Counter, defaultdict
from pathlib import Path

_LINE_NO = re.compile(r":\d+\)$")


def frame_name(frame: str) -> str:
    """``fn (file.py:123)`` -> ``fn (file.py)``; native frames as they are."""
    return _LINE_NO.sub(")", frame.strip())


def _lines(path: Path) -> list[str]:
    text = (gzip.decompress(path.read_bytes()).decode(errors="replace") if path.suffix == ".gz"
            else path.read_text(errors="replace"))
    return text.splitlines()


def _threads_through(lines: list[str], at: str) -> set[str]:
    """The first frames (threads) of the stacks that pass through line ``at`` (``file:line``)."""
    return {stack.split(";")[0] for stack, _, _ in (ln.rpartition(" ") for ln in lines) if f"{at})" in stack}


def read(path: Path, under: str | None = None, at: str | None = None,
         children: tuple[str, ...] = ()) -> dict[str, tuple[int, Counter, Counter]]:
    """thread -> (samples, own samples by function, inclusive samples by function). Without thread frames
    (py-spy without ``--threads``) everything is one thread, ``all``. ``under``, ``at``: the filters of the module
    doc; ``children``: as ``read_children``'s, whose callee counts this leaves out."""
    return read_children(path, under, at, children)[0]


def read_children(path: Path, under: str | None = None, at: str | None = None, children: tuple[str, ...] = ()):
    """``read``'s threads, and for each name of ``children``: (samples under it, Counter of the frame each of those
    samples called from it; ``(own)`` where it was the innermost frame), over all threads."""
    out: dict[str, list] = defaultdict(lambda: [0, Counter(), Counter()])
    kids = {name: [0, Counter()] for name in children}
    lines = _lines(path)
    through = _threads_through(lines, at) if at else set()
    for line in lines:
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
            continue
        if at and stack.split(";")[0] in through and f"{at})" not in stack:
            continue
        frames = [frame_name(f) for f in stack.split(";")]
        thread = "all"
        if frames and frames[0].startswith(("thread ", "process ")):
            thread = frames.pop(0)
            if frames and frames[0].startswith("thread "):
                thread = frames.pop(0)
        if under is not None and not any(f.split(" (")[0].endswith(under) for f in frames):
            continue
        n = int(count)
        for name, k in kids.items():
            for i, f in enumerate(frames):
                if f.split(" (")[0].endswith(name):
                    k[0] += n
                    k[1][frames[i + 1] if i + 1 < len(frames) else "(own)"] += n
                    break
        entry = out[thread]
        entry[0] += n
        if frames:
            entry[1][frames[-1]] += n
        for f in set(frames):
            entry[2][f] += n
    return {k: (v[0], v[1], v[2]) for k, v in out.items()}, {k: (v[0], v[1]) for k, v in kids.items()}


def report(threads: dict[str, tuple[int, Counter, Counter]], rows: int) -> list[str]:
    lines = []
    for thread, (total, own, incl) in sorted(threads.items(), key=lambda kv: -kv[1][0]):
        lines.append(f"== {thread}: {total} samples")
        for title, counter in (("own", own), ("inclusive", incl)):
            lines.append(f"  -- {title}")
            for f, n in counter.most_common(rows):
                lines.append(f"  {100.0 * n / total:6.2f}%  {n:7d}  {f}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("profile", type=Path)
    ap.add_argument("--rows", type=int, default=40)
    ap.add_argument("--under", default=None)
    ap.add_argument("--at", default=None, help="FILE:LINE, e.g. rasterizer_host.py:67")
    ap.add_argument("--children", action="append", default=[])
    args = ap.parse_args(argv)
    if not args.profile.is_file():
        ap.error(f"no such profile: {args.profile}")
    threads, kids = read_children(args.profile, args.under, args.at, tuple(args.children))
    lines = report(threads, args.rows)
    for name, (total, counter) in kids.items():
        lines.append(f"== under {name}: {total} samples, by the function it called")
        for f, n in counter.most_common(args.rows):
            lines.append(f"  {100.0 * n / max(total, 1):6.2f}%  {n:7d}  {f}")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
