"""Compact-mode benchmark (issue #8, part 3): the default run against ``--compact`` on one scene.

    python bench/quality/compact.py --data synthetic --device cpu --iterations 1000 --out bench/results/quality/compact_synthetic_cpu
    python bench/quality/compact.py --data blender --data-root /data --device cuda --out bench/results/quality/compact_lego_cuda
    python bench/quality/compact.py --data blender --method full --device cuda --out ...       # the full method

Trains the method twice at equal iterations, with its default config and with configs/compact.yaml on top
(warpgs/compact.py), into ``OUT/default`` and ``OUT/compact`` (each a normal run folder with metrics.json,
point_cloud.ply, test renders), then writes

    OUT/compact.json     both runs' test PSNR / SSIM, Gaussians, SH degree, bytes, the search's points
    OUT/compact.png      PSNR against Gaussian count: the points of the search (training-view PSNR, which
                         chooses, and test PSNR, reported only), the chosen model and the default run
    OUT/compact.md       a summary table

``--reuse`` keeps an existing ``OUT/default`` (its metrics.json) instead of training it again;
``--default DIR`` takes the default run's metrics.json from DIR (e.g. another variant's OUT/default).
``run_compact(...)`` is the same as a function, for a suite runner; it returns the JSON's dict.
The acceptance of issue #8: >= 50% fewer Gaussians than the default at <= 0.1 dB test-PSNR loss
(``accepted`` in the JSON, with both figures).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def _args(data, method, device, iterations, views, data_root, scene, overrides, compact: bool, seed) -> list[str]:
    argv = ["--data", data, "--method", method, "--no-progress"]
    for flag, v in (("--device", device), ("--iterations", iterations), ("--views", views),
                    ("--data-root", data_root), ("--scene", scene), ("--seed", seed)):
        if v is not None:
            argv += [flag, str(v)]
    for s in overrides:
        argv += ["--set", s]
    if compact:
        argv.append("--compact")
    return argv


def _train(argv: list[str], out: Path) -> dict:
    from warpgs.pipelines.sparse import RunStopped, build_parser, load_scene_for, make_config, run_method

    args = build_parser().parse_args(argv + ["--out", str(out)])
    cfg, _ = make_config(args)
    scene = load_scene_for(cfg)
    t0 = time.perf_counter()
    try:
        result = run_method(cfg.method, cfg, scene, out, resume=False)
    except RunStopped as e:
        raise RuntimeError(f"training into {out} stopped with exit code {e.code}") from e
    result["wall_s"] = round(time.perf_counter() - t0, 2)
    return result


def _summary(m: dict) -> dict:
    keys = ("psnr", "ssim", "lpips", "train_psnr", "num_gaussians", "sh_degree", "param_bytes", "ply_bytes",
            "train_time_s", "render_fps", "iterations", "wall_s")
    return {k: m.get(k) for k in keys}


def write_chart(path: Path, default: dict, compact: dict) -> Path | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = compact.get("compact") or {}
    pts = rep.get("points", [])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, title in ((axes[0], "train_psnr", "training views (chooses)"),
                           (axes[1], "test_psnr", "test views (reported only)")):
        for kind, marker in (("prune", "o"), ("sh", "s")):
            sel = [p for p in pts if p["kind"] == kind and p.get(key) is not None]
            if sel:
                ax.scatter([p["num_gaussians"] for p in sel], [p[key] for p in sel], marker=marker,
                           c=["tab:green" if p.get("within_tolerance") else "tab:red" for p in sel],
                           label=f"search: {'prune ratio' if kind == 'prune' else 'SH degree'} (green: within tolerance)")
                for p in sel:
                    ax.annotate(f"{p['ratio']:.1f}" if kind == "prune" else f"d{p['sh_degree']}",
                                (p["num_gaussians"], p[key]), textcoords="offset points",
                                xytext=(4, 4) if kind == "prune" else (4, -10), fontsize=7)
        if "chosen" in rep and pts and pts[rep["chosen"]].get(key) is not None:
            c = pts[rep["chosen"]]
            ax.scatter([c["num_gaussians"]], [c[key]], s=160, facecolors="none", edgecolors="k", label="kept")
        dkey = "train_psnr" if key == "train_psnr" else "psnr"
        if default.get(dkey) is not None:
            ax.scatter([default["num_gaussians"]], [default[dkey]], marker="*", s=140, c="tab:blue",
                       label="default run")
        if key == "train_psnr" and rep.get("best_train_psnr") is not None:
            ax.axhline(rep["best_train_psnr"] - rep["tolerance_db"], ls="--", c="grey", lw=0.8,
                       label=f"best - {rep['tolerance_db']} dB")
        ax.set_xlabel("Gaussians")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"compact mode: {default.get('scene')} ({default.get('method')}, {default.get('iterations')} it)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def write_markdown(path: Path, result: dict) -> Path:
    d, c = result["default"], result["compact"]

    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    rows = [("test PSNR", "psnr", ".3f"), ("test SSIM", "ssim", ".4f"), ("train PSNR", "train_psnr", ".3f"),
            ("Gaussians", "num_gaussians", "d"), ("SH degree", "sh_degree", "d"),
            ("parameter bytes (float32)", "param_bytes", "d"), ("PLY bytes", "ply_bytes", "d"),
            ("training time (s)", "train_time_s", ".1f"), ("render FPS", "render_fps", ".1f")]
    lines = [f"# Compact mode: {result['scene']} ({result['method']}, {result['iterations']} iterations, {result['device']})",
             "", "| | default | compact |", "|---|---|---|"]
    lines += [f"| {label} | {f(d.get(k), fmt)} | {f(c.get(k), fmt)} |" for label, k, fmt in rows]
    lines += ["", f"- Gaussians: {result['count_reduction'] * 100:.1f}% fewer than the default; bytes "
                  f"{result['bytes_reduction'] * 100:.1f}% fewer",
              f"- test PSNR change: {result['psnr_change']:+.3f} dB (acceptance: >= 50% fewer at <= 0.1 dB loss: "
              f"{'met' if result['accepted'] else 'not met'})",
              "- the search is judged on the training views only; test PSNR of its points is reported, never used",
              "", "Points of the search (after each point's fine-tune):", "",
              "| kind | prune ratio | SH degree | Gaussians | train PSNR | test PSNR | within tolerance |",
              "|---|---|---|---|---|---|---|"]
    for i, p in enumerate(result["points"]):
        mark = " (kept)" if i == result.get("chosen") else ""
        lines.append(f"| {p['kind']}{mark} | {p['ratio']:.2f} | {p['sh_degree']} | {p['num_gaussians']} | "
                     f"{p['train_psnr']:.3f} | {f(p.get('test_psnr'), '.3f')} | {p.get('within_tolerance')} |")
    if result.get("pruned_during_training"):
        lines += ["", "Pruned during training: " + ", ".join(f"step {r['step']}: {r['before']} -> {r['after']}"
                                                            for r in result["pruned_during_training"])]
    lines += ["", "![PSNR against Gaussian count](compact.png)", ""]
    path.write_text("\n".join(lines))
    return path


def run_compact(data: str = "synthetic", device: str | None = None, iterations: int | None = None,
                out: str | Path = "bench/results/quality/compact", *, method: str = "baseline", views=None,
                data_root: str | None = None, scene: str | None = None, overrides=(), compact_overrides=(),
                seed: int | None = None, reuse: bool = False, default_dir: str | Path | None = None) -> dict:
    """Trains the default and the compact run of ``method`` on ``data`` into ``out`` and writes
    compact.json / compact.png / compact.md there. ``overrides``: ``--set`` strings for both runs;
    ``compact_overrides``: only for the compact run (e.g. ``compact.finetune_steps=100``)."""
    out = Path(out)
    common = dict(data=data, method=method, device=device, iterations=iterations, views=views,
                  data_root=data_root, scene=scene, seed=seed)
    dmetrics = Path(default_dir) / "metrics.json" if default_dir is not None else out / "default" / "metrics.json"
    if default_dir is not None and not dmetrics.is_file():
        raise FileNotFoundError(f"{dmetrics}: no default run to compare with")
    if (reuse or default_dir is not None) and dmetrics.is_file():
        default = json.loads(dmetrics.read_text())
        print(f"bench/compact: reusing {dmetrics}", file=sys.stderr)
    else:
        default = _train(_args(**common, overrides=list(overrides), compact=False), out / "default")
    compact = _train(_args(**common, overrides=list(overrides) + list(compact_overrides), compact=True),
                     out / "compact")
    rep = compact.get("compact") or {}
    d_n, c_n = default["num_gaussians"], compact["num_gaussians"]
    d_b = default.get("param_bytes")
    psnr_change = compact["psnr"] - default["psnr"]
    count_reduction = 1.0 - c_n / max(d_n, 1)
    result = {
        "scene": default["scene"],
        "views": default.get("train_views"),
        "seed": default.get("seed", 0),  # the chart's run names carry it (bench/report/charts.py)
        "method": method,
        "iterations": default["iterations"],
        "device": compact["device"],
        "host": platform.node(),
        "default": _summary(default),
        "compact": _summary(compact),
        "count_reduction": count_reduction,
        "bytes_reduction": 1.0 - compact["param_bytes"] / d_b if d_b else None,
        "psnr_change": psnr_change,
        "accepted": bool(count_reduction >= 0.5 and psnr_change >= -0.1),
        "tolerance_db": rep.get("tolerance_db"),
        "best_train_psnr": rep.get("best_train_psnr"),
        "chosen": rep.get("chosen"),
        "points": rep.get("points", []),
        "search_before": rep.get("before"),
        "pruned_during_training": rep.get("pruned_during_training", []),
        "search_time_s": rep.get("search_time_s"),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "compact.json").write_text(json.dumps(result, indent=2))
    write_chart(out / "compact.png", default, compact)
    write_markdown(out / "compact.md", result)
    print(f"\n{result['scene']}: default {d_n} Gaussians, test PSNR {default['psnr']:.3f}; compact {c_n} Gaussians "
          f"(SH degree {compact.get('sh_degree')}), test PSNR {compact['psnr']:.3f} ({psnr_change:+.3f} dB), "
          f"{count_reduction * 100:.1f}% fewer; acceptance {'met' if result['accepted'] else 'not met'}\n"
          f"wrote {out / 'compact.json'}, {out / 'compact.png'}, {out / 'compact.md'}")
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="synthetic")
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--scene", default=None)
    ap.add_argument("--views", default=None)
    ap.add_argument("--method", default="baseline", choices=("baseline", "full"))
    ap.add_argument("--device", default=None)
    ap.add_argument("--iterations", type=int, default=None)
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for both runs")
    ap.add_argument("--compact-set", action="append", default=[], metavar="KEY=VALUE",
                    help="override for the compact run only, e.g. compact.finetune_steps=100")
    ap.add_argument("--out", default=None)
    ap.add_argument("--reuse", action="store_true", help="reuse OUT/default/metrics.json when it exists")
    ap.add_argument("--default", default=None, metavar="DIR", help="the default run's folder to compare with "
                    "(its metrics.json) instead of training it")
    a = ap.parse_args(argv)
    out = a.out or f"bench/results/quality/compact_{a.data.replace('/', '_')}_{a.device or 'auto'}"
    run_compact(a.data, a.device, a.iterations, out, method=a.method, views=a.views, data_root=a.data_root,
                scene=a.scene, overrides=a.set, compact_overrides=a.compact_set, seed=a.seed, reuse=a.reuse,
                default_dir=a.default)
    return 0


if __name__ == "__main__":
    sys.exit(main())
