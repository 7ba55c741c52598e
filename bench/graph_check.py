"""GPU check of the training step as a CUDA graph (``train.cuda_graph``, warpgs/graphstep.py): the same numbers as
the step without it, and what it saves.

    python bench/graph_check.py --data-root DIR [--iterations 1000] [--out FILE.json]

1. The rasterizer with fixed-capacity buffers, captured in a CUDA graph (forward and backward) and replayed, on
   random Gaussians: image, depth, alpha and every gradient equal the normal render's, bit for bit.
2. fern, 3 views, the baseline from the same initial Gaussians (``model.init=frustum``, as bench/train_speed.py),
   trained with and without the graphs: every parameter and every recorded loss equal bit for bit; the time
   of each, the number of recordings and replays.
Writes JSON (default bench/results/graph_check_cuda.json).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.train_speed import Setup, load_scene, machine, make_config  # noqa: E402
from warpgs.render import count_intersections, rasterize  # noqa: E402


def raster_check(n: int = 60000, width: int = 640, height: int = 480, seed: int = 0) -> dict:
    g = torch.Generator(device="cuda").manual_seed(seed)
    dev = "cuda"
    means = (torch.rand(n, 3, device=dev, generator=g) - 0.5) * 2.0
    means[:, 2] += 3.0
    quats = torch.randn(n, 4, device=dev, generator=g)
    scales = 0.005 + 0.03 * torch.rand(n, 3, device=dev, generator=g)
    opac = 0.1 + 0.8 * torch.rand(n, device=dev, generator=g)
    sh = 0.3 * torch.randn(n, 16, 3, device=dev, generator=g)
    viewmat = torch.eye(4, device=dev)
    K = torch.tensor([[500.0, 0, width / 2], [0, 500.0, height / 2], [0, 0, 1]], device=dev)
    w = torch.rand(height, width, 3, device=dev, generator=g)
    params = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac, sh)]

    def run(capacity):
        out = rasterize(*params, viewmat, K, width, height, sh_degree=3, isect_capacity=capacity, check_finite=False)
        loss = (out.image * w).sum() + 0.5 * out.depth.sum() + 0.2 * out.alpha.sum()
        loss.backward()
        return out

    out = run(None)
    base = [out.image.clone(), out.depth.clone(), out.alpha.clone()] + [p.grad.clone() for p in params]
    for p in params:
        p.grad = None
    del out  # its autograd graph holds the leaves' gradient accumulators, made on the default stream
    count = count_intersections(params[0], params[1], params[2], params[3], viewmat, K, width, height)
    cap = count + count // 2
    s = torch.cuda.Stream()
    s.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(s):
        run(cap)
        for p in params:
            p.grad = None
    torch.cuda.current_stream().wait_stream(s)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.stream(s):  # as warpgs.graphstep records (torch.cuda.graph's context refuses this backward)
        graph.capture_begin()
        try:
            gout = run(cap)
        finally:
            graph.capture_end()
    torch.cuda.current_stream().wait_stream(s)
    graph.replay()
    torch.cuda.synchronize()
    got = [gout.image, gout.depth, gout.alpha] + [p.grad for p in params]
    names = ["image", "depth", "alpha", "means", "quats", "scales", "opacities", "sh"]
    equal = {k: bool(torch.equal(a, b)) for k, a, b in zip(names, got, base)}
    # a replay after the inputs changed in place follows them
    with torch.no_grad():
        params[0][:, 0] += 0.01
    for p in params:
        p.grad = None
    out2 = run(None)
    del out2
    ref2 = [out2.image.clone()] + [p.grad.clone() for p in params]
    graph.replay()
    torch.cuda.synchronize()
    equal_after_change = bool(torch.equal(gout.image, ref2[0]))
    return {"gaussians": n, "size": [width, height], "intersections": count, "capacity": cap,
            "bit_equal": equal, "bit_equal_after_inputs_changed": equal_after_change}


def trainer_check(data_root: str | None, iterations: int) -> dict:
    from bench.train_speed import run_warpgs_trainer

    args = argparse.Namespace(data="llff", scene=None, views=3, data_root=data_root, iterations=iterations,
                              device="cuda", set=["model.init=frustum"])
    cfg = make_config(args)
    setup = Setup(cfg, load_scene(cfg, 1))
    rows, models = {}, {}
    for name, graph in (("eager", False), ("graph", True), ("graph_again", True)):
        go, finish, tr = run_warpgs_trainer(setup, iterations, cuda_graph=graph)
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        go()
        torch.cuda.synchronize()
        seconds = time.perf_counter() - t0
        sg = tr.graph
        rows[name] = {"seconds": round(seconds, 3), "gaussians": len(tr.model),
                      "captures": sg.captures if sg else 0, "replays": sg.replays if sg else 0,
                      "off": sg.off if sg else None, "final_loss": tr.losses[-1]}
        models[name] = ({k: v.detach().clone() for k, v in tr.model.params.items()}, list(tr.losses))
        print(name, rows[name], flush=True)
        del tr, go, finish
        torch.cuda.empty_cache()
    pe, le = models["eager"]
    for name in ("graph", "graph_again"):
        pg, lg = models[name]
        rows[name]["params_bit_equal"] = all(pe[k].shape == pg[k].shape and bool(torch.equal(pe[k], pg[k])) for k in pe)
        rows[name]["losses_equal"] = le == lg
    rows["speedup"] = round(rows["eager"]["seconds"] / rows["graph"]["seconds"], 3)
    return rows


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--iterations", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "graph_check_cuda.json")
    args = ap.parse_args(argv)
    result = {"machine": machine("cuda")}
    try:
        result["rasterizer"] = raster_check()
    except Exception as e:  # noqa: BLE001 - recorded, and the trainer's check still runs
        result["rasterizer"] = {"error": f"{type(e).__name__}: {e}"}
    print("rasterizer", result["rasterizer"], flush=True)
    result["trainer"] = trainer_check(args.data_root, args.iterations)
    print(json.dumps(result["trainer"], indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
