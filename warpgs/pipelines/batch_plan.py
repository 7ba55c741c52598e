"""The batch runner's plan: the runs of a command line or a sweep file, their names and the GPU share each asks
for, and the deadline (``python -m warpgs.pipelines.batch``; the runs themselves are in ``batch``)."""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

MIN_GPU_SHARE = 1 / 8
PIXELS_PER_GPU = 2.0e6  # gpu_share: a run of this many pixels per image takes a whole GPU ...
GAUSSIANS_PER_GPU = 1.0e7  # ... as does one of this many Gaussians
GAUSSIANS_WITHOUT_BUDGET = 500_000  # the estimate where strategy.max_gaussians is 0 (no budget)


class BatchError(ValueError):
    """Bad input for the whole batch (one line, exit code 2)."""


@dataclass
class RunSpec:
    """One run of a batch: the arguments of ``python -m warpgs.pipelines.sparse`` (without ``--out``), the
    keys it is grouped by in the results, and what it asks Ray for."""

    name: str  # its folder under OUT/runs and its log's name
    argv: list
    scene: str
    views: int | str | None
    method: str
    seed: int | None
    num_cpus: float = 1.0
    num_gpus: float = 0.0
    image_size: list | None = None  # [width, height] as probed (what the GPU share came from)


# ----------------------------------------------------------------------------------------------
# planning: the runs, their configs and their resources


def split_list(text: str | None, flag: str, cast=str) -> list:
    if text is None:
        return [None]
    items = [t.strip() for t in str(text).split(",") if t.strip()]
    if not items:
        raise BatchError(f"{flag} {text!r}: expected a comma-separated list")
    try:
        return [cast(t) for t in items]
    except ValueError:
        raise BatchError(f"{flag} {text!r}: expected a comma-separated list of numbers") from None


def data_args(entry: str, dataset: str) -> tuple[list[str], str]:
    """A ``--data`` entry -> (the run's data arguments, a short tag for run names). A dataset name or an
    existing path stays as it is; ``DATASET:SCENE`` and a bare scene name (of ``dataset``) become
    ``--data DATASET --scene SCENE``."""
    from warpgs.data.registry import dataset_names

    if entry in dataset_names():
        return ["--data", entry], entry
    if ":" in entry and entry.split(":", 1)[0] in dataset_names():
        name, scene = entry.split(":", 1)
        return ["--data", name, "--scene", scene], scene
    p = Path(entry).expanduser()
    if p.exists() or os.sep in entry:  # a path (one that does not exist is the run's to report)
        return ["--data", str(p.resolve())], p.name or "scene"
    return ["--data", dataset, "--scene", entry], entry


def gpu_share(width: int, height: int, gaussians: int) -> float:
    """The GPU share one run asks Ray for: megapixels / 2 + millions of Gaussians / 10, rounded up to 1/k (so
    that k runs fill a GPU with nothing left over) and kept in [1/8, 1]. At 768x512 (0.39 MP) with no
    Gaussian budget (estimated 500k) that is 1/4; the synthetic scene's 128x96 with 12k is 1/8; 1080p with
    1M Gaussians is 1. Measured peak allocations stay far below a GPU's memory (at most 3.3 GB at 768x512,
    bench/results/perf/capture_runs_768x512_h200.json); the share limits how many runs contend for one GPU's
    compute."""
    raw = width * height / PIXELS_PER_GPU + gaussians / GAUSSIANS_PER_GPU
    if raw >= 1:
        return 1.0
    return max(MIN_GPU_SHARE, 1 / math.floor(1 / raw))


def probe_image_size(cfg) -> tuple[int, int] | None:
    """The size of the images a run of ``cfg`` trains on, read without decoding any: the synthetic scene's
    from its options, a nerfstudio capture's from transforms.json and the ``images_N`` folder it will use,
    other formats from their first image's header. None where the scene cannot be found (the run says why)."""
    from PIL import Image

    from warpgs.data.registry import dataset_names, detect_format, read_data_config, resolve_scene_dir
    from warpgs.data.scene import SceneError

    d = cfg.data
    try:
        if d.name in dataset_names():
            dcfg = read_data_config(d.name)
            downscale = d.downscale or dcfg.get("downscale")
            if dcfg["format"] == "synthetic":
                opts = {**dcfg.get("options", {}), **d.options}
                return int(opts.get("width", 256)) // (downscale or 1), int(opts.get("height", 192)) // (downscale or 1)
            folder, fmt = resolve_scene_dir(d.name, dcfg, d.scene, d.root)
        else:
            fmt, folder = detect_format(d.name)
            downscale = d.downscale
    except (SceneError, OSError, ValueError):
        return None
    folder = Path(folder)
    meta = folder if folder.is_file() else folder / "transforms.json"
    if fmt == "nerfstudio" and meta.is_file():
        try:
            m = json.loads(meta.read_text())
            frame = m["frames"][0]
            w, h = int(frame.get("w", m["w"])), int(frame.get("h", m["h"]))
        except (OSError, ValueError, KeyError, IndexError, TypeError):
            return None
        if downscale is None:  # the first of images/, images_2/4/8 holding the first frame (the loader's order)
            rel = Path(frame["file_path"])
            downscale = next((f for f in (1, 2, 4, 8) if (meta.parent / (rel.parent.name + (f"_{f}" if f > 1 else ""))
                                                            / rel.name).is_file()), 1)
        return w // downscale, h // downscale
    base = folder.parent if folder.is_file() else folder
    scaled = base / f"images_{downscale}"  # LLFF's images_8: already at that size
    search, factor = (scaled, 1) if downscale and scaled.is_dir() else (base, downscale or 1)
    for p in sorted(search.rglob("*")):
        if p.suffix.lower() in (".png", ".jpg", ".jpeg") and "mask" not in p.parent.name:
            try:
                with Image.open(p) as im:
                    w, h = im.size
            except OSError:
                continue
            return w // factor, h // factor
    return None


def run_name(tag: str, views, method: str, seed, variant: str | None = None) -> str:
    """``<tag>_<views>v_<method>_s<seed>``, and ``_<variant>`` for a variant's run (what bench/report/compare.py
    matches a variant's runs to the default's by)."""
    parts = [re.sub(r"[^A-Za-z0-9_.-]+", "_", tag)]
    if views is not None:
        parts.append(f"{views}v")
    parts.append(method)
    if seed is not None:
        parts.append(f"s{seed}")
    if variant:
        parts.append(variant)
    return "_".join(parts)


def plan(args) -> list[RunSpec]:
    """The batch's runs (every --data x --views x method x --seeds), each config built and checked as the
    run itself will (``BatchError`` naming the run on a bad value), with its resources: a GPU share unless
    ``--device cpu``."""
    from warpgs.config import ConfigError
    from warpgs.pipelines.sparse import METHODS, build_parser, make_config

    # compare: the baseline and the full method as two runs; every other method one run
    methods = {"compare": ["baseline", "full"], **{m: [m] for m in METHODS if m != "compare"}}.get(args.method)
    if methods is None:
        raise BatchError(f"--method {args.method!r}: available methods are {', '.join(METHODS)}")
    common = []
    for f in args.config:
        common += ["--config", str(Path(f).resolve())]
    for s in args.set:
        common += ["--set", s]
    if args.iterations is not None:
        common += ["--iterations", str(args.iterations)]
    if args.data_root is not None:
        common += ["--data-root", str(Path(args.data_root).expanduser().resolve())]
    if args.device is not None:
        common += ["--device", args.device]
    entries = {}  # --data entry -> (its data arguments, a tag no other entry has)
    for entry in split_list(args.data, "--data"):
        data, tag = data_args(entry, args.dataset)
        taken = {t for _, t in entries.values()}
        entries[entry] = (data, tag if tag not in taken else next(f"{tag}-{k}" for k in itertools.count(2)
                                                                   if f"{tag}-{k}" not in taken))
    runs = []
    for entry, views, method, seed in itertools.product(entries, split_list(args.views, "--views"), methods,
                                                        split_list(args.seeds, "--seeds", int)):
        data, tag = entries[entry]
        argv = data + (["--views", str(views)] if views is not None else []) + ["--method", method]
        argv += (["--seed", str(seed)] if seed is not None else []) + common + ["--no-progress"]
        try:
            cfg, _ = make_config(build_parser().parse_args(argv))
        except ConfigError as e:
            raise BatchError(f"{entry}, {method}: {e}") from None
        name = run_name(tag, cfg.data.views, method, cfg.train.seed, getattr(args, "variant", None))
        size = probe_image_size(cfg)
        spec = RunSpec(name, argv, tag, cfg.data.views, method, cfg.train.seed, num_cpus=args.cpus_per_run,
                       image_size=list(size) if size else None)
        if args.device != "cpu":  # main() drops the shares when the cluster has no GPU
            budget = cfg.strategy.max_gaussians or GAUSSIANS_WITHOUT_BUDGET
            # no size: the scene is not there, and the run will stop at once with the loader's message
            per_gpu = getattr(args, "runs_per_gpu", None)
            spec.num_gpus = (1 / per_gpu if per_gpu else args.gpus_per_run
                             or (gpu_share(*size, budget) if size else MIN_GPU_SHARE))
        runs.append(spec)
    return runs


# ----------------------------------------------------------------------------------------------
# sweep files: the runs of a batch written down


SWEEP_BATCH_KEYS = ("out", "data_root", "device", "runs_per_gpu", "gpus_per_run", "cpus_per_run", "max_retries",
                    "grace")  # a sweep's own settings (each a command-line flag, which wins over the file)
SWEEP_RUN_KEYS = ("data", "dataset", "views", "method", "seeds", "iterations", "set", "config", "variants")


def _csv(value) -> str | None:
    if value is None:
        return None
    return ",".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)


def _strings(value, where: str) -> list[str]:
    if value is None:
        return []
    if isinstance(value, str):
        return [value]
    if isinstance(value, list) and all(isinstance(v, (str, int, float)) for v in value):
        return [str(v) for v in value]
    raise BatchError(f"{where}: expected a list of strings")


def load_sweep(path) -> tuple[dict, list[dict]]:
    """A sweep file (YAML) -> (its batch settings, its run groups). The file holds the batch settings
    (``SWEEP_BATCH_KEYS``), settings every group shares (``SWEEP_RUN_KEYS``: ``set`` entries add up) and ``runs``: a
    list of groups, each every combination of its ``data`` x ``views`` x ``method`` x ``seeds``; a group's
    ``variants`` (``{name: [KEY=VALUE, ...]}``) repeat it once per variant with those settings on top, each run
    named with the suffix ``_<name>`` (the name ``default`` adds no suffix and no setting)."""
    import yaml

    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        raise BatchError(f"--sweep {path}: {e}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("runs"), list) or not doc["runs"]:
        raise BatchError(f"--sweep {path}: expected a mapping with a non-empty list 'runs'")
    unknown = set(doc) - set(SWEEP_BATCH_KEYS) - set(SWEEP_RUN_KEYS) - {"runs"}
    if unknown:
        raise BatchError(f"--sweep {path}: unknown keys {', '.join(sorted(unknown))} (known: "
                         f"{', '.join(SWEEP_BATCH_KEYS + SWEEP_RUN_KEYS)}, runs)")
    shared = {k: doc[k] for k in SWEEP_RUN_KEYS if k in doc}
    groups = []
    for i, g in enumerate(doc["runs"]):
        where = f"--sweep {path}: runs[{i}]"
        if not isinstance(g, dict) or set(g) - set(SWEEP_RUN_KEYS):
            raise BatchError(f"{where}: expected a mapping of {', '.join(SWEEP_RUN_KEYS)}")
        group = {**shared, **g, "set": _strings(shared.get("set"), where) + _strings(g.get("set"), where)}
        variants = group.get("variants") or {"default": []}
        if not isinstance(variants, dict):
            raise BatchError(f"{where}: variants: expected a mapping of name: [KEY=VALUE, ...]")
        for name in variants:
            if name != "default" and not re.fullmatch(r"[A-Za-z0-9.-]+", str(name)):
                raise BatchError(f"{where}: variant {name!r}: letters, digits, '.' and '-' only (it ends run names)")
        group["variants"] = {str(k): _strings(v, f"{where}: variants.{k}") for k, v in variants.items()}
        groups.append(group)
    return {k: doc[k] for k in SWEEP_BATCH_KEYS if k in doc}, groups


def plan_sweep(args, groups: list[dict]) -> list[RunSpec]:
    """The runs of a sweep's groups (``load_sweep``), each planned as ``plan`` plans the command line's, with the
    command line's ``--set`` and ``--config`` under each group's; ``BatchError`` when two runs get one name."""
    specs: list[RunSpec] = []
    for g in groups:
        for variant, sets in g["variants"].items():
            ns = argparse.Namespace(**vars(args))
            for key in ("data", "views", "seeds"):
                if key in g:
                    setattr(ns, key, _csv(g[key]))
            for key in ("dataset", "method", "iterations"):
                if key in g:
                    setattr(ns, key, g[key])
            ns.set = list(args.set) + g["set"] + sets
            ns.config = list(args.config) + _strings(g.get("config"), "config")
            ns.variant = None if variant == "default" else variant
            specs += plan(ns)
    seen: set[str] = set()
    for s in specs:
        if s.name in seen:
            raise BatchError(f"--sweep: two runs are named {s.name} (give one of the groups a variant name)")
        seen.add(s.name)
    return specs


def parse_deadline(text: str | None, now: float | None = None) -> float | None:
    """``--deadline`` -> epoch seconds: a duration from ``now`` (``600``, ``90s``, ``45m``, ``2h``), a UTC clock
    time of today (``07:30``) or an ISO date and time (``2026-11-29T07:30``, UTC unless it says otherwise)."""
    import datetime as dt

    if text is None:
        return None
    now = time.time() if now is None else now
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([smh]?)\s*", text)
    if m:
        return now + float(m[1]) * {"": 1, "s": 1, "m": 60, "h": 3600}[m[2]]
    utc = dt.timezone.utc
    try:
        if re.fullmatch(r"\d{1,2}:\d{2}", text.strip()):
            h, mi = map(int, text.split(":"))
            when = dt.datetime.fromtimestamp(now, utc).replace(hour=h, minute=mi, second=0, microsecond=0)
        else:
            when = dt.datetime.fromisoformat(text.strip())
            when = when if when.tzinfo else when.replace(tzinfo=utc)
    except ValueError:
        raise BatchError(f"--deadline {text!r}: a duration (600, 90s, 45m, 2h), a UTC time (07:30) or an ISO "
                         "date and time") from None
    if when.timestamp() <= now:
        raise BatchError(f"--deadline {text}: {when.isoformat()} has passed")
    return when.timestamp()
