"""Evaluation and run outputs: metrics over views (PSNR, SSIM, LPIPS when weights exist; masked where the
scene's protocol says), the renders beside their ground truth, metrics.json and the files of a run folder.

    ev = evaluate_views(trainer.render, scene.test, masked=..., scene_name=..., lpips_weights=..., device=...)
    metrics = run_metrics(trainer, ev, train_ev, fps)
    write_run_outputs(trainer, metrics)      # point_cloud.ply, init_points.ply, checkpoint, config.yaml, metrics.json
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import torch

from warpgs.config import save_config
from warpgs.metrics import LPIPSMetric, mean_or_none, peak_memory_mb, psnr, ssim
from warpgs.model import size_report


def save_png(path: Path, image: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path)


def evaluate_views(render, cams, *, masked: bool, scene_name: str, lpips_weights, device, save_dir=None,
                   lpips: bool = True) -> dict:
    """Metrics over ``cams`` (``render(cam)`` gives the image), masked where the scene's protocol says;
    with ``save_dir``, writes each render beside its ground truth as a PNG."""
    lp = LPIPSMetric(lpips_weights, device) if lpips else None
    views = []
    with torch.no_grad():
        for i, cam in enumerate(cams):
            img = render(cam).image.clamp(0, 1)
            mask = cam.mask if masked else None
            if masked and mask is None:
                raise ValueError(f"{scene_name}: masked evaluation, but view {cam.name} has no mask")
            row = {"name": cam.name, "psnr": psnr(img, cam.image, mask), "ssim": ssim(img, cam.image, mask)}
            if lp is not None:
                row["lpips"] = lp.value(img, cam.image, mask)
            views.append(row)
            if save_dir is not None:
                pair = torch.cat([img, cam.image], dim=1).cpu().numpy()
                save_png(Path(save_dir) / f"{i:03d}_{cam.name}.png", pair)
    mean = {"psnr": mean_or_none([v["psnr"] for v in views]), "ssim": mean_or_none([v["ssim"] for v in views])}
    result = {"mean": mean, "views": views, "masked": masked}
    if lp is not None:
        mean["lpips"] = mean_or_none([v["lpips"] for v in views])
        if lp.missing:
            result["lpips_missing"] = lp.missing
    return result


def run_metrics(trainer, ev: dict, train_ev: dict, fps: float) -> dict:
    """metrics.json of a finished run: test and training-view metrics (``ev``, ``train_ev`` from
    ``evaluate_views``), speed, size, memory, divergences survived, the initial geometry and stage times."""
    tr = trainer
    finite = [x for x in tr.losses if math.isfinite(x)]
    cam0 = tr.scene.test[0] if tr.scene.test else tr.scene.train[0]
    metrics = {
        "method": tr.cfg.method,
        "scene": tr.scene.name,
        "train_views": len(tr.scene.train),
        "test_views": len(tr.scene.test),
        "resolution": [cam0.width, cam0.height],
        "iterations": tr.step,
        "psnr": ev["mean"]["psnr"],
        "ssim": ev["mean"]["ssim"],
        "lpips": ev["mean"].get("lpips"),
        "masked": ev["masked"],
        "initial_psnr": (tr.initial or {}).get("psnr"),
        "train_psnr": train_ev["mean"]["psnr"],
        "num_gaussians": len(tr.model),
        "num_gaussians_before_compaction": tr.n_before_compaction,
        "train_time_s": round(tr.train_time, 2),
        "render_fps": round(fps, 2),
        **peak_memory_mb(tr.device),
        "device": str(tr.device),
        "seed": tr.cfg.train.seed,
        "final_loss": float(np.mean(finite[-50:])) if finite else None,
        "skipped_steps": sum(1 for x in tr.losses if not math.isfinite(x)),
        "recoveries": tr.recoveries,  # divergences survived: step, cause, step rolled back to, lr scale after
        "lr_scale": tr.lr_scale,
        "max_loss_ratio": round(tr.guard.max_loss_ratio, 3),  # largest loss / running median (train.explode_factor)
        "curve": tr.curve,
        "per_view": ev["views"],
    }
    geo = getattr(tr.scene, "geometry", None)
    if geo is not None:
        metrics["init"] = geo.summary()
    metrics["stage_times_s"] = {**{f"init_{k}": round(v, 2) for k, v in (geo.times.items() if geo else [])},
                                "train_s": round(tr.train_time, 2)}
    if tr.stopped_early:
        metrics["stopped_early"] = tr.stopped_early
    if "lpips_missing" in ev:
        metrics["lpips_missing"] = ev["lpips_missing"]
    size = size_report(tr.model)  # SH degree stored, float32 parameter bytes, PLY file bytes
    metrics.update(sh_degree=size["sh_degree"], param_bytes=size["param_bytes"], ply_bytes=size["ply_bytes"])
    if tr.compact_report is not None:
        metrics["compact"] = tr.compact_report
    return metrics


def write_run_outputs(trainer, metrics: dict) -> None:
    """The run folder: point_cloud.ply, init_points.ply (the initial geometry, for open3d or
    ``python -m warpgs.viz``), the final checkpoint, config.yaml (the resolved config) and metrics.json
    (written last, through a rename)."""
    from warpgs.viz import save_origin_ply

    out = trainer.out
    out.mkdir(parents=True, exist_ok=True)
    trainer.export_ply()
    geo = getattr(trainer.scene, "geometry", None)
    if geo is not None and len(geo.xyz):
        save_origin_ply(out / "init_points.ply", geo.xyz, geo.rgb)
    trainer.save_checkpoint()
    save_config(trainer.cfg, out / "config.yaml")
    tmp = out / "metrics.json.tmp"
    tmp.write_text(json.dumps(metrics, indent=2))
    tmp.replace(out / "metrics.json")


__all__ = ["evaluate_views", "run_metrics", "save_png", "write_run_outputs"]
