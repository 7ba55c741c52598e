"""Where the race's two sides (bench/perf/race_gsplat.py) part in their Gaussian counts: gsplat 1.5.3's own loop
against warpgs's trainer set to the same recipe, from the same initial Gaussians.

    python bench/diagnostics/densify_vs_gsplat.py --scale castle9 --steps 3000 --out densify_vs_gsplat.json

Two measurements per scale (CUDA, gsplat importable):

- ``statistic``: on the initial Gaussians, for each training view, what the densification statistic sees in one
  step of each rasterizer with the recipe's loss at SH degree 0: the Gaussians visible (radii > 0 on both axes) on
  each side and on both, and over those on both the 2D gradient norm in normalised device units (gsplat's
  ``grow_grad2d`` units): the median and largest relative difference, and how many are above ``grow_grad2d`` on
  each side;
- ``counts``: both sides trained in chunks of ``refine_every`` steps to ``--steps``, the Gaussian count after each
  chunk (the same views in the same order on both).
"""

from __future__ import annotations

import json
import sys
import traceback
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT), str(ROOT / "bench" / "perf")]

import race_gsplat as race  # noqa: E402


def statistic(sc, grow_grad2d: float) -> list[dict]:
    from warpgs.losses import dssim
    from warpgs.render import means2d_grad_norm

    lam = race.RECIPE["ssim_lambda"]

    def recipe_loss(img, gt):  # the same loss on both sides (simple_trainer's, with warpgs's D-SSIM)
        return (img - gt).abs().mean() * (1.0 - lam) + dssim(img, gt) * lam

    rows = []
    # the initial Gaussians, never updated here: each render's 2D means are a tensor of its own, whose gradient is
    # that view's alone
    g_side, w_side = race.GsplatSide(sc, 1), race.WarpgsSide(sc, 1)
    for i, cam in enumerate(sc.train_cams):
        img, info = g_side.rasterize(cam, 0)
        info["means2d"].retain_grad()
        loss = recipe_loss(img, cam.image)
        loss.backward()
        g_grad = info["means2d"].grad[0].clone()
        g_grad[:, 0] *= cam.width / 2.0
        g_grad[:, 1] *= cam.height / 2.0
        g_norm = g_grad.norm(dim=-1)
        g_vis = (info["radii"][0] > 0).all(dim=-1)

        out = w_side.tr.render(cam)
        wimg = out.image.reshape(cam.image.shape)
        wloss = recipe_loss(wimg, cam.image)
        wloss.backward()
        w_norm = means2d_grad_norm(out, cam.width, cam.height)
        w_vis = (out.radii > 0).all(dim=-1)
        both = g_vis & w_vis
        rel = (w_norm[both] - g_norm[both]).abs() / g_norm[both].clamp_min(1e-12)
        rows.append({"view": i, "loss_gsplat": float(loss), "loss_warpgs": float(wloss),
                     "image_max_abs_diff": float((wimg - img).abs().max()),
                     "visible_gsplat": int(g_vis.sum()), "visible_warpgs": int(w_vis.sum()), "visible_both": int(both.sum()),
                     "grad_rel_diff_median": float(rel.median()) if rel.numel() else None,
                     "grad_rel_diff_max": float(rel.max()) if rel.numel() else None,
                     "grad_ratio_median": float((w_norm[both] / g_norm[both].clamp_min(1e-20)).median()) if rel.numel() else None,
                     "above_gsplat": int((g_norm[g_vis] > grow_grad2d).sum()),
                     "above_warpgs": int((w_norm[w_vis] > grow_grad2d).sum())})
    return rows


def counts(sc, steps: int, every: int) -> dict:
    trace = {}
    for kind in ("gsplat", "warpgs"):
        side = race.SIDES[kind](sc, steps)
        trace[kind] = []
        for stop in range(every, steps + 1, every):
            side.train(stop)
            trace[kind].append([stop, len(side)])
        del side
        torch.cuda.empty_cache()
    return trace


def main(argv=None) -> dict:
    import argparse

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scale", action="append", choices=sorted(race.SCALES), required=True)
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--data-root", default=None)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    args = race.parse_args(["--scale", a.scale[0]] + (["--data-root", a.data_root] if a.data_root else []))
    strategy = race.gsplat_strategy_defaults()
    result = {}
    for name in a.scale:
        sc = race.Scale.load(name, args, strategy)
        result[name] = {}
        for part, fn in (("statistic", lambda: statistic(sc, strategy["grow_grad2d"])),
                         ("counts", lambda: counts(sc, a.steps, strategy["refine_every"]))):
            try:
                result[name][part] = fn()
            except Exception:  # noqa: BLE001 - a diagnostic: say what failed, keep the other part
                result[name][part] = {"error": traceback.format_exc()[-1500:]}
        print(name, json.dumps(result[name])[:2000], flush=True)
        if a.out:
            Path(a.out).write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
