"""Stability bench (issue #8): seeds, sparsity and the cases where sparse-view methods fail.

    python bench/quality/stability.py --device cpu --preset small                  # every case, baseline and full
    python bench/quality/stability.py --device cpu --preset small --cases views_3 exposure --methods baseline
    python bench/quality/stability.py --device cuda --preset full                  # GPU-sized (256x192, 3000 it)

Cases (``warpgs.data.stress``, built from the embedded synthetic room; the test views are never
corrupted): ``views_2`` / ``views_3`` / ``views_6`` / ``views_9`` (sparsity), ``collinear``,
``wide_baseline``, ``textureless``, ``exposure``, ``wrong_pose``. ``views_3``, the default case, runs
with every seed of ``--seeds`` (mean +- std); the others with the first seed.

Each run is one method on one case, configured exactly as the main job configures it (the sparse CLI's
``make_config``: configs/baseline.yaml, full.yaml, synthetic.yaml, then the preset's overrides), and is
recorded, whatever happens, as

- ``finished``: training and evaluation ran; test PSNR / SSIM, Gaussians, training time, recoveries
  from divergence (``warpgs.train``) and the largest loss / running-median ratio seen;
- ``stopped``: warpgs stopped with its own clear error (``TrainingDiverged``, a scene or config error),
  with the message; the metrics are those of the last good state the trainer rolled back to;
- ``crashed``: any other exception, with the traceback's last frames (these are bugs);

and for every run whether the last checkpoint exists, loads and is finite. Writes ``stability.json``,
``stability.md`` (tables) and ``stability_psnr.png`` (PSNR per case and method, error bars over the
seeds) into ``--out`` (default bench/results/quality/stability_<device>); the run folders (checkpoints,
renders) go to ``--work`` (default outputs/stability_<device>_<preset>, not kept in the repository).

``run_stability(device, preset, out_dir, methods=..., cases=...)`` does the same from Python.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.data.stress import CASES  # noqa: E402

METHODS = ("baseline", "full")
SEEDS = (0, 1, 2)
DEFAULT_CASE = "views_3"

# the synthetic config (configs/synthetic.yaml) sized for each preset
PRESETS = {
    # CPU-friendly: 64x48 inputs, 300 steps, densification from step 100, pseudo views of 5 frames
    "small": {"downscale": 4, "iterations": 300, "set": [
        "model.init_num=1000", "strategy.max_gaussians=4000", "strategy.refine_start_iter=100",
        "strategy.refine_every=50", "train.sh_degree_interval=100", "train.checkpoint_every=100",
        "full.n_frames=5", "full.flythrough_frames=6", "full.pseudo={sampler: {steps: 10}}", "eval.fps_repeats=1"]},
    # GPU-sized: the capture's 256x192, 3000 steps, the synthetic config's numbers otherwise
    "full": {"downscale": 1, "iterations": 3000, "set": [
        "strategy.refine_start_iter=500", "train.checkpoint_every=500", "eval.fps_repeats=3"]},
}


def make_run_config(method: str, device: str, preset: str, seed: int, out: Path):
    """The main job's config for ``method`` on the synthetic data (the sparse CLI's layering) with the
    preset's overrides."""
    from warpgs.pipelines.sparse import build_parser, make_config

    p = PRESETS[preset]
    argv = ["--data", "synthetic", "--method", method, "--device", device, "--iterations", str(p["iterations"]),
            "--seed", str(seed), "--out", str(out), "--no-progress"]
    for s in p["set"]:
        argv += ["--set", s]
    cfg, _ = make_config(build_parser().parse_args(argv))
    return cfg


def check_checkpoint(path: Path) -> dict:
    """Whether ``path`` exists, loads (as ``--resume`` would) and holds finite parameters; its step."""
    import torch

    from warpgs.train import load_trained

    row = {"exists": path.is_file(), "loads": False, "finite": None, "step": None}
    if not row["exists"]:
        return row
    try:
        ck = torch.load(path, map_location="cpu", weights_only=False)
        model = load_trained(path)
        row["loads"] = True
        row["step"] = int(ck["step"])
        row["finite"] = all(bool(torch.isfinite(p).all()) for p in model.params.values())
    except Exception as e:  # a broken checkpoint is what this check is for
        row["error"] = f"{type(e).__name__}: {e}"
    return row


def run_one(case: str, method: str, seed: int, device: str, preset: str, work: Path, log=print) -> dict:
    """One method on one case; never raises (a crash is recorded with its traceback)."""
    from warpgs.config import ConfigError
    from warpgs.data.scene import SceneError
    from warpgs.data.stress import stress_scene
    from warpgs.pipelines.sparse import make_trainer
    from warpgs.train import CHECKPOINT, TrainingDiverged, TrainingInterrupted

    out = work / f"{case}_{method}_seed{seed}"
    row = {"case": case, "method": method, "seed": seed, "preset": preset, "device": device, "status": None,
           "message": None, "metrics": {}, "out": str(out)}
    t0 = time.perf_counter()
    trainer = None
    try:
        if out.exists():  # a fresh run: an earlier run's checkpoint must not be taken for this one's
            import shutil

            shutil.rmtree(out)
        cfg = make_run_config(method, device, preset, seed, out)
        scene = stress_scene(case, views=3, downscale=PRESETS[preset]["downscale"], seed=0, device=device)
        row["scene"] = {"name": scene.name, "train_views": len(scene.train), "test_views": len(scene.test),
                        "resolution": [scene.train[0].width, scene.train[0].height],
                        **{k: v for k, v in scene.metadata["stress"].items() if k != "measures"},
                        "measures": {k: v for k, v in scene.metadata["stress"]["measures"].items()
                                     if k != "true_viewmat"}}
        cfg.method = method
        trainer = make_trainer(cfg, scene, out)
        trainer.run()
        m = trainer.finish()
        row["status"] = "finished"
        row["metrics"] = {k: m.get(k) for k in ("psnr", "ssim", "lpips", "initial_psnr", "train_psnr", "num_gaussians",
                                                "train_time_s", "iterations", "skipped_steps", "lr_scale",
                                                "max_loss_ratio")}
        row["metrics"]["recoveries"] = m.get("recoveries", [])
    except (TrainingDiverged, TrainingInterrupted, SceneError, ConfigError) as e:
        row["status"] = "stopped"
        row["message"] = f"{type(e).__name__}: {e}"
        if trainer is not None:  # the trainer left its model at the last good state
            try:
                ev = trainer.evaluate(lpips=False)["mean"]
                row["metrics"] = {"psnr": ev["psnr"], "ssim": ev["ssim"], "num_gaussians": len(trainer.model),
                                  "iterations": trainer.step, "train_time_s": round(trainer.train_time, 2),
                                  "recoveries": trainer.recoveries, "lr_scale": trainer.lr_scale,
                                  "max_loss_ratio": round(trainer.guard.max_loss_ratio, 3), "of": "the last good state"}
            except Exception as ev_err:
                row["metrics"] = {"error": f"evaluating the last good state failed: {ev_err}"}
    except Exception as e:  # noqa: BLE001 -- anything else is a crash, recorded rather than raised
        row["status"] = "crashed"
        row["message"] = f"{type(e).__name__}: {e}"
        row["traceback"] = "".join(traceback.format_exception(e)[-6:])
    row["wall_s"] = round(time.perf_counter() - t0, 2)
    row["checkpoint"] = check_checkpoint(out / CHECKPOINT)
    m = row["metrics"]
    log(f"stability: {case:14s} {method:8s} seed {seed}: {row['status']:8s} "
        f"PSNR {_f(m.get('psnr'), '.2f')}  SSIM {_f(m.get('ssim'), '.3f')}  recoveries {len(m.get('recoveries') or [])}  "
        f"max loss ratio {_f(m.get('max_loss_ratio'), '.2f')}  checkpoint "
        f"{('ok' if row['checkpoint']['exists'] else 'none written') if checkpoint_ok(row) else 'MISSING/BAD'}  "
        f"({row['wall_s']:.0f} s)"
        + (f"\n  {row['message']}" if row["message"] else ""))
    return row


def checkpoint_ok(row: dict) -> bool:
    """A checkpoint that is there loads and is finite, and a finished run has one (a run stopped before its
    first checkpoint has none to lose)."""
    ck = row["checkpoint"]
    return bool(ck["loads"] and ck["finite"]) if ck["exists"] or row["status"] == "finished" else True


def _g(v):
    """A measure for the table: floats to 3 significant digits, lists element by element."""
    if isinstance(v, list):
        return "[" + ", ".join(_g(x) for x in v) + "]"
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def _f(v, fmt):
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def summarise(rows: list[dict]) -> list[dict]:
    """Per (case, method): runs, finished count, PSNR / SSIM mean and std over the finished runs' seeds."""
    out = []
    keys = list(dict.fromkeys((r["case"], r["method"]) for r in rows))
    for case, method in keys:
        rs = [r for r in rows if r["case"] == case and r["method"] == method]
        done = [r for r in rs if r["status"] == "finished" and r["metrics"].get("psnr") is not None]

        def stat(k):
            v = [r["metrics"][k] for r in done if r["metrics"].get(k) is not None]
            return (statistics.fmean(v) if v else None, statistics.stdev(v) if len(v) > 1 else None)

        p, s = stat("psnr"), stat("ssim")
        out.append({"case": case, "method": method, "runs": len(rs), "finished": len(done),
                    "statuses": sorted({r["status"] for r in rs}), "seeds": [r["seed"] for r in rs],
                    "psnr_mean": p[0], "psnr_std": p[1], "ssim_mean": s[0], "ssim_std": s[1],
                    "recoveries": sum(len(r["metrics"].get("recoveries") or []) for r in rs),
                    "max_loss_ratio": max((r["metrics"].get("max_loss_ratio") or 0.0) for r in rs),
                    "checkpoints_ok": all(checkpoint_ok(r) for r in rs)})
    return out


def write_markdown(path: Path, rows: list[dict], summary: list[dict], info: dict) -> None:
    lines = [f"# Stability ({info['preset']} preset, {info['device']})", "",
             f"{info['iterations']} iterations, inputs at {info['resolution']}, seeds {info['seeds']} on "
             f"`{DEFAULT_CASE}`; {info['host']}, {info['date']}; total {info['total_s']:.0f} s.", "",
             "PSNR / SSIM on the test views (mean ± std over the seeds where there are several). `textureless` "
             "is a different world (plain walls), so its PSNR is not comparable with the others'. Recoveries: "
             "rollbacks after a divergence (`warpgs.train`); max loss / median: the largest ratio of a step's loss "
             "to the running median of its phase, which `train.explode_factor` (10) bounds.", "",
             "| case | method | runs | finished | PSNR | SSIM | recoveries | max loss / median | checkpoints |",
             "|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        pm = _f(s["psnr_mean"], ".2f") + (f" ± {s['psnr_std']:.2f}" if s["psnr_std"] is not None else "")
        sm = _f(s["ssim_mean"], ".3f") + (f" ± {s['ssim_std']:.3f}" if s["ssim_std"] is not None else "")
        lines.append(f"| {s['case']} | {s['method']} | {s['runs']} | {s['finished']} ({', '.join(s['statuses'])}) | "
                     f"{pm} | {sm} | {s['recoveries']} | {s['max_loss_ratio']:.2f} | "
                     f"{'ok' if s['checkpoints_ok'] else 'MISSING/BAD'} |")
    lines += ["", "## Runs", "", "| case | method | seed | status | PSNR | SSIM | Gaussians | train s | checkpoint | "
              "what the case measures |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m = r["metrics"]
        ck = r["checkpoint"]
        meas = r.get("scene", {}).get("measures", {})
        shown = ", ".join(f"{k} {_g(v)}" for k, v in meas.items() if not isinstance(v, list) or len(v) <= 3)
        lines.append(f"| {r['case']} | {r['method']} | {r['seed']} | {r['status']} | {_f(m.get('psnr'), '.2f')} | "
                     f"{_f(m.get('ssim'), '.3f')} | {m.get('num_gaussians', 'n/a')} | {_f(m.get('train_time_s'), '.1f')} | "
                     f"{'step %s, loads, finite' % ck['step'] if ck['loads'] and ck['finite'] else ('none written' if not ck['exists'] else 'BAD')} | "
                     f"{shown} |")
    notes = [r for r in rows if r["message"]]
    if notes:
        lines += ["", "## Messages", ""]
        lines += [f"- `{r['case']}` {r['method']} seed {r['seed']} ({r['status']}): {r['message']}" for r in notes]
    lines += ["", "![PSNR per case](stability_psnr.png)", ""]
    path.write_text("\n".join(lines))


def plot(path: Path, summary: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    cases = list(dict.fromkeys(s["case"] for s in summary))
    methods = list(dict.fromkeys(s["method"] for s in summary))
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(cases) + 1.5), 3.6))
    width = 0.8 / max(len(methods), 1)
    for j, method in enumerate(methods):
        xs, ys, es = [], [], []
        for i, case in enumerate(cases):
            s = next((s for s in summary if s["case"] == case and s["method"] == method), None)
            if s is None or s["psnr_mean"] is None:
                continue
            xs.append(i + (j - (len(methods) - 1) / 2) * width)
            ys.append(s["psnr_mean"])
            es.append(s["psnr_std"] if s["psnr_std"] is not None else np.nan)  # error bars only over seeds
        ax.bar(xs, ys, width, yerr=es, capsize=4, label=method)
    for i, case in enumerate(cases):  # runs that did not finish are marked
        for j, method in enumerate(methods):
            s = next((s for s in summary if s["case"] == case and s["method"] == method), None)
            if s is not None and s["finished"] < s["runs"]:
                ax.text(i + (j - (len(methods) - 1) / 2) * width, 0.5, "x", ha="center", color="red")
    ax.set_xticks(np.arange(len(cases)), cases, rotation=30, ha="right")
    ax.set_ylabel("test PSNR (dB)")
    ax.set_title("test PSNR per case (error bars: std over seeds; x: a run that did not finish)", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_stability(device: str = "cpu", preset: str = "small", out_dir: str | Path | None = None,
                  methods=METHODS, cases=CASES, seeds=SEEDS, work_dir: str | Path | None = None,
                  log=print) -> list[dict]:
    """Runs every (case, method) (``DEFAULT_CASE`` once per seed, the others with ``seeds[0]``) and writes
    the JSON, the markdown tables and the PSNR chart into ``out_dir``; returns the run records."""
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: use one of {', '.join(PRESETS)}")
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"methods {bad}: use {', '.join(METHODS)}")
    if not seeds:
        raise ValueError("at least one seed is needed")
    dev_name = device.split(":")[0]
    out = Path(out_dir) if out_dir is not None else ROOT / "bench" / "results" / "quality" / f"stability_{dev_name}"
    work = Path(work_dir) if work_dir is not None else ROOT / "outputs" / f"stability_{dev_name}_{preset}"
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = []
    for case in cases:
        for method in methods:
            for seed in (seeds if case == DEFAULT_CASE else seeds[:1]):
                rows.append(run_one(case, method, seed, device, preset, work, log=log))
    summary = summarise(rows)
    p = PRESETS[preset]
    res = next((r["scene"]["resolution"] for r in rows if "scene" in r), None)
    info = {"device": device, "preset": preset, "iterations": p["iterations"], "overrides": p["set"],
            "resolution": f"{res[0]}x{res[1]}" if res else "n/a", "seeds": list(seeds), "methods": list(methods),
            "cases": list(cases), "host": platform.node() or platform.platform(),
            "date": time.strftime("%Y-%m-%d %H:%M"), "total_s": time.perf_counter() - t0}
    (out / "stability.json").write_text(json.dumps({"info": info, "summary": summary, "runs": rows}, indent=2))
    write_markdown(out / "stability.md", rows, summary, info)
    plot(out / "stability_psnr.png", summary)
    log(f"stability: wrote {out / 'stability.json'}, {out / 'stability.md'}, {out / 'stability_psnr.png'}")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu", help="cpu or cuda (default: cpu)")
    ap.add_argument("--preset", default="small", choices=list(PRESETS), help="small: CPU-sized; full: GPU-sized")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--cases", nargs="+", default=list(CASES), metavar="CASE",
                    help=f"stress cases ({', '.join(CASES)}; views_N for any N)")
    ap.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS), help=f"seeds of {DEFAULT_CASE}")
    ap.add_argument("--out", default=None, help="results folder (default bench/results/quality/stability_<device>)")
    ap.add_argument("--work", default=None, help="run folders (default outputs/stability_<device>_<preset>)")
    args = ap.parse_args(argv)
    rows = run_stability(args.device, args.preset, args.out, methods=args.methods, cases=args.cases,
                         seeds=args.seeds, work_dir=args.work)
    crashed = [r for r in rows if r["status"] == "crashed"]
    lost = [r for r in rows if not checkpoint_ok(r)]
    if crashed or lost:
        print(f"stability: {len(crashed)} run(s) crashed, {len(lost)} without a good checkpoint", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
