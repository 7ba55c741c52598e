"""The benchmark charts and their tables, drawn from the committed results (one command):

    python bench/report/charts.py                                   # charts into docs/img/, tables into docs/benchmarks.md
    python bench/report/charts.py --collect outputs/sweeps/speed_accuracy --name speed_accuracy
    python bench/report/charts.py --collect outputs/sweeps/compact --name compact --machine "NVIDIA H200"
    python bench/report/charts.py --collect outputs/more --name speed_accuracy --commit 295fedc --merge  # a sweep's rest

``--collect DIR`` reads a batch folder of ``python -m warpgs.pipelines.batch`` (``DIR/runs/<name>/metrics.json``,
``DIR/logs/<name>.attempts.jsonl`` and ``.log``, ``.argv.json``) into one results file,
``bench/results/quality/<name>_<machine>.json``: every run with its figures (test PSNR, the initial render's PSNR,
Gaussians, parameter bytes, training time, recoveries, how it stopped) or how it failed, and the machine and the
commit it was measured at (``--machine``: default the GPU name in the runs' logs, else this machine's; ``--commit``:
default ``git rev-parse`` of this checkout). Run it where the sweep ran, or name the machine. ``--merge`` adds the
folder's runs to the results file already there, of the same machine and commit (``merge``: a sweep whose runs
were finished in a later call, from another batch folder).

Without ``--collect`` it reads every results file of ``bench/results/quality`` (``load_sources``: the collected
ones, and the older committed ones where they have the fields a chart needs) and draws

- ``speed_accuracy_time.png``, ``speed_accuracy_size.png``: per scene (and view count), each method and switch one
  point, test PSNR against training time and against Gaussians: the median over seeds, the PSNR range as a bar; a
  point of fewer than 3 seeds is hollow and labelled ``n=1`` or ``n=2``;
- ``stability.png``: per method, how many runs ended ok, diverged, non-finite, out of memory, collapsed (test PSNR
  below the initial render's) or failed (``classify``), on the stress cases and on the 3-view captures;
- ``compact.png``: per scene, Gaussians and MB against test PSNR, the default against compact mode, with the goal
  (50% fewer at <= 0.1 dB lost) as a shaded corner, and the verdict per scene (``compact_verdicts``);

and writes the tables ``speed_accuracy``, ``stability`` and ``compact`` between their markers in docs/benchmarks.md
(``bench/report/markers.py``). Every chart and table names the source file, machine and commit (or date, where the
commit was not recorded) of its figures.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from markers import markers, replace_between_markers  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "bench" / "results" / "quality"
IMG = ROOT / "docs" / "img"
DOC = ROOT / "docs" / "benchmarks.md"
SEEDS_WANTED = 3
GOAL_REDUCTION, GOAL_LOSS_DB = 0.5, 0.1  # compact mode: at least 50% fewer Gaussians at most 0.1 dB lost
CATEGORIES = ("ok", "diverged", "non-finite", "out of memory", "collapse", "failed", "unchecked")
COLORS = {"ok": "tab:green", "diverged": "tab:orange", "non-finite": "tab:purple", "out of memory": "tab:red",
          "collapse": "tab:brown", "failed": "black", "unchecked": "lightgrey"}
RUN_NAME = re.compile(r"^(?P<scene>.+?)_(?:(?P<views>\d+)v_)?(?P<method>baseline|full|corgs)_s(?P<seed>\d+)"
                      r"(?:_(?P<variant>[A-Za-z0-9.-]+))?$")
METRIC_KEYS = ("psnr", "ssim", "initial_psnr", "train_psnr", "num_gaussians", "param_bytes", "ply_bytes", "sh_degree",
               "train_time_s", "iterations", "resolution", "skipped_steps", "max_loss_ratio", "peak_cuda_allocated_mb")


# ----------------------------------------------------------------------------------------------
# runs: names, classification, medians


def parse_run_name(name: str) -> dict:
    """``<scene>_<views>v_<method>_s<seed>[_<variant>]`` (the batch runner's names) -> its parts; views None for a
    scene without a view count, variant "" for the default."""
    m = RUN_NAME.match(name)
    if m is None:
        raise ValueError(f"run name {name!r}: expected <scene>_<views>v_<method>_s<seed>[_<variant>]")
    return {"scene": m["scene"], "views": int(m["views"]) if m["views"] else None, "method": m["method"],
            "seed": int(m["seed"]), "variant": m["variant"] or ""}


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def classify(run: dict) -> str:
    """How a run ended, one of ``CATEGORIES``: ``out of memory`` (it stopped on running out of memory, or every
    attempt died of it), ``non-finite`` (its guard stopped it on non-finite losses or parameters, or its final
    figures are not finite), ``diverged`` (its guard stopped it after its recoveries ran out, on exploding
    losses), ``failed`` (no figures: it crashed or stopped with an error), ``collapse`` (finished, test PSNR below
    the initial render's), ``ok``; ``unchecked`` for a finished run whose initial render's PSNR was not recorded."""
    status = run.get("status", "finished")
    stop = run.get("stopped_early") or {}
    cause = str(stop.get("cause") or run.get("error") or "").lower()
    if stop.get("reason") == "out_of_memory" or run.get("oom") or "out of memory" in cause or "outofmemory" in cause:
        return "out of memory"
    if stop.get("reason") == "diverged" or "trainingdiverged" in cause:
        return "non-finite" if ("finite" in cause or "nan" in cause) else "diverged"
    if status != "finished":
        return "failed"
    psnr = run.get("psnr")
    if psnr is not None and not _finite(psnr):
        return "non-finite"
    if psnr is None:
        return "failed"
    if not _finite(run.get("initial_psnr")):
        return "unchecked"
    return "collapse" if psnr < run["initial_psnr"] else "ok"


def spread(values) -> dict | None:
    """Median, min, max and count of the finite numbers among ``values``; None when there is none."""
    xs = [float(v) for v in values if _finite(v)]
    if not xs:
        return None
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs), "n": len(xs)}


def label(run: dict) -> str:
    """A run's series: its method, ``+variant`` for a switch."""
    return run["method"] + (f"+{run['variant']}" if run.get("variant") else "")


def scene_key(run: dict) -> str:
    return run["scene"] + (f" {run['views']}v" if run.get("views") else "")


def completed(run: dict) -> bool:
    """A run that trained to its end and has a test PSNR (not one stopped early: its figures are an earlier
    state's)."""
    return run.get("status", "finished") == "finished" and not run.get("stopped_early") and _finite(run.get("psnr"))


def points(runs: list[dict]) -> dict:
    """{scene key: {series: medians}} over the completed runs (each method and switch one point): ``psnr``,
    ``train_time_s``, ``num_gaussians``, ``mb`` (float32 parameters) as ``spread``s, and ``n``, the seeds with a
    test PSNR."""
    out: dict = {}
    for r in runs:
        if completed(r):
            out.setdefault(scene_key(r), {}).setdefault(label(r), []).append(r)
    return {scene: {lab: {"psnr": spread(x["psnr"] for x in rs),
                          "train_time_s": spread(x.get("train_time_s") for x in rs),
                          "num_gaussians": spread(x.get("num_gaussians") for x in rs),
                          "mb": spread((x.get("param_bytes") or math.nan) / 1e6 for x in rs),
                          "n": len(rs)} for lab, rs in series.items()}
            for scene, series in out.items()}


def compact_verdicts(runs: list[dict]) -> list[dict]:
    """Per scene and method: the compact runs (variant ``compact``) against the default ones of the same scene,
    view count, method, iterations and resolution: the medians over seeds of each, the reduction of Gaussians and
    of bytes, the change of test PSNR, whether the goal is met, and why not."""
    def same(a, b):
        return all(a.get(k) == b.get(k) for k in ("scene", "views", "method", "iterations", "resolution")
                   if a.get(k) is not None and b.get(k) is not None)

    done = [r for r in runs if completed(r)]
    groups: dict = {}
    for c in (r for r in done if r.get("variant") == "compact"):
        groups.setdefault((scene_key(c), c["method"]), {"compact": [], "default": []})["compact"].append(c)
    for key, g in groups.items():
        g["default"] = [d for d in done if not d.get("variant") and (scene_key(d), d["method"]) == key
                        and same(d, g["compact"][0])]
    rows = []
    for (scene, method), g in groups.items():
        if not g["default"]:
            continue
        d = {k: spread(r.get(k) for r in g["default"]) for k in ("psnr", "num_gaussians", "param_bytes")}
        c = {k: spread(r.get(k) for r in g["compact"]) for k in ("psnr", "num_gaussians", "param_bytes")}
        reduction = 1 - c["num_gaussians"]["median"] / d["num_gaussians"]["median"]
        mb_reduction = (1 - c["param_bytes"]["median"] / d["param_bytes"]["median"]
                        if d["param_bytes"] and c["param_bytes"] else None)
        change = c["psnr"]["median"] - d["psnr"]["median"]
        why = [f"{100 * reduction:.0f}% fewer Gaussians, short of {100 * GOAL_REDUCTION:.0f}%"] if reduction < GOAL_REDUCTION else []
        why += [f"loses {-change:.2f} dB, more than {GOAL_LOSS_DB} dB"] if change < -GOAL_LOSS_DB else []
        n = min(len(g["default"]), len(g["compact"]))
        rows.append({"scene": scene, "method": method, "default": d, "compact": c, "reduction": reduction,
                     "mb_reduction": mb_reduction, "psnr_change": change, "met": not why, "why": "; ".join(why),
                     "n": n})
    return rows


def stability_counts(runs: list[dict]) -> dict:
    """{method: {category: runs}} over the runs that ended (a run stopped or not started at a batch's deadline
    has not: it is left out)."""
    out: dict = {}
    for r in runs:
        if r.get("status") in ("stopped", "not_started"):
            continue
        counts = out.setdefault(r["method"], dict.fromkeys(CATEGORIES, 0))
        counts[classify(r)] += 1
    return out


# ----------------------------------------------------------------------------------------------
# collecting a batch folder


def _warp_device(log_text: str) -> str | None:
    """The CUDA device a run used, from Warp's start-up lines in its log (``"cuda:0" : "NVIDIA H200" ...``)."""
    m = re.search(r'"cuda:0"\s*:\s*"([^"]+)"', log_text)
    return m[1] if m else None


def collect_run(name: str, run_dir: Path, logs: Path) -> dict:
    """One run of a batch folder: its name's parts, its figures (metrics.json) and how it ended."""
    from warpgs.pipelines.batch import read_attempts

    rec = parse_run_name(name)
    attempts = read_attempts(logs / f"{name}.attempts.jsonl")
    log = (logs / f"{name}.log").read_text(errors="replace") if (logs / f"{name}.log").is_file() else ""
    try:
        m = json.loads((run_dir / "metrics.json").read_text())
    except (OSError, ValueError):
        m = None
    rec["oom"] = any(a.get("oom") for a in attempts)
    if m is not None and "psnr" in m:
        rec.update({k: m[k] for k in METRIC_KEYS if k in m})
        rec["recoveries"] = len(m.get("recoveries") or [])
        if m.get("stopped_early"):
            rec["stopped_early"] = m["stopped_early"]
        rec["oom"] = rec["oom"] and (m.get("stopped_early") or {}).get("reason") == "out_of_memory"
        if isinstance(m.get("compact"), dict):  # compact mode's search: where its loss and its stop came from
            rec["compact"] = compact_summary(m["compact"])
        rec["status"] = "finished"
    elif attempts and attempts[-1].get("deadline"):
        rec["status"] = "stopped"
    elif not attempts:
        rec["status"] = "not_started"
    else:
        rec["status"] = "failed"
        errors = [ln for ln in log.splitlines() if ln.startswith("error: ") or "Error" in ln]
        rec["error"] = (errors[-1] if errors else f"exit code {attempts[-1].get('returncode')}")[:300]
    rec["device"] = _warp_device(log)
    return rec


COMPACT_POINT_KEYS = ("kind", "ratio", "sh_degree", "num_gaussians", "train_psnr", "test_psnr", "within_tolerance")


def compact_summary(report: dict) -> dict:
    """A compact run's search (metrics.json's ``compact``, ``warpgs.strategy.compact.search``) as kept in a
    results file: the trained model before the search, the kept one, the best training-view PSNR it was judged
    against, each point (ratio, count, training- and test-view PSNR) and the pruning during training."""
    return {"before": report.get("before"), "after": report.get("after"),
            "best_train_psnr": report.get("best_train_psnr"), "tolerance_db": report.get("tolerance_db"),
            "points": [{k: p[k] for k in COMPACT_POINT_KEYS if k in p} for p in report.get("points") or []],
            "pruned_during_training": report.get("pruned_during_training")}


def git_commit(root: Path = ROOT) -> str | None:
    """This checkout's commit (short), ``+changes`` when its tracked files differ from it; None without git."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+changes" if dirty else "")


def this_machine() -> str:
    try:
        import torch

        if torch.cuda.is_available():
            return torch.cuda.get_device_name(0)
    except ImportError:
        pass
    return f"{platform.processor() or platform.machine()} CPU"


def collect(batch_dir: Path, name: str, *, machine: str | None = None, commit: str | None = None,
            sweep: str | None = None) -> dict:
    """A batch folder -> a results document (``--collect``): every run the folder knows (a run folder, or the
    settings its batch recorded in ``logs/<run>.argv.json``), the machine and the commit."""
    batch_dir = Path(batch_dir)
    logs, work = batch_dir / "logs", batch_dir / "runs"
    names = {p.name for p in work.iterdir() if p.is_dir()} if work.is_dir() else set()
    names = sorted(names | {p.name[:-len(".argv.json")] for p in logs.glob("*.argv.json")})
    runs = {n: collect_run(n, work / n, logs) for n in names if RUN_NAME.match(n)}
    devices = sorted({r.pop("device") for r in runs.values()} - {None})
    info = {}
    try:
        info = json.loads((batch_dir / "results.json").read_text()).get("info", {})
    except (OSError, ValueError):
        pass
    return {"what": f"the runs of {sweep or info.get('sweep') or batch_dir.name} (bench/report/charts.py --collect)",
            "sweep": sweep or info.get("sweep"), "machine": machine or (devices[0] if len(devices) == 1 else None)
            or this_machine(), "commit": commit or git_commit(), "date": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
            "seeds": sorted({r["seed"] for r in runs.values()}), "runs": runs}


def merge(old: dict, new: dict) -> dict:
    """``--merge``: a results file (``old``) with a later collect of the same machine and commit (``new``), for a
    sweep finished over several calls or machines' leases: each run of ``new`` replaces the one of that name
    unless ``old``'s is complete and ``new``'s is not; ``dates`` keeps when each part was collected.
    ``ValueError`` when the machine or the commit differs: one file holds one code on one machine."""
    for key in ("machine", "commit"):
        if old.get(key) != new.get(key):
            raise ValueError(f"--merge: the file's {key} is {old.get(key)!r}, these runs' {new.get(key)!r}; a results "
                             "file holds one machine and commit (collect them under another --name)")
    runs = dict(old["runs"])
    for name, run in new["runs"].items():
        if not (name in runs and completed(runs[name]) and not completed(run)):
            runs[name] = run
    dates = (old.get("dates") or [old.get("date")]) + [new.get("date")]
    return {**old, "date": new.get("date"), "dates": dates, "seeds": sorted({r["seed"] for r in runs.values()}),
            "runs": dict(sorted(runs.items()))}


def machine_tag(machine: str) -> str:
    """``NVIDIA H200`` -> ``h200``: the end of a results file's name."""
    words = re.findall(r"[A-Za-z0-9]+", machine.lower())
    gpu = [w for w in words if re.fullmatch(r"[a-z]+\d+[a-z]*|\d{3,4}[a-z]*", w) and w not in ("x86", "64")]
    return gpu[0] if gpu else ("cpu" if "cpu" in words else "_".join(words[:2]) or "unknown")


# ----------------------------------------------------------------------------------------------
# the committed results


SCENE_ALIASES = {"dtu65": "scan65"}  # the switch screen's names of scenes the batch runner names otherwise


def _runs_of_switch_screen(doc: dict) -> dict:
    """The switch screen's ``stats`` (``"<scene>_<views>v|<method>[+<switch>]"``: per-seed lists) as runs."""
    runs = {}
    for key, s in doc["stats"].items():
        scene, series = key.split("|")
        scene = SCENE_ALIASES.get(scene.split("_")[0], scene.split("_")[0]) + scene[len(scene.split("_")[0]):]
        method, _, switch = series.partition("+")
        for i, seed in enumerate(s["seeds"]):
            name = f"{scene}_{method}_s{seed}" + (f"_{switch.replace('_', '-')}" if switch else "")
            runs[name] = {k: s[k][i] for k in ("psnr", "train_time_s", "num_gaussians") if k in s}
    return runs


def _runs_of_stability(doc: dict) -> dict:
    """bench/quality/stability.py's records as runs (its statuses: finished, stopped with the guard's or a
    scene's error, crashed)."""
    runs = {}
    for r in doc["runs"]:
        m = r.get("metrics") or {}
        run = {k: m.get(k) for k in METRIC_KEYS if k in m}
        run["recoveries"] = len(m.get("recoveries") or [])
        run["status"] = "finished" if r["status"] == "finished" else "failed"
        if r.get("message"):
            run["error"] = r["message"]
        runs[f"{r['case']}_{r['method']}_s{r['seed']}"] = run
    return runs


def _runs_of_compact(doc: dict) -> dict:
    """bench/quality/compact.py's document (one seed, the config's) as a default and a compact run."""
    seed = doc.get("seed", 0)
    views = f"{doc['views']}v_" if doc.get("views") else ""  # documents before 2026-11-29 did not record it
    base = f"{doc['scene']}_{views}{doc['method']}_s{seed}"
    keep = ("psnr", "num_gaussians", "param_bytes", "iterations", "train_time_s")
    return {base: {k: doc["default"].get(k) for k in keep}, f"{base}_compact": {k: doc["compact"].get(k) for k in keep}}


def _source(path: Path, doc: dict, kind: str, runs: dict, machine: str | None) -> dict:
    rows = []
    for name, figures in runs.items():
        try:
            parts = parse_run_name(name)
        except ValueError:
            continue
        rows.append({**parts, **{k: v for k, v in figures.items() if k not in parts}, "name": name})
    return {"file": str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path), "kind": kind,
            "machine": machine or doc.get("machine") or "not recorded", "commit": doc.get("commit"),
            "date": str(doc.get("date") or "")[:10], "when": str(doc.get("date") or ""), "runs": rows}


def load_sources(results: Path = RESULTS) -> list[dict]:
    """Every results file of ``results`` that a chart can use, each ``{"file", "kind", "machine", "commit", "date",
    "runs"}`` with its runs as dicts (``parse_run_name``'s parts and the figures): ``kind`` ``runs`` (a collected
    sweep, or an older summary of runs), ``stress`` (bench/quality/stability.py) or ``compact``
    (bench/quality/compact.py)."""
    sources = []
    for path in sorted(results.glob("*.json")):
        doc = json.loads(path.read_text())
        if isinstance(doc.get("runs"), dict):
            sources.append(_source(path, doc, "runs", doc["runs"], None))
        elif "stats" in doc and "info" in doc:
            info = doc["info"]
            gpus = info.get("gpus") or 1
            sources.append(_source(path, {**doc, "date": info.get("date")}, "runs", _runs_of_switch_screen(doc),
                                   f"{gpus} x {info['device_name']}" if gpus > 1 else info.get("device_name")))
    for path in sorted(results.glob("*/stability.json")):
        doc = json.loads(path.read_text())
        info = doc["info"]
        machine = info.get("machine") or f"{info['device']} (host {info.get('host', '?')})"
        sources.append(_source(path, {**info, "date": info.get("date")}, "stress", _runs_of_stability(doc), machine))
    for path in sorted(results.glob("*/compact.json")):
        doc = json.loads(path.read_text())
        machine = doc.get("machine") or ("GPU model not recorded" if doc["device"] == "cuda" else doc["device"])
        sources.append(_source(path, doc, "compact", _runs_of_compact(doc), machine))
    return sources


def stamp(src: dict) -> str:
    """Where a source's figures were measured: machine, and commit (or the date, where none was recorded)."""
    if src.get("commit"):
        return f"{src['machine']}, commit {src['commit']}"
    return f"{src['machine']}, {src['date'] or 'date not recorded'} (commit not recorded)"


def _usable(src: dict) -> list[dict]:
    """A source's runs that are a speed-accuracy point: not compact mode, with a training time or a Gaussian count."""
    return [r for r in src["runs"] if r.get("variant") != "compact"
            and (r.get("train_time_s") is not None or r.get("num_gaussians") is not None)]


def speed_accuracy_scenes(sources: list[dict]) -> dict:
    """{scene key: (source, its points)}: the runs of the newest machine and commit that has such points
    (``newest_code``); per scene, the newest of its sources whose runs there have a test PSNR and a training time
    or a Gaussian count (a newer one, or one with both, replaces an older one)."""
    best: dict = {}
    for src in newest_code([s for s in sources if s["kind"] == "runs" and points(_usable(s))]):
        for scene, series in points(_usable(src)).items():
            both = any(p["train_time_s"] and p["num_gaussians"] for p in series.values())
            rank = (both, src.get("when", src["date"]))
            if scene not in best or rank >= best[scene][0]:
                best[scene] = (rank, src, series)
    return {scene: (src, series) for scene, (_, src, series) in sorted(best.items())}


# ----------------------------------------------------------------------------------------------
# charts


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _series_colors(names) -> dict:
    names = sorted(set(names), key=lambda s: (s.split("+")[0], "+" in s, s))
    return {s: f"C{i % 10}" for i, s in enumerate(names)}


def _point(ax, x, y, yrange, n, color, marker="o"):
    hollow = n < SEEDS_WANTED
    if yrange is not None:
        ax.plot([x, x], [yrange["min"], yrange["max"]], "-", color=color, lw=1, alpha=0.6)
    ax.plot([x], [y], marker, ms=7, color=color, mfc="white" if hollow else color, mew=1.5)
    if hollow:
        ax.annotate(f"n={n}", (x, y), textcoords="offset points", xytext=(4, 3), fontsize=6, color=color)


def chart_speed_accuracy(scenes: dict, out: Path) -> list[Path]:
    """Two figures, one panel per scene: test PSNR against training time, and against Gaussians."""
    plt = _plt()
    if not scenes:
        return []
    colors = _series_colors(s for _, series in scenes.values() for s in series)
    cols = min(4, len(scenes))
    rows = math.ceil(len(scenes) / cols)
    paths = []
    for key, xlabel, fname in (("train_time_s", "training time (s)", "speed_accuracy_time.png"),
                               ("num_gaussians", "Gaussians", "speed_accuracy_size.png")):
        fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows + 0.9), squeeze=False)
        for ax, (scene, (src, series)) in zip(axes.flat, scenes.items()):
            for name, p in series.items():
                if p[key] is not None:
                    _point(ax, p[key]["median"], p["psnr"]["median"], p["psnr"], p["n"], colors[name])
            if not any(p[key] for p in series.values()):
                ax.text(0.5, 0.5, f"no {xlabel} recorded", ha="center", va="center", transform=ax.transAxes, fontsize=8)
            ax.set_title(f"{scene}\n{stamp(src)}", fontsize=8)
            ax.set_xlabel(xlabel, fontsize=8)
            ax.set_ylabel("test PSNR (dB)", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[len(scenes):]:
            ax.axis("off")
        handles = [plt.Line2D([], [], marker="o", ls="", color=c, label=s) for s, c in colors.items()]
        fig.legend(handles=handles, loc="lower center", ncol=min(6, len(handles)), fontsize=7, frameon=False)
        fig.suptitle(f"test PSNR against {xlabel}: median over seeds (bar: PSNR range; hollow: fewer than "
                     f"{SEEDS_WANTED} seeds)", fontsize=10)
        fig.tight_layout(rect=(0, 0.06 if len(handles) > 6 else 0.04, 1, 0.97))
        paths.append(_save(fig, out / fname))
    return paths


def chart_stability(panels: dict, out: Path) -> Path | None:
    """Stacked bars: per panel (stress cases, 3-view captures) and method, the runs in each category."""
    plt = _plt()
    panels = {k: v for k, v in panels.items() if v["counts"]}
    if not panels:
        return None
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 3.6), squeeze=False)
    for ax, (title, panel) in zip(axes[0], panels.items()):
        methods = list(panel["counts"])
        left = [0] * len(methods)
        for cat in CATEGORIES:
            vals = [panel["counts"][m][cat] for m in methods]
            if any(vals):
                ax.barh(methods, vals, left=left, color=COLORS[cat], label=cat, edgecolor="white")
                left = [a + b for a, b in zip(left, vals)]
        ax.set_title(f"{title}\n" + "\n".join(panel["stamps"]), fontsize=8)
        ax.set_xlabel("runs", fontsize=8)
        ax.legend(fontsize=7, loc="lower right")
        ax.grid(axis="x", alpha=0.3)
    fig.suptitle("how runs end: ok, diverged, non-finite, out of memory, collapse (test PSNR below the initial "
                 "render's), failed; unchecked: no initial PSNR recorded", fontsize=9)
    fig.tight_layout()
    return _save(fig, out / "stability.png")


def chart_compact(verdicts: list[dict], out: Path) -> Path | None:
    """Per scene: Gaussians (top) and MB (bottom) against test PSNR, default and compact, with the goal's corner."""
    plt = _plt()
    if not verdicts:
        return None
    fig, axes = plt.subplots(2, len(verdicts), figsize=(3.6 * len(verdicts) + 0.6, 6.4), squeeze=False)
    for j, v in enumerate(verdicts):
        for i, (key, scale, xlabel) in enumerate((("num_gaussians", 1.0, "Gaussians"), ("param_bytes", 1e-6, "MB"))):
            ax = axes[i][j]
            d, c = v["default"], v["compact"]
            if d[key] is None or c[key] is None:
                ax.text(0.5, 0.5, f"no {xlabel} recorded", ha="center", va="center", transform=ax.transAxes, fontsize=8)
                continue
            dx, cx = d[key]["median"] * scale, c[key]["median"] * scale
            floor, x_goal = d["psnr"]["median"] - GOAL_LOSS_DB, dx * (1 - GOAL_REDUCTION)
            ys = [floor, d["psnr"]["min"], d["psnr"]["max"], c["psnr"]["min"], c["psnr"]["max"]]
            ax.set_ylim(min(ys) - 0.15, max(ys) + 0.15)
            ax.fill_between([0, x_goal], floor, max(ys) + 0.15, color="tab:green", alpha=0.1, lw=0)
            ax.axhline(floor, color="tab:green", ls="--", lw=0.8)
            ax.axvline(x_goal, color="tab:green", ls="--", lw=0.8)
            _point(ax, dx, d["psnr"]["median"], d["psnr"], v["n"], "tab:blue")
            _point(ax, cx, c["psnr"]["median"], c["psnr"], v["n"], "tab:red", marker="s")
            ax.set_xlim(0, max(dx, cx) * 1.15)
            ax.set_xlabel(xlabel, fontsize=8)
            ax.set_ylabel("test PSNR (dB)", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
            if i == 0:
                verdict = "met" if v["met"] else "not met"
                ax.set_title(f"{v['scene']} ({v['method']})\n{100 * v['reduction']:.0f}% fewer, "
                             f"{v['psnr_change']:+.2f} dB: {verdict}\n{v['stamp']}", fontsize=7)
    handles = [plt.Line2D([], [], marker="o", ls="", color="tab:blue", label="default"),
               plt.Line2D([], [], marker="s", ls="", color="tab:red", label="compact mode"),
               plt.Line2D([], [], ls="--", color="tab:green", label="goal: 50% fewer, <= 0.1 dB lost")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle("compact mode against the default: median over seeds (hollow: fewer than 3 seeds)", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return _save(fig, out / "compact.png")


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


# ----------------------------------------------------------------------------------------------
# tables


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def _f(s: dict | None, key: str = "median", fmt: str = ".2f") -> str:
    return "-" if s is None else format(s[key], fmt)


def _seeds(n: int) -> str:
    return str(n) if n >= SEEDS_WANTED else f"n={n}"


def speed_accuracy_table(scenes: dict) -> list[str]:
    rows = []
    for scene, (src, series) in scenes.items():
        for name, p in sorted(series.items()):
            rows.append([scene, name, _seeds(p["n"]), f"{_f(p['psnr'])} [{_f(p['psnr'], 'min')}, {_f(p['psnr'], 'max')}]",
                         _f(p["train_time_s"], fmt=".1f"), _f(p["num_gaussians"], fmt=",.0f"), _f(p["mb"], fmt=".1f"),
                         stamp(src), f"`{src['file']}`"])
    return _table(["scene", "method", "seeds", "test PSNR median [min, max]", "training s", "Gaussians", "MB",
                   "machine, commit", "source"], rows)


CAPTURES = ("castle_p30", "herz_jesus_p25")


def sparse_run(run: dict) -> bool:
    """A run of the stability chart's second panel: a capture at 3 views or fewer, the embedded room at 2."""
    views = run.get("views") or 99
    return (run["scene"] in CAPTURES and views <= 3) or (run["scene"] == "synthetic" and views == 2)


def _newest(sources: list[dict]) -> list[dict]:
    return sorted(sources, key=lambda s: (bool(s.get("commit")), s.get("when", s["date"])))


def newest_code(sources: list[dict]) -> list[dict]:
    """The sources of the newest machine and commit among ``sources``: a chart shows one code on one machine
    (older results stay in their files and records)."""
    if not sources:
        return []
    last = _newest(sources)[-1]
    return [s for s in sources if (s["machine"], s.get("commit")) == (last["machine"], last.get("commit"))]


def stability_panels(sources: list[dict]) -> dict:
    """The stability chart's panels: the stress cases (bench/quality/stability.py, its newest results), and the
    sparsest real inputs (``sparse_run``) of each method at its defaults (no switch, not compact), from the
    results files of runs of the newest machine and commit that has them: one code, one machine (a run in several
    of its files counted once, from the newest)."""
    panels = {}
    stress = [s for s in sources if s["kind"] == "stress"]
    if stress:
        src = _newest(stress)[-1]
        panels["stress cases (synthetic room)"] = {"counts": stability_counts(src["runs"]), "stamps": [stamp(src)],
                                                   "files": [src["file"]]}
    runs, used = {}, {}
    with_sparse = [s for s in sources if s["kind"] == "runs" and any(sparse_run(r) for r in s["runs"])]
    for src in _newest(newest_code(with_sparse)):
        for r in src["runs"]:
            if sparse_run(r) and not r.get("variant"):
                runs[r["name"]], used[r["name"]] = r, src
    if runs:
        srcs = list({id(s): s for s in used.values()}.values())
        panels["captures at 2-3 views, room at 2 (defaults)"] = {
            "counts": stability_counts(list(runs.values())), "stamps": list(dict.fromkeys(stamp(s) for s in srcs)),
            "files": [s["file"] for s in srcs]}
    return panels


def stability_table(panels: dict) -> list[str]:
    rows = []
    for title, panel in panels.items():
        for method, counts in panel["counts"].items():
            rows.append([title, method, str(sum(counts.values()))] + [str(counts[c]) for c in CATEGORIES]
                        + ["; ".join(panel["stamps"]), ", ".join(f"`{f}`" for f in panel["files"])])
    return _table(["runs of", "method", "runs", *CATEGORIES, "machine, commit", "source"], rows)


GOAL_SCENES = tuple(f"{c} {v}v" for c in ("castle_p30", "herz_jesus_p25") for v in (3, 6, 9)) + ("fern 3v", "lego 8v")


def compact_table(verdicts: list[dict]) -> list[str]:
    """The verdict per scene, and a row for each scene of the goal (``GOAL_SCENES``) with none yet."""
    rows = []
    for v in verdicts:
        d, c = v["default"], v["compact"]
        rows.append([v["scene"], v["method"], _seeds(v["n"]), _f(d["num_gaussians"], fmt=",.0f"),
                     _f(c["num_gaussians"], fmt=",.0f"), f"{100 * v['reduction']:.1f}%",
                     "-" if v["mb_reduction"] is None else f"{d['param_bytes']['median'] / 1e6:.1f} -> "
                     f"{c['param_bytes']['median'] / 1e6:.1f} ({100 * v['mb_reduction']:.0f}% less)",
                     f"{_f(d['psnr'])} -> {_f(c['psnr'])}", f"{v['psnr_change']:+.2f}",
                     "met" if v["met"] else f"not met: {v['why']}", v["stamp"], f"`{v['file']}`"])
    done = {v["scene"] for v in verdicts}
    rows += [[scene, "-", "0", "-", "-", "-", "-", "-", "-", "not measured yet (`bench/sweeps/compact.yaml`)", "-", "-"]
             for scene in GOAL_SCENES if scene not in done]
    return _table(["scene", "method", "seeds", "Gaussians", "compact", "fewer", "MB", "test PSNR", "ΔPSNR dB",
                   "goal (50% fewer, <= 0.1 dB lost)", "machine, commit", "source"], rows)


def all_compact_verdicts(sources: list[dict]) -> list[dict]:
    """The verdicts of the sources with compact runs of the newest machine and commit (``newest_code``: a
    collected sweep's, whose defaults may be in another collected source of the same machine and commit, or
    bench/quality/compact.py's), newest per scene."""
    best: dict = {}
    for src in newest_code([s for s in sources if any(r.get("variant") == "compact" for r in s["runs"])]):
        pool = list(src["runs"]) + [r for s in sources if s is not src and s["kind"] == "runs"
                                    and (s["machine"], s.get("commit")) == (src["machine"], src.get("commit"))
                                    for r in s["runs"]]
        for v in compact_verdicts(pool):
            v.update(stamp=stamp(src), file=src["file"])
            rank = (bool(src.get("commit")), v["n"], src["date"])
            if (v["scene"], v["method"]) not in best or rank >= best[(v["scene"], v["method"])][0]:
                best[(v["scene"], v["method"])] = (rank, v)
    return [v for _, v in sorted(best.values(), key=lambda x: (x[1]["scene"], x[1]["method"]))]


# ----------------------------------------------------------------------------------------------
# command line


def build(results: Path = RESULTS, img: Path = IMG) -> tuple[dict, list[Path]]:
    """The tables (``{marker name: markdown}``) and the charts drawn into ``img`` from the results in ``results``."""
    sources = load_sources(results)
    scenes = speed_accuracy_scenes(sources)
    panels = stability_panels(sources)
    verdicts = all_compact_verdicts(sources)
    charts = chart_speed_accuracy(scenes, img) + [p for p in (chart_stability(panels, img), chart_compact(verdicts, img))
                                                  if p is not None]
    tables = {"speed_accuracy": speed_accuracy_table(scenes), "stability": stability_table(panels),
              "compact": compact_table(verdicts)}
    return {k: "\n".join(v) for k, v in tables.items()}, charts


def write_tables(doc_path: Path, tables: dict) -> None:
    doc = doc_path.read_text()
    for name, text in tables.items():
        doc = replace_between_markers(doc, text, *markers(name))
    doc_path.write_text(doc)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--collect", type=Path, default=None, metavar="DIR", help="a batch folder to collect into a results file")
    ap.add_argument("--name", default=None, help="--collect: the results file's name before _<machine>.json "
                    "(default: the folder's name)")
    ap.add_argument("--machine", default=None, help="--collect: the machine the runs ran on (default: the GPU in "
                    "their logs, else this machine's)")
    ap.add_argument("--commit", default=None, help="--collect: the commit they ran at (default: this checkout's)")
    ap.add_argument("--sweep", default=None, help="--collect: the sweep file (default: the batch's record of it)")
    ap.add_argument("--merge", action="store_true", help="--collect: into the results file already there (same "
                    "machine and commit): this folder's runs replace those of their names, unless only the file's "
                    "trained to the end")
    ap.add_argument("--results", type=Path, default=RESULTS, help="the results folder (default bench/results/quality)")
    ap.add_argument("--img", type=Path, default=IMG, help="where the charts go (default docs/img)")
    ap.add_argument("--doc", default=str(DOC), help="the file whose markers get the tables (default "
                    "docs/benchmarks.md); --doc '' prints them")
    a = ap.parse_args(argv)
    if a.collect is not None:
        if not a.collect.is_dir():
            ap.error(f"--collect {a.collect}: not a folder")
        doc = collect(a.collect, a.name or a.collect.name, machine=a.machine, commit=a.commit, sweep=a.sweep)
        path = a.results / f"{a.name or a.collect.name}_{machine_tag(doc['machine'])}.json"
        if a.merge and path.is_file():
            try:
                doc = merge(json.loads(path.read_text()), doc)
            except ValueError as e:
                ap.error(f"{path}: {e}")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(doc, indent=1) + "\n")
        ended = sum(r["status"] == "finished" for r in doc["runs"].values())
        print(f"charts: {ended} of {len(doc['runs'])} runs finished ({doc['machine']}, commit {doc['commit']}); "
              f"wrote {path}")
        return 0
    tables, charts = build(a.results, a.img)
    if a.doc:
        try:
            write_tables(Path(a.doc), tables)
        except ValueError as e:
            ap.error(f"{a.doc}: {e}")
        print(f"charts: wrote {', '.join(str(p) for p in charts)}; tables into {a.doc}")
    else:
        for name, text in tables.items():
            print(f"## {name}\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
