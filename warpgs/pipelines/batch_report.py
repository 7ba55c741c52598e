"""The batch runner's results (``warpgs.pipelines.batch``): one table over seeds, every run with its stage times
and attempts, and the charts.

    write_results(records, info, out)   # -> results.json, results.md, psnr_vs_time.png, psnr_vs_gaussians.png

Per (scene, views, method): the number of seeds that finished, the median and [min, max] of test PSNR, SSIM
and LPIPS over them, and the medians of Gaussians, training time and the run's wall time. GPU-hours are each
run's wall time (all its attempts in this batch) x the GPU share it held; runs reused from an earlier batch
cost nothing here.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

STAGES = ("init_sfm_s", "init_stereo_s", "far_field_s", "train_s", "path_floaters_s", "pseudo_views_s", "densify_s")


def spread(values: list) -> dict | None:
    """Median, min, max and count of the values that are numbers; None when there is none."""
    xs = [v for v in values if isinstance(v, (int, float))]
    if not xs:
        return None
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs), "n": len(xs)}


def group_key(rec: dict) -> tuple:
    s = rec["spec"]
    return s["scene"], str(s["views"]), s["method"]


def summarize(records: list[dict]) -> list[dict]:
    """One row per (scene, views, method), in the order the runs came."""
    groups: dict[tuple, list[dict]] = {}
    for r in records:
        groups.setdefault(group_key(r), []).append(r)
    rows = []
    for (scene, views, method), recs in groups.items():
        done = [r["metrics"] for r in recs if r.get("status") == "finished"]
        row = {"scene": scene, "views": views, "method": method, "runs": len(recs), "finished": len(done),
               "seeds": [r["spec"]["seed"] for r in recs if r.get("status") == "finished"]}
        for key in ("psnr", "ssim", "lpips", "num_gaussians", "train_time_s"):
            row[key] = spread([m.get(key) for m in done])
        row["wall_s"] = spread([r.get("wall_s") for r in recs if r.get("status") == "finished"])
        rows.append(row)
    return rows


def gpu_hours(records: list[dict]) -> float:
    return sum((r.get("wall_s") or 0) * (r["spec"].get("num_gpus") or 0) for r in records) / 3600


def _f(v, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def med_range(s: dict | None, fmt: str) -> str:
    """A ``spread``'s "median [min, max]" (the median alone for one value; "n/a" for None)."""
    if s is None:
        return "n/a"
    if s["n"] == 1:
        return _f(s["median"], fmt)
    return f"{_f(s['median'], fmt)} [{_f(s['min'], fmt)}, {_f(s['max'], fmt)}]"


def markdown(records: list[dict], info: dict) -> str:
    rows = summarize(records)
    finished = sum(r.get("status") == "finished" for r in records)
    reused = sum(bool(r.get("reused")) for r in records)
    lines = ["# warpgs batch", "", f"`{info.get('command', '')}`", "",
             f"{info.get('date', '')}, {info.get('device', '')} on {info.get('nodes', '?')} node(s) "
             f"({', '.join(f'{v:g} {k}' for k, v in (info.get('cluster') or {}).items())}): {finished} of {len(records)} "
             f"runs finished ({reused} reused from an earlier batch); wall time {_f(info.get('wall_s'), '.0f')} s, "
             f"{gpu_hours(records):.2f} GPU-hours (run wall time x GPU share).", "",
             "![PSNR against training time](psnr_vs_time.png)", "", "![PSNR against Gaussians](psnr_vs_gaussians.png)",
             "", "## Over seeds: median [min, max]", "",
             "| scene | views | method | seeds | PSNR | SSIM | LPIPS | Gaussians | training s | run wall s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for g in rows:
        lines.append(f"| {g['scene']} | {g['views']} | {g['method']} | {g['finished']}/{g['runs']} | "
                     f"{med_range(g['psnr'], '.2f')} | {med_range(g['ssim'], '.3f')} | {med_range(g['lpips'], '.3f')} | "
                     f"{_f((g['num_gaussians'] or {}).get('median'), '.0f')} | "
                     f"{_f((g['train_time_s'] or {}).get('median'), '.1f')} | {_f((g['wall_s'] or {}).get('median'), '.1f')} |")
    lines += ["", "## Runs: stage times (s)", "",
              "| run | status | attempts | PSNR | Gaussians | " + " | ".join(STAGES) + " | wall |",
              "|---|---|---|---|---|" + "---|" * len(STAGES) + "---|"]
    for r in records:
        m = r.get("metrics") or {}
        st = m.get("stage_times_s") or {}
        status = "reused" if r.get("reused") else r.get("status", "?")
        lines.append(f"| {r['name']} | {status} | {len(r.get('attempts') or [])} | {_f(m.get('psnr'), '.2f')} | "
                     f"{_f(m.get('num_gaussians'), 'd')} | " + " | ".join(_f(st.get(k), '.1f') for k in STAGES)
                     + f" | {_f(r.get('wall_s'), '.1f')} |")
    failed = [r for r in records if r.get("status") != "finished"]
    if failed:
        lines += ["", "## Runs that did not finish", ""]
        lines += [f"- `{r['name']}` ({r.get('status')}): {r.get('error', '')}" for r in failed]
    retried = [r for r in records if r.get("retries")]
    if retried:
        lines += ["", "## Retries", ""]
        lines += [f"- `{r['name']}`: " + "; ".join(r["retries"]) for r in retried]
    return "\n".join(lines) + "\n"


def plot(records: list[dict], out: Path) -> list[Path]:
    """PSNR against training time and against Gaussians, one panel per scene, one colour per method and
    views; a small dot per seed, a large one at the medians."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = [r for r in records if r.get("status") == "finished" and r["metrics"].get("psnr") is not None]
    scenes = list(dict.fromkeys(r["spec"]["scene"] for r in done))
    if not scenes:
        return []
    series = list(dict.fromkeys((r["spec"]["method"], str(r["spec"]["views"])) for r in done))
    paths = []
    for kind, xkey, xlabel in (("time", "train_time_s", "training time (s)"),
                               ("gaussians", "num_gaussians", "Gaussians (final count)")):
        fig, axes = plt.subplots(1, len(scenes), figsize=(5.2 * len(scenes), 4.2), squeeze=False)
        for ax, scene in zip(axes[0], scenes):
            for i, (method, views) in enumerate(series):
                pts = [(r["metrics"][xkey], r["metrics"]["psnr"]) for r in done
                       if r["spec"]["scene"] == scene and (r["spec"]["method"], str(r["spec"]["views"])) == (method, views)]
                if not pts:
                    continue
                xs, ys = zip(*pts)
                color = f"C{i % 10}"
                ax.plot(xs, ys, "o", color=color, ms=4, alpha=0.6)
                ax.plot([statistics.median(xs)], [statistics.median(ys)], "o", color=color, ms=9,
                        label=f"{method}, {views} views" if views != "None" else method)
            ax.set_title(scene, fontsize=10)
            ax.set_xlabel(xlabel)
            ax.set_ylabel("test PSNR (dB)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        fig.suptitle(f"PSNR against {'training time' if kind == 'time' else 'model size'} (large: median over seeds)",
                     fontsize=10)
        paths.append(_save(fig, out / f"psnr_vs_{kind}.png"))
    return paths


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def write_results(records: list[dict], info: dict, out: Path) -> list[Path]:
    """results.json (info, the table over seeds, every run), results.md and the charts in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    data = {"info": {**info, "gpu_hours": round(gpu_hours(records), 4)}, "groups": summarize(records), "runs": records}
    paths = [out / "results.json", out / "results.md"]
    paths[0].write_text(json.dumps(data, indent=1))
    paths[1].write_text(markdown(records, info))
    return paths + plot(records, out)
