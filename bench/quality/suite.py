"""Speed against accuracy: one command runs methods and settings on the available scenes and charts
test PSNR against training wall time and against Gaussian count (issue #8).

    python bench/quality/suite.py                          # CPU: the "small" preset (embedded synthetic scene)
    python bench/quality/suite.py --device cuda --data-root DIR    # GPU: the "full" preset (synthetic, fern, lego, DTU)
    python bench/quality/suite.py --only baseline_1000,full_1000 --jobs 2
    python bench/quality/suite.py --summary-only           # redraw charts and summary from results.json
    python bench/quality/suite.py --device cuda --ray      # through the batch runner on Ray: every GPU, retries

Each entry of a preset is one ``python -m warpgs.pipelines.sparse`` run (its own process and output
folder under --work): a method (baseline, full, an ablation of the paper's Table 4, compact mode) at an
iteration budget on a scene and a backend. Runs go ``--jobs`` at a time (Warp's CPU kernels use one
thread, so two at once on a 2-core CPU; several on one GPU, which each run leaves mostly idle);
a run that already finished (metrics.json present) is reused unless --fresh, so an interrupted suite
continues where it stopped. Each run records its test-PSNR curve (``train.eval_every``), so a chart
shows PSNR against time along every run, not only its end point.

Outputs in --out (default bench/results/quality/suite_<device>): results.json (every run: config, metrics,
curve, status), psnr_vs_time.png, psnr_vs_gaussians.png and summary.md (tables per scene and the
charts). A failed run is recorded with the end of its log and the suite goes on.

Wall times are the training time the trainer measures (evaluation excluded) with runs sharing the
machine, so compare times within one suite run; the speed of one method alone is in metrics.json of
a run made with --jobs 1.

Screens of settings against the default (a switch on or off, over scenes and seeds) are sweep files run by the
batch runner (``bench/sweeps/switches.yaml``, ``python -m warpgs.pipelines.batch --sweep ...``) and compared with
``bench/report/compare.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.runfolder import checkpoint_file  # noqa: E402


@dataclass
class Run:
    """One training run of the suite."""

    name: str
    data: str
    method: str  # baseline | full
    iterations: int
    args: list = field(default_factory=list)  # extra CLI arguments (--set ..., --ablation ..., --compact)
    label: str = ""  # series name in the charts (runs of one label at several budgets form a line)
    case: str = ""  # the scene's name in charts and tables (e.g. castle_p30_3v); "": the scene the run reports
    seed: int | None = None  # --seed; None: the config's. Runs differing only in it are one point (the median)

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
    if run.seed is not None:
        args += ["--seed", str(run.seed)]
    return args + list(run.args)


def config_error(run: Run) -> str | None:
    """The error of the run's ``--set`` overrides against this checkout's config (a key it does not know, a
    value out of range), or None: such a run is recorded as failed without starting it."""
    from warpgs.config import ConfigError, load_config

    sets = [run.args[i + 1] for i, a in enumerate(run.args[:-1]) if a == "--set"]
    try:
        load_config(overrides=sets)
    except ConfigError as e:
        return f"error: {e}"
    return None


def not_started(run: Run, device: str, work: Path, error: str) -> dict:
    """The record of a run refused before it started (``config_error``)."""
    return {"run": asdict(run), "device": device, "out": str(work / run.name), "status": "failed",
            "returncode": None, "log_tail": error}


def command(run: Run, device: str, work: Path, data_root: str | None, resume: bool = False) -> list[str]:
    """--overwrite: the suite decides what to reuse (execute); a run it starts replaces what its folder holds.
    ``resume``: continue the run interrupted in its folder from its checkpoint (same arguments: the
    checkpoint's config is the base, and the run's own arguments set the same values again)."""
    mode = ["--resume"] if resume else ["--overwrite"]
    return [sys.executable, "-m", "warpgs.pipelines.sparse", *sparse_args(run, device, data_root),
            "--out", str(work / run.name), *mode]



STOP_GRACE_S = 120.0  # after SIGINT at the time limit: the run writes its checkpoint (then it is killed)
MIN_START_S = 20.0  # no run starts in the time limit's last seconds


def execute(run: Run, device: str, work: Path, data_root: str | None, fresh: bool, gpu: str | None = None,
            deadline: float | None = None) -> dict:
    """Runs (or reuses) one entry -> its record. ``gpu``: the run's ``CUDA_VISIBLE_DEVICES`` (``gpu_slots``).
    ``deadline`` (``time.time()`` seconds): the run is stopped then as Ctrl-C stops it (SIGINT: it keeps its
    checkpoint), recorded as ``stopped``, and a later call goes on from its checkpoint."""
    out = work / run.name
    metrics_path = out / "metrics.json"
    rec = {"run": asdict(run), "device": device, "out": str(out)}
    if gpu is not None:
        rec["gpu"] = gpu
    if metrics_path.is_file() and not fresh:
        rec.update(status="finished", reused=True, metrics=_slim(json.loads(metrics_path.read_text())))
        return rec
    error = config_error(run)
    if error:
        return not_started(run, device, work, error)
    # no metrics (see above) but a checkpoint: an earlier call stopped it (a time limit); go on from there
    resume = not fresh and checkpoint_file(out) is not None
    if resume:
        rec["resumed"] = True
    out.mkdir(parents=True, exist_ok=True)
    log = out.parent / f"{run.name}.log"
    t0 = time.perf_counter()
    stopped = False
    with open(log, "a" if resume else "w") as f:
        proc = subprocess.Popen(command(run, device, work, data_root, resume), cwd=ROOT, stdout=f,
                                stderr=subprocess.STDOUT, env={**os.environ, "PYTHONUNBUFFERED": "1",
                                                               **({"CUDA_VISIBLE_DEVICES": gpu} if gpu is not None else {})})
        try:
            proc.wait(timeout=None if deadline is None else max(deadline - time.time(), 0.0))
        except subprocess.TimeoutExpired:
            stopped = True
            proc.send_signal(signal.SIGINT)  # the run checkpoints and says how to go on
            try:
                proc.wait(timeout=STOP_GRACE_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    rec["wall_s"] = round(time.perf_counter() - t0, 2)
    if proc.returncode == 0 and metrics_path.is_file():
        rec.update(status="finished", metrics=_slim(json.loads(metrics_path.read_text())))
    elif stopped:
        rec.update(status="stopped", returncode=proc.returncode, log_tail=log.read_text()[-1500:])
    else:
        rec.update(status="failed", returncode=proc.returncode, log_tail=log.read_text()[-1500:])
    return rec


def execute_on_ray(runs: list[Run], device: str, work: Path, data_root: str | None, fresh: bool, jobs: int,
                   address: str | None, log=print) -> list[dict]:
    """The runs as tasks of the batch runner (``warpgs.pipelines.batch``: Ray, retries from checkpoints) -> their
    records. On CUDA each run asks for 1/``jobs`` of a GPU (``jobs`` runs per GPU, on every GPU Ray has); on
    the CPU a local Ray gets ``jobs`` CPUs, one per run. Logs in ``work``/logs. A run whose config this
    checkout refuses (``config_error``) is recorded as failed and not submitted."""
    from warpgs.pipelines import batch

    cuda = device.startswith("cuda")
    errors = {r.name: config_error(r) for r in runs}
    refused = {r.name: not_started(r, device, work, errors[r.name]) for r in runs if errors[r.name]}
    runs_ok = [r for r in runs if r.name not in refused]
    specs = [batch.RunSpec(r.name, sparse_args(r, device, data_root), r.data, None, r.method, r.seed,
                           num_gpus=1 / jobs if cuda else 0.0) for r in runs_ok]
    init = {"address": address} if address else {"num_cpus": None if cuda else jobs}
    recs = batch.run_on_ray(specs, work, work / "logs", overwrite=fresh, log=log, ray_init=init) if specs else []
    records = list(refused.values())
    for run, b in zip(runs_ok, recs):
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


def scene_of(rec: dict) -> str:
    """A record's scene in charts and tables: its run's case, else the scene its metrics name."""
    return rec["run"].get("case") or rec["metrics"]["scene"]


def _point(recs: list[dict]) -> dict:
    """One point of a chart or a table row from runs that differ only in their seed: the median of each
    metric, the PSNR's min and max, and the test-PSNR curve of the run whose PSNR is the median's."""
    def med(key):
        vals = [r["metrics"].get(key) for r in recs]
        return statistics.median(vals) if vals and all(v is not None for v in vals) else None

    psnrs = [r["metrics"]["psnr"] for r in recs]
    middle = min(recs, key=lambda r: abs(r["metrics"]["psnr"] - statistics.median(psnrs)))
    return {"iterations": recs[0]["run"]["iterations"], "n": len(recs), "psnr": statistics.median(psnrs),
            "psnr_min": min(psnrs), "psnr_max": max(psnrs), "ssim": med("ssim"), "lpips": med("lpips"),
            "num_gaussians": med("num_gaussians"), "train_time_s": med("train_time_s"),
            "render_fps": med("render_fps"), "device": recs[0]["metrics"].get("device", ""),
            "curve": middle["metrics"].get("curve") or []}


def _series(records: list[dict]) -> dict:
    """{scene: {label: [points sorted by iterations]}} of the finished runs, a point per budget (its seeds'
    median; ``_point``). Scenes and labels in the order of the records."""
    groups: dict = {}
    for r in records:
        if r.get("status") != "finished":
            continue
        key = (r["run"]["label"], r["run"]["iterations"])
        groups.setdefault(scene_of(r), {}).setdefault(key, []).append(r)
    out: dict = {}
    for scene, by_key in groups.items():
        for (label, _), recs in by_key.items():
            out.setdefault(scene, {}).setdefault(label, []).append(_point(recs))
        for points in out[scene].values():
            points.sort(key=lambda p: p["iterations"])
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
        cols = min(n, 4)
        rows = -(-n // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.2 * rows), squeeze=False)
        for ax in axes.flat[n:]:
            ax.axis("off")
        for ax, (scene, labels) in zip(axes.flat, series.items()):
            for i, (label, points) in enumerate(labels.items()):
                color, marker = f"C{i % 10}", "osD^v"[(i // 10) % 5]
                xs = [p[xkey] for p in points]
                ys = [p["psnr"] for p in points]
                ax.plot(xs, ys, marker + "-", color=color, label=label, ms=5)
                spread = [(p["psnr"] - p["psnr_min"], p["psnr_max"] - p["psnr"]) for p in points]
                if any(p["n"] > 1 for p in points):  # the seeds' min and max around their median
                    ax.errorbar(xs, ys, yerr=list(zip(*spread)), fmt="none", ecolor=color, capsize=3, lw=1)
                if kind == "time":  # the longest run's test-PSNR curve along its training time
                    curve = points[-1]["curve"]
                    if curve:
                        ax.plot([c["train_time_s"] for c in curve], [c["psnr"] for c in curve], ":", color=color,
                                alpha=0.6, lw=1)
                for p, x, y in zip(points, xs, ys):
                    ax.annotate(str(p["iterations"]), (x, y), fontsize=6, alpha=0.7,
                                textcoords="offset points", xytext=(3, 3))
            ax.set_title(f"{scene} ({points[0]['device']})", fontsize=10)
            ax.set_xlabel(xlabel)
            ax.set_ylabel("test PSNR (dB)")
            if kind == "time":
                ax.set_xscale("log")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        seeds = "\npoints over seeds: the median, bars from min to max" if any(
            p["n"] > 1 for labels in series.values() for points in labels.values() for p in points) else ""
        fig.suptitle("PSNR against " + ("training time (labels: iterations; dotted: test PSNR during the "
                                        "longest run)" if kind == "time" else "model size (labels: iterations)")
                     + seeds, fontsize=10)
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
             f"{info['jobs']} at a time (times are with runs sharing the machine). Where a row has several runs "
             "(seeds), each figure is their median and the PSNR's [min, max] follows it.", "",
             "![PSNR against time](psnr_vs_time.png)", "", "![PSNR against Gaussians](psnr_vs_gaussians.png)", ""]
    for scene, labels in _series(records).items():
        lines += [f"## {scene}", "",
                  "| method | iterations | PSNR | SSIM | LPIPS | Gaussians | training (s) | FPS | runs |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for label, points in labels.items():
            for p in points:
                psnr = f(p["psnr"], ".2f") + (f" [{p['psnr_min']:.2f}, {p['psnr_max']:.2f}]" if p["n"] > 1 else "")
                lines.append(f"| {label} | {p['iterations']} | {psnr} | {f(p['ssim'], '.3f')} | "
                             f"{f(p['lpips'], '.3f')} | {f(p['num_gaussians'], '.0f')} | {f(p['train_time_s'], '.1f')} | "
                             f"{f(p['render_fps'], '.0f')} | {p['n']} |")
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


def select_runs(runs: list[Run], preset: str, only: list[str] | None = None, scenes: list[str] | None = None,
                seeds: list[int] | None = None, iterations: int | None = None) -> list[Run]:
    """The part of a preset to run: ``only`` run names, labels, datasets or cases; ``scenes`` cases (or the
    scene a run reports: its dataset for presets without cases); ``seeds``; ``iterations`` replaces every
    run's budget (its name gets ``_it<N>``, so its folder is not an earlier run's). A name that selects
    nothing is a ``ValueError`` listing what there is."""
    for flag, wanted, keys in (("--only", only, lambda r: (r.name, r.label, r.data, r.case)),
                               ("--scenes", scenes, lambda r: (r.case or r.data,)),
                               ("--seeds", seeds, lambda r: (r.seed,))):
        if not wanted:
            continue
        unknown = [w for w in wanted if not any(w in keys(r) for r in runs)]
        if unknown:
            have = sorted({str(k) for r in runs for k in keys(r) if k is not None})
            raise ValueError(f"{flag} {', '.join(map(str, unknown))}: not in preset {preset} (it has: {', '.join(have)})")
        runs = [r for r in runs if any(k in wanted for k in keys(r))]
    if iterations is not None:
        if iterations < 1:
            raise ValueError(f"--iterations {iterations}: must be >= 1")
        runs = [Run(f"{r.name}_it{iterations}", r.data, r.method, iterations, list(r.args), r.label, r.case, r.seed)
                for r in runs]
    return runs


def default_out(device: str, preset: str) -> Path:
    """bench/results/quality/suite_<device> for the small and full presets, suite_<device>_<preset> for the others."""
    dev_tag = "cuda" if device.startswith("cuda") else "cpu"
    name = f"suite_{dev_tag}" if preset in ("small", "full") else f"suite_{dev_tag}_{preset}"
    return ROOT / "bench" / "results" / "quality" / name


def earlier_records(path: Path, preset: str) -> list[dict]:
    """The records of an earlier results.json of the same preset at ``path`` ([] when there is none): the
    runs a call leaves out keep theirs, so a preset run in parts (--scenes, --seeds, --only) adds up in one
    file."""
    try:
        earlier = json.loads(path.read_text())
    except (OSError, ValueError):
        return []
    return earlier.get("records", []) if earlier.get("info", {}).get("preset") == preset else []


def visible_gpus(gpus: int | None = None) -> list[str]:
    """The GPUs the suite spreads its runs over: the first ``gpus`` (None: all) of ``CUDA_VISIBLE_DEVICES`` where it
    is set, else of the devices torch counts."""
    listed = [g.strip() for g in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",") if g.strip()]
    if not listed:
        import torch

        listed = [str(i) for i in range(torch.cuda.device_count())]
    return listed[:gpus] if gpus else listed


def gpu_slots(jobs: int, gpus: list[str]):
    """A pool of ``jobs`` slots, each holding one GPU of ``gpus`` in turn (slot k: gpus[k mod len]): ``take()`` a
    slot's GPU (None with fewer than two GPUs: runs see what the suite sees) for one run, ``give(gpu)`` it back, so
    that each GPU holds at most ceil(jobs / len(gpus)) runs at a time."""
    import queue

    free: queue.Queue = queue.Queue()
    for k in range(jobs):
        free.put(gpus[k % len(gpus)] if len(gpus) > 1 else None)
    return free.get, free.put


def run_suite(device: str = "cpu", preset: str | None = None, out: Path | None = None, work: Path | None = None,
              jobs: int | None = None, only: list[str] | None = None, data_root: str | None = None,
              fresh: bool = False, log=print, ray: bool = False, address: str | None = None,
              scenes: list[str] | None = None, seeds: list[int] | None = None,
              iterations: int | None = None, gpus: int | None = None, time_limit: float | None = None) -> list[dict]:
    """Runs (a part of) a preset and writes results.json, the charts and summary.md (and for runs with cases,
    switches.md / switches.json) in ``out``; returns the records of the runs of this call. results.json
    keeps the records of the preset's other runs from an earlier call (``earlier_records``). On CUDA without Ray the
    runs are spread over ``gpus`` GPUs (None: every visible one; ``gpu_slots``). ``time_limit`` (s, without Ray):
    runs still going then are stopped and recorded as ``stopped`` (a later call goes on from their checkpoints), and
    runs not started by then are left out of this call (their earlier records, if any, stay)."""
    preset = preset or ("full" if device.startswith("cuda") else "small")
    if preset not in PRESETS:
        raise ValueError(f"preset {preset!r}: available {', '.join(PRESETS)}")
    runs = select_runs(PRESETS[preset], preset, only, scenes, seeds, iterations)
    dev_tag = "cuda" if device.startswith("cuda") else "cpu"
    out = out or default_out(device, preset)
    work = work or ROOT / "outputs" / f"suite_{dev_tag}_{preset}"
    jobs = jobs or (min(2, os.cpu_count() or 1) if dev_tag == "cpu" else 6)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    info = {"preset": preset, "device": device, "device_name": device_name(device), "jobs": jobs,
            "date": time.strftime("%Y-%m-%d %H:%M"), "runs": len(runs)}
    spread = visible_gpus(gpus) if dev_tag == "cuda" and not (ray or address) else []
    if len(spread) > 1:
        info["gpus"] = len(spread)
    log(f"suite: {len(runs)} runs of preset {preset} on {info['device_name']}"
        + (f" x {len(spread)} (GPUs {', '.join(spread)})" if len(spread) > 1 else "")
        + f", {jobs} at a time; work in {work}")
    take, give = gpu_slots(jobs, spread)
    records: list[dict] = []
    results_path = out / "results.json"
    earlier = earlier_records(results_path, preset)
    rank = {(r.case, r.label, r.seed, r.data): i for i, r in enumerate(PRESETS[preset])}

    def save(recs):  # this call's records and the earlier ones of the preset's other runs, in the preset's order
        names = {x["run"]["name"] for x in recs}
        merged = [r for r in earlier if r["run"]["name"] not in names] + recs
        merged.sort(key=lambda r: rank.get((r["run"].get("case", ""), r["run"]["label"], r["run"].get("seed"),
                                            r["run"]["data"]), len(rank)))
        results_path.write_text(json.dumps({"info": {**info, "runs": len(merged)}, "records": merged}, indent=1))
        return merged

    def report(rec: dict) -> dict:
        rec.setdefault("machine", info["device_name"])
        rec.setdefault("date", info["date"])
        m = rec.get("metrics") or {}
        log(f"  {rec['run']['name']:<36} {rec['status']:<9}" + (f" PSNR {m['psnr']:.2f}  {m['num_gaussians']} "
                                                                f"Gaussians  {m['train_time_s']:.0f} s" if m else ""))
        records.append(rec)
        return rec

    deadline = None if time_limit is None else time.time() + time_limit

    def one(run: Run) -> dict | None:
        if deadline is not None and time.time() > deadline - MIN_START_S:
            return None  # too late to start: the next call runs it
        gpu = take()
        try:
            rec = report(execute(run, device, work, data_root, fresh, gpu, deadline))
        finally:
            give(gpu)
        save(list(records))  # progress survives
        return rec

    if ray or address:
        for rec in execute_on_ray(runs, device, work, data_root, fresh, jobs, address, log):
            report(rec)
    else:
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            list(pool.map(one, runs))
    order = {r.name: i for i, r in enumerate(runs)}
    records.sort(key=lambda r: order[r["run"]["name"]])
    merged = save(records)
    written = write_reports(merged, {**info, "runs": len(merged)}, out)
    log(f"suite: wrote {results_path}, " + ", ".join(str(p) for p in written))
    return records


def write_reports(records: list[dict], info: dict, out: Path) -> list[Path]:
    """The charts and summary.md."""
    return plot(records, out) + [write_summary(records, info, out)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None, help="cpu or cuda (default: cuda if available)")
    ap.add_argument("--preset", default=None, choices=list(PRESETS), help="default: small on cpu, full on cuda")
    ap.add_argument("--only", default=None, help="comma-separated run names, labels, datasets or cases of the "
                    "preset")
    ap.add_argument("--scenes", default=None, help="comma-separated cases of the preset")
    ap.add_argument("--seeds", default=None, help="comma-separated seeds of the preset")
    ap.add_argument("--iterations", type=int, default=None, help="replace every run's budget (smoke tests)")
    ap.add_argument("--jobs", type=int, default=None, help="runs at a time (default: 2 on cpu, 6 on cuda)")
    ap.add_argument("--time-limit", type=float, default=None, help="seconds (without --ray): then the runs still "
                    "going are stopped at their checkpoints and the rest left for the next call")
    ap.add_argument("--gpus", type=int, default=None, help="on cuda without --ray: spread the runs over the first N "
                    "visible GPUs (default: all), --jobs in all")
    ap.add_argument("--data-root", default=None, help="folder holding llff_fern, blender_lego, dtu_scan65, castle_p30, "
                    "herz_jesus_p25, ...")
    ap.add_argument("--out", type=Path, default=None, help="default bench/results/quality/suite_<device> (small, full) or "
                    "suite_<device>_<preset>")
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
        out = a.out or default_out(a.device, a.preset or ("full" if a.device.startswith("cuda") else "small"))
        data = json.loads((out / "results.json").read_text())
        for path in write_reports(data["records"], data["info"], out):
            print(f"wrote {path}")
        return 0
    try:
        seeds = [int(x) for x in a.seeds.split(",")] if a.seeds else None
    except ValueError:
        print(f"error: --seeds {a.seeds!r}: expected comma-separated integers", file=sys.stderr)
        return 2
    try:
        records = run_suite(a.device, a.preset, a.out, a.work, a.jobs, a.only.split(",") if a.only else None,
                            a.data_root, a.fresh, ray=a.ray, address=a.address,
                            scenes=a.scenes.split(",") if a.scenes else None, seeds=seeds, iterations=a.iterations,
                            gpus=a.gpus, time_limit=a.time_limit)
    except ValueError as e:  # also warpgs.pipelines.batch.BatchError: Ray is not installed
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0 if all(r.get("status") == "finished" for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
