"""What a trained model's worst test views lose, and to which Gaussians: a diagnosis of sudden drops in test
PSNR (a Gaussian in front of a novel camera that no input constrains).

    python bench/diagnostics/floaters.py RUN_DIR [RUN_DIR ...] [--device cuda] [--data-root ../shared/data]

For each run folder (``config.yaml`` and ``point_cloud.ply``, and ``far_field.json`` when it used one) the scene
is loaded as the run loaded it. Per test view: the PSNR, and each Gaussian's blending weight there (pixels)
against its total over the training views. The Gaussians that carry most of a test view's weight while the
inputs barely use them (``--ratio``: test weight over input weight) are the suspects: the script prints the
worst view's top suspects (distance to the test camera, size, opacity, colour, weights) and the PSNR of every
test view with the suspects of *all* views removed, and with every Gaussian the inputs use less than
``--min-input`` pixels removed, and how far the worst view's suspects and every test camera lie from the camera
path (``warpgs/strategy/clearance.py``; ``path_near``: in the run's near depths, as ``clearance.path`` counts).
``--unseen-sweep 0.05,1,5``: also each view's PSNR without the Gaussians below each of those input weights
(what ``strategy.prune_unseen_at_end`` with that ``strategy.unseen_min_weight`` would leave).
Writes ``floaters.json`` in each run folder (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return -10 * math.log10(max(float(((a.clamp(0, 1) - b) ** 2).mean()), 1e-12))


def load_run(run: Path, device: str, data_root: str | None):
    """A finished run folder as the run saw it: (config, scene, trained model with every SH band on, its far field
    or None, the background colour, the training cameras, the test cameras; cameras as tensors on ``device``)."""
    from warpgs.config import build_config
    from warpgs.configio import read_yaml
    from warpgs.farfield import ElevationFarField
    from warpgs.pipelines.sparse import load_scene_for
    from warpgs.train import background_colour, load_trained

    cfg = build_config([(str(run / "config.yaml"), read_yaml(run / "config.yaml"))])
    if data_root:
        cfg.data.root = data_root
    cfg.train.device = device
    scene = load_scene_for(cfg)
    model = load_trained(run / "point_cloud.ply", device=device)
    model.active_sh_degree = model.max_sh_degree
    ff = ElevationFarField.load(run / "far_field.json") if (run / "far_field.json").is_file() else None
    bgc = torch.tensor(background_colour(cfg, scene), dtype=torch.float32, device=device)
    train = [c.to_torch(device) for c in scene.train]
    test = [c.to_torch(device) for c in scene.test]
    return cfg, scene, model, ff, bgc, train, test


def render_view(model, cam, far_field, background: torch.Tensor, keep: torch.Tensor | None = None) -> torch.Tensor:
    """``model``'s image of ``cam`` (without gradients) over the run's far field (or ``background`` where it had none),
    with only the Gaussians of the bool mask ``keep`` where given."""
    from warpgs.model import GaussianModel

    m = model
    if keep is not None:
        P = {k: v.detach()[keep] for k, v in model.params.items()}
        m = GaussianModel(P["means"], P["quats"], P["scales"], P["opacities"], P["sh0"], P["shN"],
                          max_sh_degree=model.max_sh_degree)
        m.active_sh_degree = model.active_sh_degree
    bg = far_field.image(cam.viewmat, cam.K, cam.width, cam.height) if far_field is not None else background
    with torch.no_grad():
        return m.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg).image


def diagnose(run: Path, device: str, data_root: str | None, ratio: float, min_input: float, top: int,
             sweep: tuple[float, ...] = ()) -> dict:
    from warpgs.strategy import contribution
    from warpgs.strategy.clearance import PathClearance, segment_distance

    cfg, scene, model, ff, bgc, train, test = load_run(run, device, data_root)

    def render(c, keep=None):
        return render_view(model, c, ff, bgc, keep)

    w_in = contribution(model, train)
    suspects = torch.zeros(len(model), dtype=torch.bool, device=device)
    views = []
    for c in test:
        w_t = contribution(model, [c])
        share = w_t / w_t.sum().clamp_min(1e-9)
        sus = (w_t > ratio * w_in.clamp_min(1e-3)) & (share > 1e-3)
        suspects |= sus
        views.append({"name": c.name, "psnr": psnr(render(c), c.image), "suspects": int(sus.sum()),
                      "suspect_share": float(share[sus].sum()), "_w": w_t})
    unseen = w_in < min_input
    for v, c in zip(views, test):
        v["psnr_without_suspects"] = psnr(render(c, ~suspects), c.image)
        v["psnr_without_unseen"] = psnr(render(c, ~unseen), c.image)
        # what strategy.prune_unseen_at_end with strategy.unseen_min_weight t would leave (opacity pruning aside)
        v["psnr_without_unseen_sweep"] = {str(t): psnr(render(c, w_in >= t), c.image) for t in sweep}
    worst = min(views, key=lambda v: v["psnr"])
    cam = test[views.index(worst)]
    w_t = worst.pop("_w")
    order = torch.argsort(w_t, descending=True)[: max(top * 5, top)]
    R, t = cam.viewmat[:3, :3], cam.viewmat[:3, 3]
    rows = []
    with torch.no_grad():
        from warpgs.model import sh_to_rgb

        rgb = sh_to_rgb(model.params["sh0"][:, 0]).clamp(0, 1)
        for i in order.tolist():
            if len(rows) >= top:
                break
            z = float((R @ model.means[i] + t)[2])
            rows.append({"index": i, "test_weight_px": round(float(w_t[i]), 1), "input_weight_px": round(float(w_in[i]), 1),
                         "depth_in_view": round(z, 3), "max_scale": round(float(model.scales[i].max()), 4),
                         "min_scale": round(float(model.scales[i].min()), 5), "opacity": round(float(model.opacities[i]), 3),
                         "rgb": [round(float(x), 3) for x in rgb[i]]})
    for v in views:
        v.pop("_w", None)
    depths_in = [float((c.viewmat[:3, :3] @ model.means.detach().T + c.viewmat[:3, 3:]).T[:, 2].median()) for c in train]
    # where they lie against the camera path of clearance.path, in metres and in near depths (the run's
    # measured bounds when metrics.json has them: the loader's are not what the clearance used)
    metrics = json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").is_file() else {}
    near = float(((metrics.get("init") or {}).get("bounds") or scene.bounds)[0])
    path = PathClearance.build(np.stack([c.viewmat for c in scene.train]), 0.0, order=cfg.pseudo.trajectory.order,
                               device=device)
    on_path = segment_distance(model.means.detach()[[r["index"] for r in rows]], path.a, path.b).tolist()
    for r, d in zip(rows, on_path):
        r["path_m"], r["path_near"] = round(d, 3), round(d / near, 4)
    centres = torch.tensor(np.stack([c.center for c in scene.test]), dtype=torch.float32, device=device)
    for v, d in zip(views, segment_distance(centres, path.a, path.b).tolist()):
        v["camera_path_m"] = round(d, 3)
    return {"run": str(run), "gaussians": len(model), "suspects": int(suspects.sum()), "unseen": int(unseen.sum()),
            "unseen_sweep": {str(t): int((w_in < t).sum()) for t in sweep},
            "scene_bounds": list(map(float, scene.bounds)), "near": near, "median_depth_in_inputs": depths_in,
            "views": views, "worst": worst["name"], "worst_top": rows}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("runs", nargs="+")
    p.add_argument("--device", default="cpu")
    p.add_argument("--data-root", default=None)
    p.add_argument("--ratio", type=float, default=10.0, help="suspect: test weight > ratio x input weight")
    p.add_argument("--min-input", type=float, default=1.0, help="unseen: input weight below this (pixels)")
    p.add_argument("--top", type=int, default=12)
    p.add_argument("--unseen-sweep", default="", help="comma-separated input weights (pixels): each view's PSNR "
                   "without the Gaussians below each (psnr_without_unseen_sweep)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    results = []
    for r in args.runs:
        sweep = tuple(float(x) for x in args.unseen_sweep.split(",") if x.strip())
        res = diagnose(Path(r), args.device, args.data_root, args.ratio, args.min_input, args.top, sweep)
        results.append(res)
        print(f"{r}: {res['gaussians']} Gaussians, {res['suspects']} suspects, {res['unseen']} unseen by the inputs")
        for v in res["views"]:
            print(f"  {v['name']}: PSNR {v['psnr']:.2f} -> {v['psnr_without_suspects']:.2f} without suspects "
                  f"({v['suspects']}, {v['suspect_share']:.0%} of the view's weight), "
                  f"{v['psnr_without_unseen']:.2f} without the unseen")
        print(f"  worst {res['worst']}: top Gaussians (path_m / path_near: from the camera path, near depth "
              f"{res['near']:.2f}; test cameras from it: "
              + ", ".join(f"{v['name']} {v['camera_path_m']:.2f} m" for v in res["views"]) + ")")
        for row in res["worst_top"]:
            print("   ", row)
        out = Path(args.out) if args.out else Path(r) / "floaters.json"
        if not args.out:
            out.write_text(json.dumps(res, indent=1))
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
