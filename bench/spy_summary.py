"""Sums a py-spy profile in its raw (collapsed stacks) format: per thread, the share of samples by the function
they were in (own) and by every function on their stack (inclusive), the file's line numbers dropped.

    py-spy record --native --idle --threads -r 1000 -f raw -o spy.txt -- python bench/rasterizer_host.py --loop 10 --only warpgs
    python bench/spy_summary.py spy.txt[.gz] [--rows 40] [--under f_b]

``--under NAME``: count only the samples whose stack passes through a function named NAME (the timed calls).
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


def read(path: Path, under: str | None = None) -> dict[str, tuple[int, Counter, Counter]]:
    """thread -> (samples, own samples by function, inclusive samples by function). Without thread frames
    (py-spy without ``--threads``) everything is one thread, ``all``."""
    out: dict[str, list] = defaultdict(lambda: [0, Counter(), Counter()])
    text = (gzip.decompress(path.read_bytes()).decode(errors="replace") if path.suffix == ".gz"
            else path.read_text(errors="replace"))
    for line in text.splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
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
        entry = out[thread]
        entry[0] += n
        if frames:
            entry[1][frames[-1]] += n
        for f in set(frames):
            entry[2][f] += n
    return {k: (v[0], v[1], v[2]) for k, v in out.items()}


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
    args = ap.parse_args(argv)
    if not args.profile.is_file():
        ap.error(f"no such profile: {args.profile}")
    print("\n".join(report(read(args.profile, args.under), args.rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
