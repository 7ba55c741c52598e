"""Speed against accuracy: one command runs methods and settings on the available scenes and charts
test PSNR against training wall time and against Gaussian count (issue #8).

    python bench/suite.py                          # CPU: the "small" preset (embedded synthetic scene)
    python bench/suite.py --device cuda --data-root DIR    # GPU: the "full" preset (synthetic, fern, lego, DTU)
    python bench/suite.py --only baseline_1000,full_1000 --jobs 2
    python bench/suite.py --summary-only           # redraw charts and summary from results.json
    python bench/suite.py --device cuda --ray      # through the batch runner on Ray: every GPU, retries

Each entry of a preset is one ``python -m warpgs.pipelines.sparse`` run (its own process and output
folder under --work): a method (baseline, full, an ablation of the paper's Table 4, compact mode) at an
iteration budget on a scene and a backend. Runs go ``--jobs`` at a time (Warp's CPU kernels use one
thread, so two at once on a 2-core CPU; several on one GPU, which each run leaves mostly idle);
a run that already finished (metrics.json present) is reused unless --fresh, so an interrupted suite
continues where it stopped. Each run records its test-PSNR curve (``train.eval_every``), so a chart
shows PSNR against time along every run, not only its end point.

Outputs in --out (default bench/results/suite_<device>): results.json (every run: config, metrics,
curve, status), psnr_vs_time.png, psnr_vs_gaussians.png and summary.md (tables per scene and the
charts). A failed run is recorded with the end of its log and the suite goes on.

Wall times are the training time the trainer measures (evaluation excluded) with runs sharing the
machine, so compare times within one suite run; the speed of one method alone is in metrics.json of
a run made with --jobs 1.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Run:
    """One training run of the suite."""

    name: str
    data: str
    method: str  # baseline | full
    iterations: int
    args: list = field(default_factory=list)  # extra CLI arguments (--set ..., --ablation ..., --compact)
    label: str = ""  # series name in the charts (runs of one label at several budgets form a line)

    def __post_init__(self):
        self.label = self.label or self.method


def _budgets(data, method, its, label=None, args=()):
    return [Run(f"{data}_{label or method}_{n}", data, method, n, list(args), label or method) for n in its]


# CPU: the embedded scene at its default size (3 views, 128x96); a few minutes per run on one core.
SMALL = (
    _budgets("synthetic", "baseline", (250, 500, 1000))
    + _budgets("synthetic", "full", (500, 1000))
    + _budgets("synthetic", "full", (1000,), label="full_no_densify", args=["--ablation", "no_densify"])
    + _budgets("synthetic", "baseline", (1000,), label="baseline_compact", args=["--compact"])
)

# GPU: the real scenes at the standard sparse splits, and the synthetic one.
FULL = (
    _budgets("synthetic", "baseline", (500, 1000, 2000))
    + _budgets("synthetic", "full", (1000, 2000))
    + [r for ab in ("render_guidance", "no_geometric", "no_photometric", "no_filter", "no_densify", "l1_pseudo")
       for r in _budgets("synthetic", "full", (1000,), label=f"full_{ab}", args=["--ablation", ab])]
    + _budgets("llff", "baseline", (1000, 3000))
    + _budgets("llff", "full", (1000, 3000))
    + _budgets("blender", "baseline", (2000, 5000))
    + _budgets("dtu", "baseline", (3000,))
    + _budgets("dtu", "full", (3000,))
)

PRESETS = {"small": SMALL, "full": FULL}


def eval_every(run: Run) -> int:
    return max(run.iterations // 10, 50)


def sparse_args(run: Run, device: str, data_root: str | None) -> list[str]:
    """The run's arguments of ``python -m warpgs.pipelines.sparse``, but its output folder."""
    args = ["--method", run.method, "--data", run.data, "--iterations", str(run.iterations), "--device", device,
            "--no-progress", "--set", f"train.eval_every={eval_every(run)}"]
    if data_root and run.data != "synthetic":
        args += ["--data-root", data_root]
    return args + list(run.args)


def command(run: Run, device: str, work: Path, data_root: str | None) -> list[str]:
    # --overwrite: the suite decides what to reuse (execute); a run it starts replaces what its folder holds
    return [sys.executable, "-m", "warpgs.pipelines.sparse", *sparse_args(run, device, data_root),
            "--out", str(work / run.name), "--overwrite"]


def execute(run: Run, device: str, work: Path, data_root: str | None, fresh: bool) -> dict:
    """Runs (or reuses) one entry -> its record."""
    out = work / run.name
    metrics_path = out / "metrics.json"
    rec = {"run": asdict(run), "device": device, "out": str(out)}
    if metrics_path.is_file() and not fresh:
        rec.update(status="finished", reused=True, metrics=_slim(json.loads(metrics_path.read_text())))
        return rec
    out.mkdir(parents=True, exist_ok=True)
    log = out.parent / f"{run.name}.log"
    t0 = time.perf_counter()
    with open(log, "w") as f:
        proc = subprocess.run(command(run, device, work, data_root), cwd=ROOT, stdout=f, stderr=subprocess.STDOUT,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
    rec["wall_s"] = round(time.perf_counter() - t0, 2)
    if proc.returncode == 0 and metrics_path.is_file():
        rec.update(status="finished", metrics=_slim(json.loads(metrics_path.read_text())))
    else:
        rec.update(status="failed", returncode=proc.returncode, log_tail=log.read_text()[-1500:])
    return rec


def execute_on_ray(runs: list[Run], device: str, work: Path, data_root: str | None, fresh: bool, jobs: int,
                   address: str | None, log=print) -> list[dict]:
    """The runs as tasks of the batch runner (``warpgs.pipelines.batch``: Ray, retries from checkpoints) -> their
    records. On CUDA each run asks for 1/``jobs`` of a GPU (``jobs`` runs per GPU, on every GPU Ray has); on
    the CPU a local Ray gets ``jobs`` CPUs, one per run. Logs in ``work``/logs."""
    from warpgs.pipelines import batch

    cuda = device.startswith("cuda")
    specs = [batch.RunSpec(r.name, sparse_args(r, device, data_root), r.data, None, r.method, None,
                           num_gpus=1 / jobs if cuda else 0.0) for r in runs]
    init = {"address": address} if address else {"num_cpus": None if cuda else jobs}
    recs = batch.run_on_ray(specs, work, work / "logs", overwrite=fresh, log=log, ray_init=init)
    records = []
    for run, b in zip(runs, recs):
        rec = {"run": asdict(run), "device": device, "out": b["out"], "status": b["status"], "wall_s": b.get("wall_s"),
               "attempts": len(b.get("attempts") or []), "retries": b.get("retries")}
        if b.get("reused"):
            rec["reused"] = True
        if b["status"] == "finished":
            rec["metrics"] = _slim(b["metrics"])
        else:
            rec.update(returncode=b.get("returncode"), log_tail=b.get("log_tail") or b.get("error", ""))
        records.append(rec)
    return records


def _slim(m: dict) -> dict:
    keep = ("method", "scene", "train_views", "resolution", "iterations", "psnr", "ssim", "lpips", "masked",
            "num_gaussians", "train_time_s", "render_fps", "peak_cuda_allocated_mb", "peak_rss_mb", "device",
            "curve", "compact", "recoveries")
    return {k: m[k] for k in keep if k in m}


# ----------------------------------------------------------------------------------------------
# charts and summary


def _series(records: list[dict]) -> dict:
    """{scene: {label: [records sorted by iterations]}} of the finished runs."""
    out: dict = {}
    for r in records:
        if r.get("status") != "finished":
            continue
        m = r["metrics"]
        out.setdefault(m["scene"], {}).setdefault(r["run"]["label"], []).append(r)
    for scene in out.values():
        for recs in scene.values():
            recs.sort(key=lambda r: r["run"]["iterations"])
    return out


def plot(records: list[dict], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = _series(records)
    if not series:
        return []
    paths = []
    for kind, xlabel, xkey in (("time", "training wall time (s)", "train_time_s"),
                               ("gaussians", "Gaussians (final count)", "num_gaussians")):
        n = len(series)
        fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 4.2), squeeze=False)
        for ax, (scene, labels) in zip(axes[0], sorted(series.items())):
            for i, (label, recs) in enumerate(sorted(labels.items())):
                color = f"C{i % 10}"
                xs = [r["metrics"][xkey] for r in recs]
                ys = [r["metrics"]["psnr"] for r in recs]
                ax.plot(xs, ys, "o-", color=color, label=label, ms=5)
                if kind == "time":  # the longest run's test-PSNR curve along its training time
                    curve = recs[-1]["metrics"].get("curve") or []
                    if curve:
                        ax.plot([c["train_time_s"] for c in curve], [c["psnr"] for c in curve], ":", color=color,
                                alpha=0.6, lw=1)
                for r, x, y in zip(recs, xs, ys):
                    ax.annotate(str(r["run"]["iterations"]), (x, y), fontsize=6, alpha=0.7,
                                textcoords="offset points", xytext=(3, 3))
            dev = recs[0]["metrics"].get("device", "")
            ax.set_title(f"{scene} ({dev})", fontsize=10)
            ax.set_xlabel(xlabel)
            ax.set_ylabel("test PSNR (dB)")
            if kind == "time":
                ax.set_xscale("log")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        fig.suptitle("PSNR against " + ("training time (labels: iterations; dotted: test PSNR during the "
                                        "longest run)" if kind == "time" else "model size (labels: iterations)"),
                     fontsize=10)
        fig.tight_layout()
        path = out / f"psnr_vs_{kind}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def write_summary(records: list[dict], info: dict, out: Path) -> Path:
    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    lines = ["# warpgs benchmark suite", "",
             f"Preset `{info['preset']}` on {info['device_name']} ({info['device']}), {info['date']}; "
             f"{sum(r.get('status') == 'finished' for r in records)} of {len(records)} runs finished, "
             f"{info['jobs']} at a time (times are with runs sharing the machine).", "",
             "![PSNR against time](psnr_vs_time.png)", "", "![PSNR against Gaussians](psnr_vs_gaussians.png)", ""]
    for scene, labels in sorted(_series(records).items()):
        lines += [f"## {scene}", "", "| method | iterations | PSNR | SSIM | LPIPS | Gaussians | training (s) | FPS |",
                  "|---|---|---|---|---|---|---|---|"]
        for label, recs in sorted(labels.items()):
            for r in recs:
                m = r["metrics"]
                lines.append(f"| {label} | {m['iterations']} | {f(m['psnr'], '.2f')} | {f(m['ssim'], '.3f')} | "
                             f"{f(m.get('lpips'), '.3f')} | {m['num_gaussians']} | {f(m['train_time_s'], '.1f')} | "
                             f"{f(m.get('render_fps'), '.0f')} |")
        lines.append("")
    failed = [r for r in records if r.get("status") != "finished"]
    if failed:
        lines += ["## Runs that did not finish", ""]
        for r in failed:
            tail = (r.get("log_tail") or "").strip().splitlines()
            lines.append(f"- `{r['run']['name']}` (exit code {r.get('returncode')}): {tail[-1] if tail else 'no log'}")
        lines.append("")
    path = out / "summary.md"
    path.write_text("\n".join(lines))
    return path


# ----------------------------------------------------------------------------------------------


def device_name(device: str) -> str:
    if device.startswith("cuda"):
        try:
            import torch

            return torch.cuda.get_device_name()
        except Exception:  # noqa: BLE001 - a name for the report only
            return "CUDA GPU"
    return f"{platform.processor() or 'CPU'} ({os.cpu_count()} cores)"


def run_suite(device: str = "cpu", preset: str | None = None, out: Path | None = None, work: Path | None = None,
              jobs: int | None = None, only: list[str] | None = None, data_root: str | None = None,
              fresh: bool = False, log=print, ray: bool = False, address: str | None = None) -> list[dict]:
    preset = preset or ("full" if device.startswith("cuda") else "small")
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: available {', '.join(PRESETS)}")
    runs = PRESETS[preset]
    if only:
        unknown = [o for o in only if not any(o in (r.name, r.label, r.data) for r in runs)]
        if unknown:
            raise ValueError(f"--only {', '.join(unknown)}: not a run, label or dataset of preset {preset} "
                             f"(runs: {', '.join(r.name for r in runs)})")
        runs = [r for r in runs if r.name in only or r.label in only or r.data in only]
    dev_tag = "cuda" if device.startswith("cuda") else "cpu"
    out = out or ROOT / "bench" / "results" / f"suite_{dev_tag}"
    work = work or ROOT / "outputs" / f"suite_{dev_tag}_{preset}"
    jobs = jobs or (min(2, os.cpu_count() or 1) if dev_tag == "cpu" else 6)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    info = {"preset": preset, "device": device, "device_name": device_name(device), "jobs": jobs,
            "date": time.strftime("%Y-%m-%d %H:%M"), "runs": len(runs)}
    log(f"suite: {len(runs)} runs of preset {preset} on {info['device_name']}, {jobs} at a time; work in {work}")
    records: list[dict] = []
    results_path = out / "results.json"

    def one(run: Run) -> dict:
        rec = execute(run, device, work, data_root, fresh)
        m = rec.get("metrics") or {}
        log(f"  {run.name:<36} {rec['status']:<9}" + (f" PSNR {m['psnr']:.2f}  {m['num_gaussians']} Gaussians  "
                                                       f"{m['train_time_s']:.0f} s" if m else ""))
        records.append(rec)
        results_path.write_text(json.dumps({"info": info, "records": records}, indent=1))  # progress survives
        return rec

    if ray or address:
        for rec in execute_on_ray(runs, device, work, data_root, fresh, jobs, address, log):
            m = rec.get("metrics") or {}
            log(f"  {rec['run']['name']:<36} {rec['status']:<9}" + (f" PSNR {m['psnr']:.2f}  {m['num_gaussians']} "
                                                                    f"Gaussians  {m['train_time_s']:.0f} s" if m else ""))
            records.append(rec)
    else:
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            list(pool.map(one, runs))
    order = {r.name: i for i, r in enumerate(runs)}
    records.sort(key=lambda r: order[r["run"]["name"]])
    results_path.write_text(json.dumps({"info": info, "records": records}, indent=1))
    plot(records, out)
    write_summary(records, info, out)
    log(f"suite: wrote {results_path}, {out / 'psnr_vs_time.png'}, {out / 'psnr_vs_gaussians.png'}, "
        f"{out / 'summary.md'}")
    return records


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None, help="cpu or cuda (default: cuda if available)")
    ap.add_argument("--preset", default=None, choices=list(PRESETS), help="default: small on cpu, full on cuda")
    ap.add_argument("--only", default=None, help="comma-separated run names, labels or datasets of the preset")
    ap.add_argument("--jobs", type=int, default=None, help="runs at a time (default: 2 on cpu, 6 on cuda)")
    ap.add_argument("--data-root", default=None, help="folder holding llff_fern, blender_lego, dtu_scan65, ...")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--work", type=Path, default=None, help="run folders (default outputs/suite_<device>_<preset>)")
    ap.add_argument("--fresh", action="store_true", help="rerun runs that already finished")
    ap.add_argument("--summary-only", action="store_true", help="redraw charts and summary from --out/results.json")
    ap.add_argument("--ray", action="store_true", help="run through the batch runner on Ray (warpgs.pipelines.batch: "
                    "every GPU, retries from checkpoints); --jobs is then runs per GPU, or CPUs of a local Ray")
    ap.add_argument("--address", default=None, help="with --ray: the Ray cluster to join (implies --ray)")
    a = ap.parse_args(argv)
    if a.device is None:
        import torch

        a.device = "cuda" if torch.cuda.is_available() else "cpu"
    if a.summary_only:
        out = a.out or ROOT / "bench" / "results" / f"suite_{'cuda' if a.device.startswith('cuda') else 'cpu'}"
        data = json.loads((out / "results.json").read_text())
        plot(data["records"], out)
        print(f"wrote {write_summary(data['records'], data['info'], out)}")
        return 0
    try:
        records = run_suite(a.device, a.preset, a.out, a.work, a.jobs, a.only.split(",") if a.only else None,
                            a.data_root, a.fresh, ray=a.ray, address=a.address)
    except ValueError as e:  # also warpgs.pipelines.batch.BatchError: Ray is not installed
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0 if all(r.get("status") == "finished" for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
