"""Peak memory and time of the svd backend at Stable Video Diffusion img2vid-xt's full size, on the GPU machine.

The model is SVD-xt's architecture with random weights (built by the device folder's ``svd_fullsize.py``, path in
$SVD_BUILDER, default .device/svd_fullsize.py, into $SVD_DIR, default /tmp/svd_full, when not there yet): the
pseudo views are meaningless, the memory and time are the real model's. Phases, each within one 10-minute call:

    python bench/perf/svd_fullsize.py stages [none model sequential]   # one 25-frame bidirectional trajectory at
                                                                       # 576x1024 per offload option: time and
                                                                       # peak memory per stage
    python bench/perf/svd_fullsize.py run castle_p30 9 [--offload model] [--set KEY=VALUE ...]
    python bench/perf/svd_fullsize.py runs3        # castle_p30 and herz_jesus_p25 at 3 views, one after the other
    python bench/perf/svd_fullsize.py runs9        # the same at 9 views (over 10 minutes today: use run per scene)
    python bench/perf/svd_fullsize.py run herz_jesus_p25 9 --set pseudo.svd.area=327680   # a variant: fewer pixels
    python bench/perf/svd_fullsize.py summary      # the table of what $OUT holds

A run is the full method with svd at images_4 (--downscale 4), 10,000 iterations, scenes in $SVD_DATA (default
.device/data). Everything is written as JSON under $OUT (default bench/results/svd_fullsize).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # warpgs from this checkout
    sys.path.insert(0, str(ROOT))
OFFLOADS = ("none", "model", "sequential")
STAGE_NAMES = ("conditioning", "encode", "denoise", "decode")


def out_dir() -> Path:
    p = Path(os.environ.get("OUT") or ROOT / "bench" / "results" / "svd_fullsize").resolve()
    p.mkdir(parents=True, exist_ok=True)
    return p


def parse(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python bench/perf/svd_fullsize.py", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="phase", required=True)
    st = sub.add_parser("stages", help="one trajectory per offload option: time and peak memory per stage")
    st.add_argument("offloads", nargs="*", metavar="OFFLOAD", help=f"of {', '.join(OFFLOADS)} (default: all)")
    st.add_argument("--frames", type=int, default=25)
    st.add_argument("--size", default="576x1024", help="HxW of the model (and of the frames)")
    st.add_argument("--steps", type=int, default=25)
    st.add_argument("--repeats", type=int, default=2, help="trajectories per option (the first warms up)")
    st.add_argument("--compile", action="store_true", help="pseudo.svd.compile: torch.compile the UNet")
    st.add_argument("--device", default="cuda", help="cuda (the measurement); cpu for a smoke test of a tiny model")
    for name in ("run", "runs3", "runs9"):
        r = sub.add_parser(name, help="the full method with svd" + ("" if name == "run" else f" on both scenes, "
                                                                                            f"{name[-1]} views"))
        if name == "run":
            r.add_argument("scene")
            r.add_argument("views", type=int)
        r.add_argument("--offload", choices=OFFLOADS, default=None)
        r.add_argument("--iterations", type=int, default=10000)
        r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    sub.add_parser("summary", help="a table of the JSON under $OUT")
    args = ap.parse_args(argv)
    if args.phase == "stages":
        args.offloads = list(args.offloads) or list(OFFLOADS)
        bad = [o for o in args.offloads if o not in OFFLOADS]
        h, _, w = args.size.partition("x")
        if bad or not (h.isdigit() and w.isdigit()):
            ap.error(f"offload options are {', '.join(OFFLOADS)}; --size is HxW" + (f" (got {bad})" if bad else ""))
        args.height, args.width = int(h), int(w)
    return args


def svd_folder() -> Path:
    """The full-size random model, built on first use."""
    folder = Path(os.environ.get("SVD_DIR", "/tmp/svd_full"))
    if not (folder / "model_index.json").is_file():
        builder = os.environ.get("SVD_BUILDER", str(ROOT / ".device" / "svd_fullsize.py"))
        subprocess.run([sys.executable, builder, str(folder)], check=True)
    return folder


# ----------------------------------------------------------------------------------------------
# stages: one trajectory through the backend


def stages(args) -> dict:
    import torch

    from warpgs.pseudo.backends import SVDBackend, SVDConfig
    from warpgs.pseudo.sampler import SamplerConfig, StageClock, sample_video

    folder, dev = svd_folder(), torch.device(args.device)
    cuda = dev.type == "cuda"

    def sync_reset():
        if cuda:
            torch.cuda.synchronize(dev)
            torch.cuda.reset_peak_memory_stats(dev)

    n, H, W = args.frames, args.height, args.width
    g = torch.Generator().manual_seed(0)
    start, end = torch.rand(H, W, 3, generator=g), torch.rand(H, W, 3, generator=g)
    w = torch.linspace(0, 1, n).view(n, 1, 1, 1)
    guidance = ((1 - w) * start + w * end).to(dev)
    U = torch.rand(n, H, W, generator=g).to(dev)  # about half the pixels reliable (delta 0.5)
    results = {}
    for offload in args.offloads:
        if cuda:
            torch.cuda.empty_cache()
        sync_reset()
        t0 = time.perf_counter()
        svd = SVDConfig(width=W, height=H, offload=offload, compile=args.compile)
        backend = SVDBackend.from_pretrained(folder, device=dev, cfg=svd)
        sync_reset()
        row = {"load_s": time.perf_counter() - t0,
               "resident_mb": torch.cuda.memory_allocated(dev) / 2**20 if cuda else 0.0, "trajectories": []}
        for _ in range(args.repeats):
            sync_reset()
            clock = StageClock(dev, memory=True)
            t0 = time.perf_counter()
            sample_video(backend, start.to(dev), end.to(dev), guidance=guidance, uncertainty=U,
                         cfg=SamplerConfig(steps=args.steps), clock=clock)
            sync_reset()
            row["trajectories"].append({"total_s": time.perf_counter() - t0, **clock.times, **clock.peaks})
        row["peak_mb"] = max((v for t in row["trajectories"] for k, v in t.items() if k.endswith("_peak_mb")),
                             default=0.0)
        results[offload] = row
        print(json.dumps({offload: summarise_stages(row)}), flush=True)
        del backend
        gc.collect()
    report = {"frames": n, "size": [H, W], "steps": args.steps, "compile": args.compile,
              "device": torch.cuda.get_device_name(dev) if cuda else str(dev),
              "options": results}
    write(f"stages_{'_'.join(args.offloads)}.json", report)
    return report


def summarise_stages(row: dict) -> dict:
    """The last (warm) trajectory of one option: seconds and peak MB per stage, the trajectory's total, the peak."""
    t = row["trajectories"][-1]
    out = {f"{s}_s": round(t.get(f"{s}_s", 0.0), 2) for s in STAGE_NAMES}
    out.update({f"{s}_peak_mb": round(t.get(f"{s}_peak_mb", 0.0)) for s in STAGE_NAMES})
    out["trajectory_s"] = round(t["total_s"], 2)
    out["peak_mb"] = round(row["peak_mb"])
    return out


# ----------------------------------------------------------------------------------------------
# runs: the full method with svd, end to end


def run_one(scene: str, views: int, args) -> dict:
    data = Path(os.environ.get("SVD_DATA", str(ROOT / ".device" / "data"))).resolve()
    name = f"{scene}_{views}v" + (f"_{args.offload}" if args.offload else "")
    run = out_dir() / "runs" / name
    cmd = [sys.executable, "-m", "warpgs.pipelines.sparse", "--data", str(data / scene), "--views", str(views),
           "--downscale", "4", "--iterations", str(args.iterations), "--method", "full", "--device", "cuda",
           "--svd-path", str(svd_folder()), "--no-progress", "--overwrite", "--out", str(run)]
    if args.offload:
        cmd += ["--set", f"pseudo.svd.offload={args.offload}"]
    for s in args.set:
        cmd += ["--set", s]
    t0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)}
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
    wall = time.perf_counter() - t0
    (out_dir() / f"run_{name}.log").write_text(proc.stdout + proc.stderr)
    metrics = json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").is_file() else None
    row = {"scene": scene, "views": views, "offload": args.offload or "none", "exit_code": proc.returncode,
           **summarise_run(metrics, wall)}
    write(f"run_{name}.json", row)
    print(json.dumps(row), flush=True)
    return row


def summarise_run(metrics: dict | None, wall_s: float) -> dict:
    """What a run's metrics.json says of the video model: PSNR, Gaussians, peak memory, wall time, the command's
    stages (``wall_s``: start-up, loading, geometry, set-up, training with the cycles, the final evaluation and
    outputs), and per cycle the model's loading, the pseudo views' seconds, their stages' and per trajectory."""
    row = {"wall_s": round(wall_s, 1)}
    if metrics is None:
        return {**row, "metrics": False}
    row.update({"metrics": True, "psnr": metrics.get("psnr"), "num_gaussians": metrics.get("num_gaussians"),
                "peak_mb": metrics.get("peak_cuda_allocated_mb"), "train_time_s": metrics.get("train_time_s"),
                "stages_s": metrics.get("wall_s"), "outputs_s": metrics.get("outputs_s")})
    keys = ("pseudo_model_load_s", "pseudo_views_s", "pseudo_trajectories", "pseudo_per_trajectory_s",
            *(f"pseudo_{s}_s" for s in STAGE_NAMES), "pseudo_save_s", "densify_s", "train_s")
    row["cycles"] = [{k: c[k] for k in keys if k in c} for c in metrics.get("cycles", [])[1:]]
    return row


def summary() -> str:
    """A Markdown table of the stage and run JSON under $OUT."""
    lines = ["| option | " + " | ".join(f"{s} s / peak MB" for s in STAGE_NAMES) + " | trajectory s | peak MB |",
             "|---|" + "---|" * (len(STAGE_NAMES) + 2)]
    for f in sorted(out_dir().glob("stages_*.json")):
        for opt, row in json.loads(f.read_text())["options"].items():
            s = summarise_stages(row)
            lines.append(f"| {opt} | " + " | ".join(f"{s[f'{k}_s']} / {s[f'{k}_peak_mb']}" for k in STAGE_NAMES)
                         + f" | {s['trajectory_s']} | {s['peak_mb']} |")
    lines += ["", "| run | exit | wall s | PSNR | peak MB | pseudo views s per cycle | per trajectory s |",
              "|---|---|---|---|---|---|---|"]
    for f in sorted(out_dir().glob("run_*.json")):
        r = json.loads(f.read_text())
        cyc = r.get("cycles", [])
        lines.append(f"| {r['scene']} {r['views']}v {r['offload']} | {r['exit_code']} | {r['wall_s']} | "
                     f"{r.get('psnr')} | {r.get('peak_mb')} | {', '.join(str(c.get('pseudo_views_s')) for c in cyc)} | "
                     f"{', '.join(str(c.get('pseudo_per_trajectory_s')) for c in cyc)} |")
    return "\n".join(lines)


def write(name: str, obj) -> None:
    (out_dir() / name).write_text(json.dumps(obj, indent=2))


def main(argv=None) -> int:
    args = parse(argv)
    if args.phase == "stages":
        stages(args)
    elif args.phase == "run":
        run_one(args.scene, args.views, args)
    elif args.phase in ("runs3", "runs9"):
        for scene in ("castle_p30", "herz_jesus_p25"):
            run_one(scene, int(args.phase[-1]), args)
    else:
        text = summary()
        (out_dir() / "summary.md").write_text(text + "\n")
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
