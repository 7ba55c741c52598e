"""The GPU memory one run holds, over time and by holder: ``python -m warpgs.pipelines.sparse`` in this process,
sampled every ``--every`` seconds.

    python bench/perf/run_memory.py --out outputs/bench/run_memory_fern_full.json -- \\
        --data llff --scene fern --views 3 --method full --iterations 3000 --data-root ../shared/data

Everything after ``--`` goes to ``warpgs.pipelines.sparse`` (``--device cuda`` and ``--no-progress`` are added).
Each sample: seconds since the start, torch's allocated and reserved bytes (its caching allocator, the CUDA graphs'
pools included), Warp's memory pool in use (``wp.get_mempool_used_mem_current``) and the device's used bytes
(``torch.cuda.mem_get_info``: every process on the GPU; run it alone). Each line the run prints is kept with its
time, so the rises can be placed in its stages. Writes JSON: the samples, the lines, the peak of each holder and
what the device held beyond torch's reservation and Warp's pool (CUDA's contexts, cuBLAS's workspaces, other
libraries' memory).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

MB = 2**20


class _Lines(io.TextIOBase):
    """A stdout that keeps each line with its time and passes it on."""

    def __init__(self, inner, t0: float):
        self.inner, self.t0, self.lines, self.part = inner, t0, [], ""

    def write(self, s: str) -> int:
        self.inner.write(s)
        self.part += s
        while "\n" in self.part:
            line, self.part = self.part.split("\n", 1)
            if line.strip():
                self.lines.append([round(time.perf_counter() - self.t0, 2), line])
        return len(s)

    def flush(self):
        self.inner.flush()


def sample(device) -> dict:
    import torch
    import warp as wp

    free, total = torch.cuda.mem_get_info(device)
    try:
        warp_pool = wp.get_mempool_used_mem_current(f"cuda:{device.index or 0}")
    except Exception:  # noqa: BLE001 - no pool on this device, or Warp not started yet
        warp_pool = 0
    return {"torch_allocated_mb": torch.cuda.memory_allocated(device) / MB,
            "torch_reserved_mb": torch.cuda.memory_reserved(device) / MB,
            "warp_pool_mb": warp_pool / MB, "device_used_mb": (total - free) / MB}


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    run_argv = argv[argv.index("--") + 1:] if "--" in argv else []
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("outputs/bench/run_memory.json"))
    ap.add_argument("--every", type=float, default=0.5, help="seconds between samples (default 0.5)")
    a = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    import torch

    if not torch.cuda.is_available():
        ap.error("needs a CUDA GPU")
    from warpgs.pipelines import sparse

    device = torch.device("cuda", 0)
    t0 = time.perf_counter()
    samples, stop = [], threading.Event()

    def sampler():
        while not stop.is_set():
            samples.append({"t": round(time.perf_counter() - t0, 2), **sample(device)})
            stop.wait(a.every)

    out, err = _Lines(sys.stdout, t0), _Lines(sys.stderr, t0)
    thread = threading.Thread(target=sampler, daemon=True)
    thread.start()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = sparse.main([*run_argv, "--device", "cuda", "--no-progress"])
    stop.set()
    thread.join()
    keys = ("torch_allocated_mb", "torch_reserved_mb", "warp_pool_mb", "device_used_mb")
    peaks = {k: round(max(s[k] for s in samples), 1) for k in keys}
    beyond = max(s["device_used_mb"] - s["torch_reserved_mb"] - s["warp_pool_mb"] for s in samples)
    doc = {"what": "GPU memory of one run over time (bench/perf/run_memory.py)", "argv": run_argv, "exit_code": rc,
           "device": torch.cuda.get_device_name(device), "torch": torch.__version__, "peaks_mb": peaks,
           "max_beyond_torch_and_warp_mb": round(beyond, 1), "samples": samples, "lines": sorted(out.lines + err.lines)}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"run_memory: peaks {peaks}; beyond torch and Warp {beyond:.0f} MB; wrote {a.out}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
