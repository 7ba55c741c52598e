"""Main job: sparse-view 3D Gaussian Splatting, ``python -m warpgs.pipelines.sparse``.

With no arguments it runs the embedded synthetic scene (3 views at 128x96) with the plain 3D-GS
baseline and with the full generation-guided method, at equal iterations, and prints them side by side
(a few minutes on a 2-core CPU). Methods: ``baseline`` (3D-GS on the inputs), ``full`` (the paper's
loop: pseudo views, densification from them, training on both), ``compare`` (both; the default).
Examples:

    python -m warpgs.pipelines.sparse                                   # synthetic, 3 views, compare
    python -m warpgs.pipelines.sparse --data dl3dv --views 9 --method full --device cuda
    python -m warpgs.pipelines.sparse --data llff --method compare --cycles 2
    python -m warpgs.pipelines.sparse --method full --ablation no_densify --ablation l1_pseudo
    python -m warpgs.pipelines.sparse --data dl3dv --method full --svd-path /path/to/svd   # Stable Video Diffusion
    python -m warpgs.pipelines.sparse --data llff --views 3 --device cuda
    python -m warpgs.pipelines.sparse --data blender --iterations 10000 --out outputs/lego
    python -m warpgs.pipelines.sparse --data /path/to/scene --set strategy.max_gaussians=200000
    python -m warpgs.pipelines.sparse --resume outputs/lego             # continue an interrupted run
    python -m warpgs.pipelines.sparse --method baseline --data blender --compact   # fewest Gaussians

Config layers (later wins): configs/methods/<method>.yaml, configs/datasets/<dataset>.yaml, --config files, --set
key=value, explicit flags. With --resume the checkpoint's config replaces the first two. Every layer is
checked on its own (keys, types, ranges), so a bad value is named with the file, --set or flag it came from.

The output folder gets config.yaml, checkpoint.pt (every train.checkpoint_every steps and on Ctrl-C; the
one it replaced stays as checkpoint.prev.pt, which --resume falls back to when checkpoint.pt cannot be
read), metrics.json, test/NNN_<view>.png (render | ground truth) and point_cloud.ply (3D-GS layout). A run
locks its folder (.warpgs.lock; warpgs/runfolder.py): a second run into it stops, and a folder holding an
earlier run needs --resume or --overwrite. Bad input of any kind ends in one line, ``error: ...``, exit 2; a device
that runs out of memory ends with exit 1 (not the input's fault: again may succeed), in one line or paragraph.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path

from warpgs import losses
from warpgs.config import CONFIG_DIR, ConfigError, build_config, parse_override, read_yaml, save_config
from warpgs.console import warn_once
from warpgs.methods.full import ABLATIONS

METHODS = ("baseline", "full", "corgs", "compare")


def build_parser() -> argparse.ArgumentParser:
    from warpgs.data.registry import add_data_args

    ap = argparse.ArgumentParser(prog="python -m warpgs.pipelines.sparse", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data_args(ap)
    ap.set_defaults(data=None)  # None: the config's data.name (synthetic by default)
    g = ap.add_argument_group("run")
    g.add_argument("--method", default=None, help=f"training method: {', '.join(METHODS)} (default: compare)")
    g.add_argument("--cycles", type=int, default=None, help="pseudo-view cycles of the full method")
    g.add_argument("--ablation", action="append", default=[], metavar="NAME",
                   help="switch of the paper's Table 4 (repeatable): " + ", ".join(ABLATIONS))
    g.add_argument("--compact", action="store_true",
                   help="compact mode: the fewest Gaussians and lowest SH degree within 0.1 dB of the best "
                        "training-view PSNR (configs/presets/compact.yaml, warpgs/strategy/compact.py)")
    g.add_argument("--config", action="append", default=[], metavar="FILE", help="extra YAML config (repeatable)")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value, e.g. --set strategy.max_gaussians=20000 (repeatable)")
    g.add_argument("--device", default=None, help="cpu, cuda or cuda:N (default: cuda if available)")
    g.add_argument("--iterations", type=int, default=None, help="training steps")
    g.add_argument("--seed", type=int, default=None)
    g.add_argument("--out", default=None, help="output folder (default: outputs/<method>/<scene>_<views>v)")
    g.add_argument("--resume", nargs="?", const="", default=None, metavar="DIR",
                   help="continue from DIR/checkpoint.pt (DIR defaults to --out; an unreadable checkpoint falls "
                        "back to DIR/checkpoint.prev.pt)")
    g.add_argument("--overwrite", action="store_true",
                   help="--out holds an earlier run: delete its outputs and start over (without it, such a folder "
                        "needs --resume)")
    g.add_argument("--drop-invalid", action="store_true",
                   help="model.init=ply: drop points with non-finite values (one warning) instead of refusing the file")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    from warpgs.pseudo.views import add_backend_args

    add_backend_args(ap.add_argument_group("pseudo views (the full method)"))
    g.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="compare: 2 trains baseline and full method at once (default on a multi-core CPU), 1 in turn")
    return ap


def dataset_overlay(data: str) -> Path | None:
    """configs/datasets/<dataset>.yaml for a dataset name or a folder of a known format."""
    name = data
    if not (CONFIG_DIR / "datasets" / f"{name}.yaml").is_file() or "/" in data:
        try:
            from warpgs.data.registry import detect_format

            name, _ = detect_format(data)
        except Exception:
            return None
    p = CONFIG_DIR / "datasets" / f"{name}.yaml"
    return p if p.is_file() else None


def flag_layers(args) -> list[tuple[str, dict]]:
    """The explicit flags as config layers, each named after its flag (a value out of range is reported
    as coming from that flag)."""
    layers: list[tuple[str, dict]] = []
    for flag, section, key, value in (("--data", "data", "name", args.data), ("--scene", "data", "scene", args.scene),
                                      ("--views", "data", "views", args.views),
                                      ("--downscale", "data", "downscale", args.downscale),
                                      ("--data-root", "data", "root", args.data_root),
                                      ("--iterations", "train", "iterations", args.iterations),
                                      ("--device", "train", "device", args.device), ("--seed", "train", "seed", args.seed),
                                      ("--cycles", "full", "cycles", args.cycles)):
        if value is None:
            continue
        if key == "views" and value != "all":
            try:
                value = int(value)
            except ValueError:
                raise ConfigError(f"--views {value!r}: expected a number or 'all'") from None
        layers.append((f"{flag} {value}", {section: {key: value}}))
    if args.no_progress:
        layers.append(("--no-progress", {"train": {"progress": False}}))
    if getattr(args, "drop_invalid", False):
        layers.append(("--drop-invalid", {"model": {"drop_invalid": True}}))
    for name in args.ablation:
        if name not in ABLATIONS:
            raise ConfigError(f"--ablation {name!r}: available ablations are {', '.join(ABLATIONS)}")
        layers.append((f"--ablation {name}", ABLATIONS[name]))
    if getattr(args, "pseudo_backend", None):
        layers.append((f"--pseudo-backend {args.pseudo_backend}", {"pseudo": {"backend": args.pseudo_backend}}))
    if getattr(args, "svd_path", None):
        layers.append((f"--svd-path {args.svd_path}", {"pseudo": {"svd": {"path": args.svd_path}}}))
    if args.out is not None:
        layers.append(("--out", {"out": args.out}))
    return layers


def make_config(args):
    """-> (config, resume folder or None). Every layer is checked on its own (``build_config``): a value out
    of range is an error naming the file, ``--set`` or flag it came from, even where a later layer sets the
    key again."""
    from warpgs.engine.checkpoint import resumable_checkpoint

    resume_dir = None
    if args.resume is not None:
        if getattr(args, "overwrite", False):
            raise ConfigError("--resume continues the run in a folder and --overwrite replaces it: give one of them")
        resume_dir = Path(args.resume or args.out or "")
        if not str(resume_dir) or str(resume_dir) == ".":
            raise ConfigError("--resume needs a folder: --resume DIR (or --out DIR)")
        found = resumable_checkpoint(resume_dir)  # checkpoint.pt, else checkpoint.prev.pt (with a note)
        if found is not None:
            base = [(str(found[0]), found[1]["config"]), ("--resume", {"out": str(resume_dir)})]
        elif (resume_dir / "config.yaml").is_file():  # a compare run: each method has its own checkpoint
            base = [(str(resume_dir / "config.yaml"), read_yaml(resume_dir / "config.yaml")),
                    ("--resume", {"out": str(resume_dir)})]
        else:
            raise ConfigError(f"--resume: {resume_dir / 'checkpoint.pt'} does not exist; nothing to resume")
    else:
        method = args.method or "compare"
        if method not in METHODS:
            raise ConfigError(f"--method {method!r}: available methods are {', '.join(METHODS)}")
        # only the method's file; a compare run reads full.yaml (whose base is baseline.yaml): it runs both
        own = CONFIG_DIR / "methods" / f"{'full' if method == 'compare' else method}.yaml"
        base = [(str(own), read_yaml(own)), (f"--method {method}", {"method": method})]
        overlay = dataset_overlay(args.data or "synthetic")
        if overlay is not None:
            base.append((str(overlay), read_yaml(overlay)))
    if getattr(args, "compact", False):
        base.append(("--compact", read_yaml(CONFIG_DIR / "presets" / "compact.yaml")))
    layers = (base + [(str(f), read_yaml(f)) for f in args.config] + [(f"--set {s}", parse_override(s)) for s in args.set]
              + flag_layers(args))
    return build_config(layers), resume_dir


def load_scene_for(cfg):
    from warpgs.data import load_scene

    d = cfg.data
    device = "cpu" if cfg.train.device == "cpu" else None
    return load_scene(d.name, scene=d.scene, views=d.views, downscale=d.downscale, root=d.root, device=device,
                      **d.options)


def print_metrics(m: dict, out: Path) -> None:
    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    masked = " (masked)" if m["masked"] else ""
    print(f"\n{m['method']} on {m['scene']}: {m['train_views']} train / {m['test_views']} test views at "
          f"{m['resolution'][0]}x{m['resolution'][1]}, {m['iterations']} iterations on {m['device']}")
    print(f"  test{masked}: PSNR {f(m['psnr'], '.2f')}  SSIM {f(m['ssim'], '.3f')}  LPIPS {f(m['lpips'], '.3f')}"
          f"   (initial PSNR {f(m['initial_psnr'], '.2f')}, train PSNR {f(m['train_psnr'], '.2f')})")
    if m.get("lpips_missing"):  # one line, once per process (a compare run has two runs, the full method said it)
        warn_once(f"warpgs: LPIPS not computed: {losses.one_line(m['lpips_missing'])}", key="lpips-missing")
    mem = m.get("peak_cuda_allocated_mb", m.get("peak_rss_mb"))
    print(f"  {m['num_gaussians']} Gaussians, training {m['train_time_s']:.1f} s, {m['render_fps']:.1f} FPS, "
          f"peak memory {mem:.0f} MB")
    c = m.get("compact")
    if c and c.get("after"):
        b, k = c["before"], c["after"]
        print(f"  compact: {k['num_gaussians']} of {b['num_gaussians']} Gaussians kept at SH degree {k['sh_degree']}, "
              f"{k['param_bytes'] / 2**20:.2f} MiB of parameters (was {b['param_bytes'] / 2**20:.2f}), PLY "
              f"{k['ply_bytes'] / 2**20:.2f} MiB; train PSNR {k['train_psnr']:.2f} (best {c['best_train_psnr']:.2f}, "
              f"tolerance {c['tolerance_db']} dB)")
    print(f"  wrote {out / 'metrics.json'}, {out / 'point_cloud.ply'}, {out / 'test'}/")


def training_methods() -> dict:
    """The training methods by name: each a ``warpgs.engine.method.Method`` class (``warpgs.methods``)."""
    from warpgs.methods import METHODS, method_class

    return {name: method_class(name) for name in METHODS}


def make_trainer(cfg, scene, out: Path | None = None, **kwargs):
    """The trainer of ``cfg.method`` with the stages its config asks for (compact mode)."""
    from warpgs.strategy.compact import attach
    from warpgs.engine.loop import Trainer

    methods = training_methods()
    if cfg.method not in methods:
        raise ValueError(f"method={cfg.method!r}: the training methods are {', '.join(methods)}")
    trainer = Trainer(cfg, scene, out, method=methods[cfg.method](), **kwargs)
    attach(trainer)
    return trainer


class RunStopped(Exception):
    """A run that ends without metrics (bad settings, Ctrl-C, SIGTERM): ``code`` is the process's exit code (2,
    130, 143); what to tell the user has been printed already."""

    def __init__(self, code: int):
        super().__init__(code)
        self.code = code


def run_method(method: str, cfg, scene, out: Path, resume: bool, baseline_metrics: dict | None = None,
               resume_hint: str | None = None, clock=None) -> dict:
    """Trains one method into ``out``; returns its metrics (``stopped_early`` set when it diverged or the device
    ran out of memory, and the last good state's were written). Raises ``RunStopped`` when it ends without them: bad settings, Ctrl-C,
    a checkpoint that cannot be read or written, outputs that cannot be written (each said in one line)."""
    from warpgs.engine.checkpoint import (CHECKPOINT, PREVIOUS_CHECKPOINT, CheckpointError, TrainingDiverged,
                                          TrainingInterrupted)
    from warpgs.engine.signals import exit_code, interrupt_code, is_out_of_memory

    from warpgs.engine.evaluation import write_metrics
    from warpgs.wallclock import WallClock

    cfg = copy.deepcopy(cfg)
    cfg.method = method
    resume_hint = resume_hint or f"--resume {out}"
    clock = clock or WallClock(with_startup=False)
    try:
        with clock("setup"):
            trainer = make_trainer(cfg, scene, out)
    except (RuntimeError, ValueError) as e:
        if is_out_of_memory(e):  # not bad input: the device was full (other runs on it); again may succeed
            first = (str(e).strip().splitlines() or [""])[0]
            print(f"error: the device ran out of memory while setting up the {method} run ({first}); free the "
                  f"device (other processes on it), then run again", file=sys.stderr)
            raise RunStopped(1) from e
        print(f"error: {e}", file=sys.stderr)
        raise RunStopped(2) from e
    has_checkpoint = (out / CHECKPOINT).is_file() or (out / PREVIOUS_CHECKPOINT).is_file()
    try:
        if resume and has_checkpoint:
            used = trainer.load_checkpoint()  # checkpoint.pt, or the previous one when it cannot be read
            print(f"warpgs: resumed {used} at step {trainer.step} of {cfg.train.iterations}", file=sys.stderr)
        elif has_checkpoint:
            print(f"warpgs: {out} holds an earlier run; starting over (use --resume to continue it)", file=sys.stderr)
        out.mkdir(parents=True, exist_ok=True)
        save_config(cfg, out / "config.yaml")
        with clock("train"):
            trainer.run()
    except TrainingInterrupted as e:
        try:  # the model as it stands, viewable now; metrics.json stays for the finished run (it marks one)
            ply = f"; the model so far {trainer.export_ply()}"
        except OSError:
            ply = ""
        print(f"\nwarpgs: stopped at step {e.step}; checkpoint {e.checkpoint}{ply}. Continue with:\n"
              f"  python -m warpgs.pipelines.sparse {resume_hint}", file=sys.stderr)
        raise RunStopped(exit_code(e.signum)) from e  # 130 after Ctrl-C, 143 after SIGTERM
    except KeyboardInterrupt as e:
        print(f"\nwarpgs: stopped; the last checkpoint in {out} is intact ({resume_hint})", file=sys.stderr)
        raise RunStopped(interrupt_code(e)) from e
    except TrainingDiverged as e:
        # the model is at its last good state: its metrics, renders and PLY are written all the same
        print("\n" + diverged_message(method, e, out), file=sys.stderr)
        trainer.stopped_early = {"reason": "diverged", "step": e.step, "cause": e.cause}
    except CheckpointError as e:
        full = "space" in str(e).lower()  # ENOSPC, EDQUOT
        print(f"error: {e}" + ("" if "cannot write" not in str(e) else
                               f"; {'free space, then ' if full else ''}continue with {resume_hint}"), file=sys.stderr)
        raise RunStopped(2) from e
    except OSError as e:
        print(f"error: {out}: cannot write {e.filename or 'the run folder'}: {e.strerror or e}", file=sys.stderr)
        raise RunStopped(2) from e
    except RuntimeError as e:  # after CheckpointError, a RuntimeError too
        if not is_out_of_memory(e):  # torch.OutOfMemoryError, or CUDA's, cuBLAS's or Warp's allocation failure
            raise
        # the metrics, renders and PLY of the last good state are written all the same (issue 13: whatever happens)
        step = trainer.step
        back = trainer.after_out_of_memory()
        print("\n" + memory_message(method, step, back, trainer.device, out, resume_hint), file=sys.stderr)
        if back is None:
            raise RunStopped(1) from e  # not bad input: again, on a freer device, may succeed
        trainer.stopped_early = {"reason": "out_of_memory", "step": step, "restored_step": back}
    try:
        with clock("finish"):
            metrics = trainer.finish(baseline_metrics)
        if trainer.out is not None:  # where the whole command's time went (training's own split is in cycles)
            metrics["wall_s"] = clock.as_dict()
            write_metrics(trainer.out, metrics)
    except (CheckpointError, OSError) as e:
        what = str(e) if isinstance(e, CheckpointError) else f"cannot write {e.filename or out}: {e.strerror or e}"
        fix = "free space, then " if "space" in what.lower() else ""
        print(f"error: {what}; the outputs in {out} are incomplete ({fix}run again with {resume_hint})", file=sys.stderr)
        raise RunStopped(2) from e
    except RuntimeError as e:
        if not is_out_of_memory(e):
            raise
        print(f"error: {trainer.device} ran out of memory while evaluating; the outputs in {out} are incomplete "
              f"(free the device, then run again with {resume_hint})", file=sys.stderr)
        raise RunStopped(1) from e
    except KeyboardInterrupt as e:  # Ctrl-C, or a batch's time limit, during the final evaluation and writing
        print(f"\nwarpgs: stopped while writing the results; training is complete and checkpointed in {out}. "
              f"Write them with:\n  python -m warpgs.pipelines.sparse {resume_hint}", file=sys.stderr)
        raise RunStopped(interrupt_code(e)) from e
    print_metrics(metrics, out)
    return metrics


def _paragraph(text: str) -> str:
    """``text`` wrapped at 100 columns without breaking paths or hyphenated words: a stop's one paragraph."""
    import textwrap

    return textwrap.fill(text, width=100, break_long_words=False, break_on_hyphens=False)


def memory_message(method: str, step: int, back: int | None, device, out: Path, resume_hint: str) -> str:
    """One paragraph (no traceback) for a run whose device ran out of memory at ``step``."""
    what = (f"its outputs in {out} (metrics.json with 'stopped_early', renders, point_cloud.ply) are those of the "
            f"last good state, step {back}" if back is not None else
            "no good state was kept in memory yet, so it writes no results")
    return _paragraph(f"warpgs: the {method} run stopped early: {device} ran out of memory at step {step}; {what}. "
                      "Free the device (other processes on it), lower the image size (--downscale) or cap the "
                      f"model (strategy.max_gaussians), then continue with {resume_hint} from the last checkpoint.")


def diverged_message(method: str, e, out: Path) -> str:
    """One paragraph (no traceback) for a run that stopped because training diverged (``TrainingDiverged``)."""
    return _paragraph(f"warpgs: the {method} run stopped early: {e} Its outputs in {out} (metrics.json with "
                      "'stopped_early', renders, point_cloud.ply) are those of the last good state.")


def print_side_by_side(base: dict, full: dict, out: Path) -> None:
    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    rows = [("test PSNR", "psnr", ".2f"), ("test SSIM", "ssim", ".3f"), ("test LPIPS", "lpips", ".3f"),
            ("Gaussians", "num_gaussians", "d"), ("training time (s)", "train_time_s", ".1f"),
            ("render FPS", "render_fps", ".1f")]
    print(f"\n{base['scene']}: {base['train_views']} views, {base['iterations']} iterations each")
    print(f"  {'':<20}{'baseline':>12}{'full':>12}{'gain':>10}")
    for label, key, fmt in rows:
        b, g = base.get(key), full.get(key)
        gain = f(g - b, "+.2f" if fmt != "d" else "+d") if b is not None and g is not None else ""
        print(f"  {label:<20}{f(b, fmt):>12}{f(g, fmt):>12}{gain:>10}")
    if full.get("pseudo_loss") == "l1" and full.get("full", {}).get("pseudo_loss") == "lpips":
        print("  (pseudo views trained with L1: no LPIPS weights here; see metrics.json)")
    table = {"baseline": {k: base.get(k) for _, k, _ in rows}, "full": {k: full.get(k) for _, k, _ in rows},
             "psnr_gain": (full["psnr"] - base["psnr"]) if full.get("psnr") is not None and base.get("psnr") is not None
             else None, "scene": base["scene"], "iterations": base["iterations"]}
    (out / "comparison.json").write_text(json.dumps(table, indent=2))
    print(f"  wrote {out / 'comparison.json'}, {out / 'full' / 'report.md'}")


DEFAULT_OUT = "outputs/sparse"  # Config.out: replaced by outputs/<method>/<scene>_<views>v


def main(argv=None) -> int:
    """The command line. Bad input of any kind (config, scene, output folder, checkpoint) ends with one line,
    ``error: ...``, and exit code 2, before any training; Ctrl-C with 130, SIGTERM with 143."""
    from warpgs.data.scene import SceneError
    from warpgs.engine.checkpoint import CheckpointError
    from warpgs.engine.init import prepare_geometry, resolve_device
    from warpgs.engine.signals import sigterm_as_interrupt
    from warpgs.pseudo.backends import SVDWeightsNotFound
    from warpgs.runfolder import RunFolderError, open_run_folder
    from warpgs.wallclock import WallClock

    args = build_parser().parse_args(argv)
    restore_sigterm = sigterm_as_interrupt()  # SIGTERM ends a run as Ctrl-C does (exit code 143)
    started = time.perf_counter()
    clock = WallClock()  # metrics.json's wall_s: the command's stages
    folder = None
    try:
        try:
            cfg, resume_dir = make_config(args)
            resume = resume_dir is not None
            resolve_device(cfg.train.device)  # a device that cannot run stops here, before any work
            if cfg.method != "baseline":  # the video model's weights, before the run folder is made (said below)
                from warpgs.pseudo.backends import choose_backend
                from warpgs.pseudo.views import resolve_backend

                choose_backend(cfg.pseudo.backend, cfg.pseudo.svd.path)
            chosen = args.out is not None or resume or cfg.out != DEFAULT_OUT
            if chosen:  # the folder is checked and locked before the scene loads
                folder = open_run_folder(cfg.out, resume=resume, overwrite=args.overwrite)
            with clock("load"):
                scene = load_scene_for(cfg)
            if not chosen:
                cfg.out = f"outputs/{cfg.method}{'-compact' if cfg.compact.enabled else ''}/{scene.name}_{len(scene.train)}v"
                folder = open_run_folder(cfg.out, resume=resume, overwrite=args.overwrite)
            out = Path(cfg.out)
            print(f"warpgs: {scene.summary()}", file=sys.stderr)
            if cfg.method != "baseline":  # which video prior, once the scene is known to load
                resolve_backend(cfg.pseudo, real_data=cfg.data.name != "synthetic")
            with clock("geometry"):
                prepare_geometry(cfg, scene)  # once for both methods of a compare run
        except (ConfigError, SceneError, RunFolderError, CheckpointError, ValueError, SVDWeightsNotFound) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        if cfg.method != "compare":
            stopped = run_method(cfg.method, cfg, scene, out, resume, clock=clock).get("stopped_early")
            print_total_time(started)
            return 1 if stopped else 0
        out.mkdir(parents=True, exist_ok=True)
        save_config(cfg, out / "config.yaml")
        hint = f"--resume {out}"
        if compare_in_parallel(args, cfg):
            base, full = compare_parallel(cfg, scene, out, resume, hint)
        else:
            base = run_method("baseline", cfg, scene, out / "baseline", resume, resume_hint=hint)
            full = run_method("full", cfg, scene, out / "full", resume, baseline_metrics=base, resume_hint=hint)
        print_side_by_side(base, full, out)
        print_total_time(started)
        return 1 if base.get("stopped_early") or full.get("stopped_early") else 0
    except RunStopped as e:
        return e.code
    finally:
        restore_sigterm()
        if folder is not None:
            folder.release()


def print_total_time(started: float) -> None:
    """The run's wall-clock time from the command's start (loading, geometry, training, evaluation, writing)."""
    m, sec = divmod(time.perf_counter() - started, 60)
    print(f"warpgs: finished in {int(m)}m{sec:04.1f}s (wall clock, the whole command)")


def compare_in_parallel(args, cfg) -> bool:
    """``--jobs 2`` (or the default on a CPU with two or more cores): the baseline trains in a second
    process while the full method trains in this one. Warp's CPU kernels use one thread each, so on a
    2-core machine this nearly halves the wall time; on a GPU the two would only take turns."""
    import os

    from warpgs.engine.init import resolve_device

    if args.jobs is not None:
        return args.jobs >= 2
    return resolve_device(cfg.train.device).type == "cpu" and (os.cpu_count() or 1) >= 2


def _baseline_process(cfg, scene, out: Path, resume: bool, hint: str, log_path: Path) -> None:
    """Entry point of the second process: the baseline run, its output into ``log_path``."""
    import os

    from warpgs.engine.signals import sigterm_as_interrupt

    sigterm_as_interrupt()
    log = open(log_path, "a", buffering=1)
    os.dup2(log.fileno(), 1)
    os.dup2(log.fileno(), 2)
    sys.stdout = sys.stderr = log
    code = 0
    try:
        run_method("baseline", cfg, scene, out, resume, resume_hint=hint)
    except RunStopped as e:
        code = e.code
    log.flush()
    sys.exit(code)


def compare_parallel(cfg, scene, out: Path, resume: bool, hint: str):
    """Baseline (second process) and full method (this process) at once -> (baseline, full) metrics;
    ``RunStopped`` when either ends without them. Ctrl-C reaches both; each keeps its checkpoint, and
    --resume continues both."""
    import multiprocessing as mp

    from warpgs.engine.evaluation import write_report

    bcfg = copy.deepcopy(cfg)
    bcfg.train.progress = False
    log_path = out / "baseline.log"
    proc = mp.get_context("spawn").Process(target=_baseline_process,
                                           args=(bcfg, scene, out / "baseline", resume, hint, log_path))
    proc.start()
    print(f"warpgs: the baseline trains in a second process (progress in {log_path}); the full method here",
          file=sys.stderr)
    try:
        full = run_method("full", cfg, scene, out / "full", resume, resume_hint=hint)
    finally:
        try:
            proc.join()
        except KeyboardInterrupt:
            proc.join()
    if proc.exitcode != 0:
        print(f"warpgs: the baseline process stopped (exit code {proc.exitcode}); see {log_path}", file=sys.stderr)
        raise RunStopped(130 if proc.exitcode in (130, -2) else proc.exitcode or 1)
    base = json.loads((out / "baseline" / "metrics.json").read_text())
    print(f"\nbaseline: test PSNR {base['psnr']:.2f}  SSIM {base['ssim']:.3f}  ({base['num_gaussians']} Gaussians, "
          f"training {base['train_time_s']:.1f} s; full log {log_path})")
    write_report(out / "full", full, full.get("cycles", []), base)  # the report's PSNR chart gets the baseline line
    return base, full


if __name__ == "__main__":
    sys.exit(main())
