"""Radius-gated insertion benchmark: ``warpgs.densify.insert.insert_points`` on N existing Gaussian
centres and N candidate points.

    python bench/perf/insertion.py --device cuda        # 1M existing + 1M candidates (writes bench/results/perf/insertion_cuda.json)
    python bench/perf/insertion.py --device cpu         # 20K + 20K (Warp's CPU kernels run on one thread)
    python bench/perf/insertion.py --device cuda --n 250000 --out /tmp/x.json

Two point layouts, both seeded:
  uniform  existing and candidates uniform in the unit cube; radius = the mean spacing N^(-1/3)
  surface  existing on the six faces of the unit cube and a sphere inside (a scanned room), candidates
           from the same surfaces with 0.5-spacing noise; radius = the mean spacing on the surface

Timed: the whole insertion (HashGrid over the existing centres and radius query, greedy thinning of
the survivors in parallel rounds, HashGrid k-nearest spacing for the new scales) and the radius query
alone, each a median over --iters runs after a warm-up, with the device synchronised around each run.
Correctness on the same data: for a random sample of added points the distance to every existing
centre is computed by brute force (chunked torch.cdist); the JSON records the violations (expected 0).
No open3d here: it is not installed on the GPU machine.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import warp as wp  # noqa: E402

from warpgs.densify.insert import InsertConfig, insert_points, within_radius  # noqa: E402


def surface_points(n: int, g: torch.Generator) -> torch.Tensor:
    """n points on the unit cube's faces (6/7 of them) and on a sphere of radius 0.25 at its centre."""
    n_box = n * 6 // 7
    face = torch.randint(0, 6, (n_box,), generator=g)
    p = torch.rand(n_box, 3, generator=g)
    axis = face % 3
    p[torch.arange(n_box), axis] = (face // 3).float()
    s = torch.randn(n - n_box, 3, generator=g)
    s = 0.5 + 0.25 * s / s.norm(dim=1, keepdim=True)
    return torch.cat([p, s])


def make_case(layout: str, n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    if layout == "uniform":
        existing = torch.rand(n, 3, generator=g)
        cand = torch.rand(n, 3, generator=g)
        radius = n ** (-1.0 / 3.0)
    else:
        area = 6.0 + 4.0 * 3.14159265 * 0.25**2
        spacing = (area / n) ** 0.5
        existing = surface_points(n, g)
        cand = surface_points(n, g) + 0.5 * spacing * torch.randn(n, 3, generator=g)
        radius = spacing
    return existing, cand, torch.rand(n, 3, generator=g), float(radius)


def sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def timed(fn, device: str, iters: int) -> tuple[list[float], object]:
    out = None
    times = []
    for _ in range(iters):
        sync(device)
        t0 = time.perf_counter()
        out = fn()
        sync(device)
        times.append((time.perf_counter() - t0) * 1e3)
    return times, out


def brute_force_violations(existing: torch.Tensor, added: torch.Tensor, radius: float, sample: int, g) -> tuple[int, int]:
    """(checked, violations): added points (a random sample) with an existing centre within radius."""
    if added.shape[0] == 0:
        return 0, 0
    pick = torch.randperm(added.shape[0], generator=g)[:sample].to(added.device)
    q = added[pick].double()
    best = torch.full((q.shape[0],), float("inf"), dtype=torch.float64, device=added.device)
    step = max(1, (1 << 26) // max(1, q.shape[0]))
    for s in range(0, existing.shape[0], step):
        d = torch.cdist(q, existing[s:s + step].double())
        best = torch.minimum(best, d.min(dim=1).values)
    return int(q.shape[0]), int((best <= radius).sum().item())


def run(device: str, n: int, iters: int, sample: int) -> dict:
    results = []
    for layout in ("uniform", "surface"):
        existing, cand, colors, radius = make_case(layout, n)
        existing, cand, colors = existing.to(device), cand.to(device), colors.to(device)
        cfg = InsertConfig(radius=radius)
        insert_points(existing, cand, colors, config=cfg)  # warm-up: kernel compilation, allocator
        within_radius(existing, cand, radius)
        t_all, res = timed(lambda: insert_points(existing, cand, colors, config=cfg), device, iters)
        t_query, _ = timed(lambda: within_radius(existing, cand, radius), device, iters)
        checked, bad = brute_force_violations(existing, res.means, radius, sample, torch.Generator().manual_seed(1))
        row = {
            "layout": layout,
            "existing": n,
            "candidates": n,
            "radius": radius,
            "insert_ms_median": statistics.median(t_all),
            "insert_ms_all": t_all,
            "radius_query_ms_median": statistics.median(t_query),
            "added": int(res.added.sum().item()),
            "rejected_near_existing": int(res.near_existing.sum().item()),
            "thinning_rounds": res.rounds,
            "bruteforce_checked": checked,
            "bruteforce_violations": bad,
        }
        print(json.dumps({k: v for k, v in row.items() if k != "insert_ms_all"}), flush=True)
        results.append(row)
    return {"results": results}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--n", type=int, default=None, help="existing = candidate count (default 1M on CUDA, 20K on the CPU)")
    ap.add_argument("--iters", type=int, default=None)
    ap.add_argument("--sample", type=int, default=None, help="added points checked by brute force")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    cuda = a.device.startswith("cuda")
    if cuda and not torch.cuda.is_available():
        print("CUDA is not available here; use --device cpu", file=sys.stderr)
        return 2
    n = a.n or (1_000_000 if cuda else 20_000)
    iters = a.iters or (10 if cuda else 3)
    sample = a.sample or (20_000 if cuda else 2_000)
    body = run(a.device, n, iters, sample)
    info = {
        "device": a.device,
        "device_name": torch.cuda.get_device_name() if cuda else platform.processor() or platform.machine(),
        "torch": torch.__version__,
        "warp": wp.__version__,
        "iters": iters,
        **body,
    }
    out = Path(a.out) if a.out else ROOT / "bench" / "results" / "perf" / f"insertion_{'cuda' if cuda else 'cpu'}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(info, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
