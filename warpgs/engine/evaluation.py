"""Evaluation and run outputs: metrics over views (PSNR, SSIM, LPIPS when weights exist; masked where the
scene's protocol says), the renders beside their ground truth, metrics.json and the files of a run folder.

    ev = evaluate_views(trainer.render, scene.test, masked=..., scene_name=..., lpips_weights=..., device=...)
    metrics = run_metrics(trainer, ev, train_ev, fps)
    write_run_outputs(trainer, metrics)      # point_cloud.ply, init_points.ply, checkpoint, config.yaml, metrics.json
    write_flythrough(trainer, path); write_report(out, metrics, history, baseline)   # the full method's extras
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from warpgs.config import save_config
from warpgs.metrics import LPIPSMetric, mean_or_none, peak_memory_mb, psnr, render_fps, ssim
from warpgs.model import size_report
from warpgs.runfolder import atomic_write
from warpgs.viz import save_image, to_uint8


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
                save_image(Path(save_dir) / f"{i:03d}_{cam.name}.png", pair)
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
        "max_loss_ratio": round(tr.guard.max_loss_ratio, 3),  # largest loss / running median (guard.explode_factor)
        "curve": tr.curve,
        "per_view": ev["views"],
    }
    geo = getattr(tr.scene, "geometry", None)
    if geo is not None:
        metrics["init"] = geo.summary()
    metrics["stage_times_s"] = {**{f"init_{k}": round(v, 2) for k, v in (geo.times.items() if geo else [])},
                                "train_s": round(tr.train_time, 2)}
    metrics["stage_times_s"].update({k: round(v, 2) for k, v in tr.bg.components.times().items()})  # far_field_s
    if getattr(tr, "path_floaters_time", None) is not None:
        metrics["stage_times_s"]["path_floaters_s"] = round(tr.path_floaters_time, 2)
    if getattr(tr, "held", None):
        metrics["hold_geometry"] = tr.held
    # the step growth stopped at, as the run resolved it (strategy.refine_stop_fraction; 0 when held)
    metrics["refine_stop_iter"] = tr.cfg.strategy.refine_stop_iter
    if tr.graph is not None:  # train.cuda_graph: how many steps ran as replays (warpgs.engine.graphstep)
        g = tr.graph
        metrics["cuda_graph"] = {"recordings": g.captures, "replays": g.replays, "cut_short": g.cut, "off": g.off}
    if tr.stopped_early:
        metrics["stopped_early"] = tr.stopped_early
    if "lpips_missing" in ev:
        metrics["lpips_missing"] = ev["lpips_missing"]
    size = size_report(tr.model)  # SH degree stored, float32 parameter bytes, PLY file bytes
    metrics.update(sh_degree=size["sh_degree"], param_bytes=size["param_bytes"], ply_bytes=size["ply_bytes"])
    metrics.update(tr.stage_records)  # (compact mode's ``compact``)
    return metrics


def finish_run(tr, baseline: dict | None = None) -> dict:
    """After training ``tr`` (a ``Trainer``): a checkpoint of the trained state (unless one was written at this
    step), the final pruning (if asked), the stages, test metrics and renders, FPS, PLY, final checkpoint,
    metrics.json, then the method's records and outputs (``baseline``: the baseline run's metrics, for its
    report)."""
    out = tr.out
    if out is not None and tr.saved_step != tr.step:
        # the trained state, before the final pruning changes it: an interrupt while the results are written
        # loses no training (--resume writes them from here, as an uninterrupted run would)
        tr.save_checkpoint()
    if tr.cfg.clearance.floaters_final:  # the camera path's floaters (warpgs.strategy.clearance.PathPruning)
        tr.path_pruning.remove_floaters(tr.context, tr.step)
    if tr.cfg.strategy.prune_unseen_at_end:  # what no training view uses
        if tr.n_before_compaction is None:
            tr.n_before_compaction = len(tr.model)
        removed = tr.strategy.prune_unseen(tr.model, tr.optimizer, tr.state, tr.train_cams, tr.background)
        if removed:
            tr.log(f"warpgs: pruning the unseen removed {removed} of {tr.n_before_compaction} Gaussians")
    for stage in tr.stages:  # (Trainer.add_stage)
        record = stage.before_evaluation(tr.context)
        if record is not None:
            tr.stage_records[stage.name] = record
        if tr.n_before_compaction is None:
            tr.n_before_compaction = stage.size_before
        tr.step += tr.reserved_steps  # the stage trained the run's last steps
        tr.reserved_steps = 0
    ev = tr.evaluate(save_dir=(out / "test") if out is not None and tr.cfg.eval.save_images else None)
    train_ev = tr.evaluate(tr.train_cams, lpips=False)
    fps = render_fps(lambda i: tr.render(tr.test_cams[i] if tr.test_cams else tr.train_cams[i]),
                     len(tr.test_cams) or len(tr.train_cams), tr.cfg.eval.fps_repeats, tr.device)
    metrics = run_metrics(tr, ev, train_ev, fps)
    if tr.pair is not None:
        metrics["co_reg"] = tr.pair.report()
    if out is not None:
        write_run_outputs(tr, metrics)
    return tr.method.finish(metrics, baseline)


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
    trainer.bg.components.save(out)  # far_field.json
    save_config(trainer.requested_cfg, out / "config.yaml")  # as requested; what the run derived from it is recorded
    #   in metrics.json (hold_geometry) and derived again on --resume
    write_metrics(out, metrics)


def write_metrics(out: Path, metrics: dict) -> Path:
    """``out``/metrics.json, through a temporary file and a rename (never half written)."""
    text = json.dumps(metrics, indent=2)
    return atomic_write(out / "metrics.json", lambda tmp: tmp.write_text(text))


# ----------------------------------------------------------------------------------------------------
# the full method's outputs beside these: fly-through, charts, report


def write_flythrough(trainer, path: Path, frames_per_segment: int = 24, max_frames: int = 120,
                     max_width: int = 512) -> Path | None:
    """A GIF along the interpolated path through the inputs (the scene's capture path, ``trainer.cameras``:
    the trajectories the pseudo views use): ``frames_per_segment`` between neighbouring inputs, fewer when the
    path would pass ``max_frames`` in all, rendered at most ``max_width`` pixels wide, its frames in one palette
    (``shared_palette``)."""
    cams = trainer.train_cams
    if len(cams) < 2:
        return None
    cam0 = cams[0]
    per_segment = max(2, min(frames_per_segment, max_frames // max(1, len(cams) - 1)))
    s = min(1.0, max_width / cam0.width)
    width, height = max(1, round(cam0.width * s)), max(1, round(cam0.height * s))
    K = cam0.K.clone()
    K[:2] *= torch.tensor([[width / cam0.width], [height / cam0.height]], dtype=K.dtype, device=K.device)
    frames = []
    with torch.no_grad():
        for traj in trainer.cameras.trajectories(per_segment):
            for vm in traj.viewmats:
                v = torch.as_tensor(vm, dtype=torch.float32, device=trainer.device)
                view = SimpleNamespace(viewmat=v, K=K, width=width, height=height)
                bg = trainer.background_for(view, keep=False)  # a one-off pose: nothing kept
                frames.append(to_uint8(trainer.model.render(v, K, width, height, background=bg).image))
    frames = shared_palette(frames)
    # through a rename: an interrupted run leaves no half-written GIF; optimize=False: Pillow's optimize would give
    # each frame its own reordered palette
    return atomic_write(path, lambda tmp: frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:],
                                                         duration=80, loop=0, optimize=False))


def shared_palette(frames: list[np.ndarray], sample_pixels: int = 65_536) -> list:
    """``frames`` (uint8 [H, W, 3], one size) as PIL palette images sharing one adaptive palette of 256 colours:
    median cut refined by k-means on every frame's pixels at the stride that keeps about ``sample_pixels`` (the
    quality was the same from 26k to 330k of them; k-means added 1.3 dB to median cut alone), each frame then mapped
    to its nearest colours. Pillow's GIF writer would quantise each RGB frame by median cut over all its pixels,
    nearly all of its time: on 120 frames of 512x341 (pans over castle_p30's photos) 10.7 s on the 2-core CPU
    machine (17 s on the GPU machine) against 0.46 s here. PSNR of the decoded frames against the given ones:
    39.2 dB here, 40.3 dB one palette a frame; the same photos blurred, closer to renders: 39.8 against 41.1 dB. The
    worst frame is better here (38.2 against 37.5 dB, 38.8 against 38.1). Floyd-Steinberg dithering would cost
    1.5 dB more. One palette also keeps flat colours from flickering between frames."""
    from PIL import Image

    step = max(1, math.ceil(math.sqrt(sum(f.shape[0] * f.shape[1] for f in frames) / sample_pixels)))
    sample = np.ascontiguousarray(np.concatenate([f[::step, ::step] for f in frames]))
    palette = Image.fromarray(sample).quantize(colors=256, method=Image.Quantize.MEDIANCUT, kmeans=1)
    return [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]


def write_report(out: Path, metrics: dict, history: list[dict], baseline: dict | None = None) -> Path:
    """report.md with PNG charts: test PSNR per cycle (baseline as a line) and time per stage."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    charts = out / "charts"
    charts.mkdir(parents=True, exist_ok=True)
    cyc = [h["cycle"] for h in history]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.plot(cyc, [h["psnr"] for h in history], "o-", label="full method")
    if baseline is not None and baseline.get("psnr") is not None:
        ax.axhline(baseline["psnr"], color="gray", ls="--", label=f"baseline ({baseline['iterations']} it)")
    ax.set_xlabel("cycle (0 = before the first pseudo views)")
    ax.set_ylabel("test PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(charts / "psnr_per_cycle.png", dpi=120)
    plt.close(fig)

    stages = [("train_s", "training"), ("pseudo_views_s", "pseudo views"), ("densify_s", "densification")]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    bottom = np.zeros(len(history))
    for key, label in stages:
        vals = np.array([h.get(key, 0.0) or 0.0 for h in history])
        ax.bar(cyc, vals, bottom=bottom, label=label)
        bottom += vals
    ax.set_xlabel("cycle")
    ax.set_ylabel("wall time (s)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(charts / "time_per_stage.png", dpi=120)
    plt.close(fig)

    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    lines = [f"# {metrics['method']} on {metrics['scene']}", "",
             f"{metrics['train_views']} training views, {metrics['test_views']} test views at "
             f"{metrics['resolution'][0]}x{metrics['resolution'][1]}, {metrics['iterations']} iterations on "
             f"{metrics['device']}.", "",
             "| run | PSNR | SSIM | LPIPS | Gaussians | training time (s) |", "|---|---|---|---|---|---|"]
    for name, m in (("baseline", baseline), ("full method", metrics)):
        if m is not None:
            lines.append(f"| {name} | {f(m['psnr'], '.2f')} | {f(m['ssim'], '.3f')} | {f(m.get('lpips'), '.3f')} | "
                         f"{m['num_gaussians']} | {f(m['train_time_s'], '.1f')} |")
    lines += ["", "## Per cycle", "", "| cycle | step | PSNR | SSIM | Gaussians | added | pseudo views (s) | "
              "densification (s) | training (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for h in history:
        lines.append(f"| {h['cycle']} | {h['step']} | {f(h['psnr'], '.2f')} | {f(h['ssim'], '.3f')} | "
                     f"{h['num_gaussians']} | {h.get('added', '-')} | {f(h.get('pseudo_views_s'), '.1f')} | "
                     f"{f(h.get('densify_s'), '.1f')} | {f(h.get('train_s'), '.1f')} |")
    lines += ["", f"Pseudo-view loss: {metrics.get('pseudo_loss', 'n/a')}"
              + (f" (LPIPS unavailable: {metrics['lpips_fallback_reason']})" if metrics.get("lpips_fallback_reason")
                 else ""), "",
              "![test PSNR per cycle](charts/psnr_per_cycle.png)", "", "![time per stage](charts/time_per_stage.png)",
              "", "Outputs: `cycle_N/pseudo/` (pseudo views, guidance, uncertainty), `cycle_N/densified.ply` "
              "(`python -m warpgs.viz` colours kept / added / removed), `point_cloud.ply`, `test/`, "
              "`flythrough.gif`, `metrics.json`."]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


__all__ = ["evaluate_views", "run_metrics", "shared_palette", "write_flythrough", "write_metrics", "write_report",
           "write_run_outputs"]
