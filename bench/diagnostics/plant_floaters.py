"""Which test cameras the path-floater pass (``clearance.floaters``, ``warpgs/strategy/clearance.py`` ``PathFloaters``)
protects: plant an opaque, dark Gaussian on each test camera's optical axis at several distances in front of it,
in a trained model, and report for each whether the pass finds it with N poses per pair of inputs (on the pseudo
views' spline, and on it and the straight line between the inputs: ``clearance.floaters_paths``), and whether
the path clearance (``clearance.path``, ``PathClearance``, built as the run's trainer builds it) takes it.

    python bench/diagnostics/plant_floaters.py RUN_DIR [--depths 0.3,0.6,1,2] [--poses 3,9,17] [--device cpu]
                                   [--data-root ../shared/data] [--out FILE.json]

Each planted Gaussian is a sphere of radius 0.05 x its distance (about 2% of the view's pixels), opacity 0.998,
colour near black: what was found in front of castle_p30's frame 8 when its test PSNR collapsed.
Prints and writes, per distance: the planted Gaussians' weight (pixels) in their test view and in all inputs
together, and per pose count which of them the pass finds (ratio ``--ratio``, as ``clearance.floaters``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def planted(params: dict, points: np.ndarray, radius: np.ndarray, max_sh_degree: int):
    """A ``GaussianModel`` of ``params`` plus opaque dark spheres at ``points`` [n, 3] of ``radius`` [n]."""
    from warpgs.model import GaussianModel

    n = len(points)
    P = {k: v.detach().clone() for k, v in params.items()}
    dt, dev = P["means"].dtype, P["means"].device
    P["means"] = torch.cat([P["means"], torch.as_tensor(points, dtype=dt, device=dev)])
    P["quats"] = torch.cat([P["quats"], torch.tensor([[1.0, 0, 0, 0]], dtype=dt, device=dev).repeat(n, 1)])
    P["scales"] = torch.cat([P["scales"], torch.log(torch.as_tensor(radius, dtype=dt, device=dev))[:, None].repeat(1, 3)])
    P["opacities"] = torch.cat([P["opacities"], torch.full((n,), 6.0, dtype=dt, device=dev)])  # sigmoid(6) = 0.998
    P["sh0"] = torch.cat([P["sh0"], torch.full((n,) + tuple(P["sh0"].shape[1:]), -1.5, dtype=dt, device=dev)])
    P["shN"] = torch.cat([P["shN"], torch.zeros((n,) + tuple(P["shN"].shape[1:]), dtype=dt, device=dev)])
    m = GaussianModel(P["means"], P["quats"], P["scales"], P["opacities"], P["sh0"], P["shN"], max_sh_degree=max_sh_degree)
    m.active_sh_degree = max_sh_degree
    return m


def main(argv=None) -> int:
    from warpgs.strategy.clearance import PathFloaters
    from warpgs.config import build_config
    from warpgs.configio import read_yaml
    from warpgs.pipelines.sparse import load_scene_for
    from warpgs.strategy import contribution
    from warpgs.train import Trainer, load_trained

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("run")
    p.add_argument("--depths", default="0.3,0.6,1,2")
    p.add_argument("--poses", default="3,9,17")
    p.add_argument("--ratio", type=float, default=10.0)
    p.add_argument("--device", default="cpu")
    p.add_argument("--data-root", default=None)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    run = Path(args.run)
    cfg = build_config([(str(run / "config.yaml"), read_yaml(run / "config.yaml"))])
    if args.data_root:
        cfg.data.root = args.data_root
    cfg.train.device = args.device
    scene = load_scene_for(cfg)
    clearance = Trainer(cfg, scene).clearance  # the run's initial geometry, bounds and path, as it trained
    model = load_trained(run / "point_cloud.ply", device=args.device)
    train = [c.to_torch(args.device) for c in scene.train]
    test = [c.to_torch(args.device) for c in scene.test]
    names = [getattr(c, "name", str(i)) for i, c in enumerate(scene.test)]
    viewmats = np.array([c.viewmat.detach().cpu().numpy() for c in train], np.float64)
    order = cfg.pseudo.trajectory.order  # as the trainer builds its pass
    n0 = len(model)
    rows = []
    for depth in (float(x) for x in args.depths.split(",")):
        pts = []
        for c in test:
            V = c.viewmat.detach().cpu().double().numpy()
            pts.append(-V[:3, :3].T @ V[:3, 3] + depth * V[2, :3])  # the camera centre + depth x its optical axis
        m = planted(model.params, np.array(pts), np.full(len(pts), 0.05 * depth), model.max_sh_degree)
        row = {"depth_m": depth,
               "test_weight_px": {n: round(float(contribution(m, [c])[n0 + i]), 1) for i, (n, c) in enumerate(zip(names, test))},
               "input_weight_px": dict(zip(names, (round(float(x), 1) for x in contribution(m, train)[n0:])))}
        if clearance is not None:
            inside = clearance.inside(m.means.detach()[n0:])
            row["taken_by_path_clearance"] = dict(zip(names, (bool(x) for x in inside)))
        for paths in ("spline", "both"):
            for k in (int(x) for x in args.poses.split(",")):
                pf = PathFloaters.build(viewmats, train[0].K.detach().cpu().numpy(), (train[0].width, train[0].height),
                                        args.ratio, per_pair=k, order=order, device=args.device, paths=paths)
                found = pf.find(m, train)[n0:]
                key = f"found_with_{k}_poses" + ("" if paths == "spline" else "_on_both_paths")
                row[key] = dict(zip(names, (bool(x) for x in found)))
        rows.append(row)
        print(json.dumps(row), flush=True)
    res = {"run": str(run), "gaussians": n0, "order": order, "ratio": args.ratio, "rows": rows,
           "clearance_radius_m": None if clearance is None else clearance.radius,
           "clearance_segments_dropped": None if clearance is None else clearance.dropped}
    out = Path(args.out) if args.out else run / "plant_floaters.json"
    out.write_text(json.dumps(res, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
