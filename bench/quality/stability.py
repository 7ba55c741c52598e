"""Stability bench: the cases where sparse-view methods fail, every method, seeds 0-2.

    python bench/quality/stability.py --device cpu --preset small                  # every case, method and seed
    python bench/quality/stability.py --device cpu --preset small --cases views_3 exposure --methods baseline
    python bench/quality/stability.py --device cuda --preset full --jobs 8 --out bench/results/quality/stability_h200

Cases (``warpgs.data.stress``, built in memory from the embedded synthetic room, so not a sweep of the batch
runner; the test views are never corrupted): ``views_2`` / ``views_3`` / ``views_6`` / ``views_9`` (sparsity),
``collinear``, ``wide_baseline``, ``textureless``, ``exposure``, ``wrong_pose``; each with every seed of
``--seeds``, ``--jobs`` runs at a time (each in its own process).

Each run is one method on one case, configured exactly as the main job configures it (the sparse CLI's
``make_config``: the method's, the synthetic data's config, then the preset's overrides), and is
recorded, whatever happens, as

- ``finished``: training and evaluation ran; test PSNR / SSIM, the initial render's PSNR, Gaussians, training
  time, recoveries from divergence (``warpgs.train``) and the largest loss / running-median ratio seen;
- ``stopped``: warpgs stopped with its own clear error (``TrainingDiverged``, a scene or config error),
  with the message; the metrics are those of the last good state the trainer rolled back to;
- ``crashed``: any other exception (out of memory among them), with the traceback's last frames;

and for every run whether the last checkpoint exists, loads and is finite. Writes ``stability.json`` (with the
machine and the commit) into ``--out`` (default bench/results/quality/stability_<device>), which
``bench/report/charts.py`` charts (how runs end, per method) and tabulates in docs/benchmarks.md; the run
folders (checkpoints, renders) go to ``--work`` (default outputs/stability_<device>_<preset>, not kept in the
repository).

``run_stability(device, preset, out_dir, methods=..., cases=...)`` does the same from Python.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.data.stress import CASES  # noqa: E402

METHODS = ("baseline", "full", "corgs")
SEEDS = (0, 1, 2)

# the synthetic config (configs/synthetic.yaml) sized for each preset
PRESETS = {
    # CPU-friendly: 64x48 inputs, 300 steps, densification from step 100, pseudo views of 5 frames
    "small": {"downscale": 4, "iterations": 300, "set": [
        "model.init_num=1000", "strategy.max_gaussians=4000", "strategy.refine_start_iter=100",
        "strategy.refine_every=50", "train.sh_degree_interval=100", "train.checkpoint_every=100",
        "full.n_frames=5", "full.flythrough_frames=6", "full.pseudo={sampler: {steps: 10}}", "eval.fps_repeats=1",
        "corgs.start=100", "corgs.prune_every=100"]},  # CoR-GS's pair from step 100 (its 500 is past the end)
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


def _f(v, fmt):
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def _run_one(job: tuple) -> dict:
    return run_one(*job)


def run_stability(device: str = "cpu", preset: str = "small", out_dir: str | Path | None = None,
                  methods=METHODS, cases=CASES, seeds=SEEDS, work_dir: str | Path | None = None,
                  jobs: int = 1, log=print) -> list[dict]:
    """Runs every (case, method, seed), ``jobs`` at a time (each in its own process when more than one), and
    writes ``stability.json`` into ``out_dir``; returns the run records."""
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
    todo = [(case, method, seed, device, preset, work) for case in cases for method in methods for seed in seeds]
    if jobs > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn")) as pool:
            rows = list(pool.map(_run_one, todo))
    else:
        rows = [run_one(*job, log=log) for job in todo]
    from bench.report.charts import git_commit, this_machine

    p = PRESETS[preset]
    res = next((r["scene"]["resolution"] for r in rows if "scene" in r), None)
    info = {"device": device, "machine": this_machine() if dev_name == "cuda" else None, "commit": git_commit(ROOT),
            "preset": preset, "iterations": p["iterations"], "overrides": p["set"],
            "resolution": f"{res[0]}x{res[1]}" if res else "n/a", "seeds": list(seeds), "methods": list(methods),
            "cases": list(cases), "host": platform.node() or platform.platform(),
            "date": time.strftime("%Y-%m-%d %H:%M"), "total_s": time.perf_counter() - t0}
    (out / "stability.json").write_text(json.dumps({"info": info, "runs": rows}, indent=2))
    log(f"stability: wrote {out / 'stability.json'} (charts and tables: python bench/report/charts.py)")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu", help="cpu or cuda (default: cpu)")
    ap.add_argument("--preset", default="small", choices=list(PRESETS), help="small: CPU-sized; full: GPU-sized")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--cases", nargs="+", default=list(CASES), metavar="CASE",
                    help=f"stress cases ({', '.join(CASES)}; views_N for any N)")
    ap.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS), help="seeds of every case and method")
    ap.add_argument("--jobs", type=int, default=1, help="runs at a time, each in its own process (default 1)")
    ap.add_argument("--out", default=None, help="results folder (default bench/results/quality/stability_<device>)")
    ap.add_argument("--work", default=None, help="run folders (default outputs/stability_<device>_<preset>)")
    args = ap.parse_args(argv)
    rows = run_stability(args.device, args.preset, args.out, methods=args.methods, cases=args.cases,
                         seeds=args.seeds, work_dir=args.work, jobs=args.jobs)
    crashed = [r for r in rows if r["status"] == "crashed"]
    lost = [r for r in rows if not checkpoint_ok(r)]
    if crashed or lost:
        print(f"stability: {len(crashed)} run(s) crashed, {len(lost)} without a good checkpoint", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
