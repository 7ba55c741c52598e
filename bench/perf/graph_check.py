"""GPU check of the training step as a CUDA graph (``train.cuda_graph``, warpgs/graphstep.py): the same numbers as
the step without it, and what it saves.

    python bench/perf/graph_check.py --data-root DIR [--iterations 1000] [--out FILE.json]

fern, 3 views (``--data``, ``--scene``, ``--views``), the baseline from the same initial Gaussians (``model.init=frustum``,
as bench/perf/train_speed.py; ``--set`` adds config overrides, e.g. dropout, opacity noise, the far field), trained
without the graphs and twice with them: every parameter and every recorded loss equal bit for bit; the time of each,
the number of recordings and replays. (The fixed-capacity render itself is checked against the counted one bit for
bit on both devices by tests/test_rasterizer.py.)
Writes JSON (default outputs/bench/graph_check_cuda.json).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench.perf.train_speed import Setup, load_scene, machine, make_config, write_result  # noqa: E402


def trainer_check(data_root: str | None, iterations: int, data: str = "llff", scene: str | None = None,
                  views: int = 3, sets: tuple = ()) -> dict:
    from bench.perf.train_speed import run_warpgs_trainer

    args = argparse.Namespace(data=data, scene=scene, views=views, data_root=data_root, iterations=iterations,
                              device="cuda", set=["model.init=frustum", *sets])
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
    ap.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench" / "graph_check_cuda.json")
    ap.add_argument("--data", default="llff")
    ap.add_argument("--scene", default=None)
    ap.add_argument("--views", type=int, default=3)
    ap.add_argument("--set", action="append", default=[],
                    help="config overrides over plain 3D-GS (e.g. train.drop_rate=0.2: dropout's draws in the graph)")
    args = ap.parse_args(argv)
    result = {"machine": machine("cuda"), "data": args.data, "scene": args.scene, "views": args.views,
              "set": args.set}
    result["trainer"] = trainer_check(args.data_root, args.iterations, args.data, args.scene, args.views, args.set)
    print(json.dumps(result["trainer"], indent=1))
    write_result(args.out, result)
    return result


if __name__ == "__main__":
    main()
