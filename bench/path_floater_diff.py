"""What the path-floater pass's two settings take from a trained capture model, and what that costs its test views.

    python bench/path_floater_diff.py RUN_DIR [--device cuda] [--data-root ../shared/data] [--out diff.json]

Session 31 found that at 768x512 the pass on both paths with 9 poses per pair (``train.path_floaters_paths=both``,
``train.path_floaters_poses=9``) costs castle_p30 3 and 6 views 0.4 dB against the spline with 3 poses, where at
384x256 it gained. This script takes a run folder (``config.yaml``, ``point_cloud.ply``, ``far_field.json``), builds
the pass with each setting (the run's ratio and trajectory order) and reports for each:
- how many Gaussians it finds (what it would remove now), and of those only the second setting finds (``extra``);
- where those extra ones lie: the share whose centre projects inside no input's image, and the share within 5% of
  the image's edge of every input that sees it (content beside the inputs' frusta, which poses near an input see
  and the inputs barely do);
- each test view's PSNR with the model as it is, without each setting's Gaussians, and without the extra ones alone.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.floaters import load_run, psnr, render_view  # noqa: E402

SETTINGS = {"spline3": ("spline", 3), "both9": ("both", 9)}


def edge_shares(means: torch.Tensor, cams, margin: float = 0.05) -> tuple[float, float]:
    """(share of ``means`` [M, 3] that project inside no camera's image, share that lies within ``margin`` x the image
    size of the edge in every camera whose image holds it)."""
    if len(means) == 0:
        return 0.0, 0.0
    inside_any = torch.zeros(len(means), dtype=torch.bool, device=means.device)
    central_any = torch.zeros_like(inside_any)
    for c in cams:
        p = means @ c.viewmat[:3, :3].T + c.viewmat[:3, 3]
        z = p[:, 2]
        uv = (p @ c.K.T)[:, :2] / z.clamp_min(1e-6)[:, None]
        W, H = float(c.width), float(c.height)
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        mx, my = margin * W, margin * H
        central = inside & (uv[:, 0] >= mx) & (uv[:, 0] < W - mx) & (uv[:, 1] >= my) & (uv[:, 1] < H - my)
        inside_any |= inside
        central_any |= central
    n = float(len(means))
    return float((~inside_any).sum()) / n, float((inside_any & ~central_any).sum()) / n


def diff(run: Path, device: str, data_root: str | None) -> dict:
    from warpgs.clearance import PathFloaters

    cfg, scene, model, ff, bgc, train, test = load_run(run, device, data_root)
    c0 = scene.train[0]
    found = {}
    for name, (paths, poses) in SETTINGS.items():
        pf = PathFloaters.build(np.stack([c.viewmat for c in scene.train]), c0.K, (c0.width, c0.height),
                                cfg.train.path_floaters or 10.0, per_pair=poses, order=cfg.pseudo.trajectory.order,
                                device=device, paths=paths)
        found[name] = pf.find(model, train, bgc)
    found["extra"] = found["both9"] & ~found["spline3"]

    out = {"run": str(run), "gaussians": len(model), "found": {k: int(v.sum()) for k, v in found.items()}}
    outside, edge = edge_shares(model.means.detach()[found["extra"]], train)
    out["extra_outside_every_input"], out["extra_near_the_edge"] = outside, edge
    out["all_outside_every_input"], out["all_near_the_edge"] = edge_shares(model.means.detach(), train)
    views = []
    for c in test:
        gt = c.image.to(device)
        views.append({k: psnr(render_view(model, c, ff, bgc, None if drop is None else ~drop), gt) for k, drop in
                      (("model", None), ("without_spline3", found["spline3"]), ("without_both9", found["both9"]),
                       ("without_extra", found["extra"]))})
    out["test_views"] = views
    out["test_mean"] = {k: float(np.mean([v[k] for v in views])) for k in views[0]} if views else {}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    for need in ("config.yaml", "point_cloud.ply"):
        if not (args.run / need).is_file():
            ap.error(f"{args.run} is not a finished run folder: no {need}")
    res = diff(args.run, args.device, args.data_root)
    text = json.dumps(res, indent=1)
    print(text)
    (args.out or args.run / "path_floater_diff.json").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
