"""``--data NAME|PATH``: named datasets through ``configs/data/*.yaml``, or a folder whose format is detected.

A name (``dl3dv``, ``llff``, ``dtu``, ``blender``, ``synthetic``) reads ``configs/data/<name>.yaml``:
its ``format``, the dataset ``roots`` (relative to the repository root), the ``scene_dirs`` patterns
that locate a scene under a root, the default ``scene``, ``views`` and ``downscale``, loader
``options`` and an ``obtain`` text shown when the data is missing. The roots are replaced by the
``root`` argument (``--data-root``) or else by ``$WARPGS_DATA_ROOT``.

A path is inspected (``detect_format``): ``transforms.json`` (nerfstudio / DL3DV),
``transforms_train.json`` (Blender), ``poses_bounds.npy`` (LLFF), ``cameras.npz`` (DTU) or a COLMAP
model (``sparse/0``, ``colmap/sparse/0``, ``sparse``).
"""

from __future__ import annotations

import argparse
import glob
import inspect
import os
from pathlib import Path
from typing import Any

from warpgs.configio import CONFIG_DIR, REPO_ROOT, UniqueKeyLoader

from . import plausible
from .blender import load_blender
from .dtu import load_dtu
from .llff import load_llff
from .nerfstudio import find_colmap_model, load_colmap, load_nerfstudio
from .scene import DatasetNotFoundError, Scene, SceneError

LOADERS = {
    "nerfstudio": load_nerfstudio,
    "colmap": load_colmap,
    "llff": load_llff,
    "dtu": load_dtu,
    "blender": load_blender,
}
# the config whose defaults a detected path takes (views, downscale, options); captures keep their images as stored
FORMAT_CONFIG = {"llff": "llff", "dtu": "dtu", "blender": "blender"}
CAPTURE_DEFAULTS = {"views": 9, "downscale": None, "options": {}}
ENV_ROOT = "WARPGS_DATA_ROOT"


def config_dir() -> Path:
    return Path(os.environ.get("WARPGS_CONFIG_DIR", CONFIG_DIR)) / "data"


def dataset_names() -> list[str]:
    d = config_dir()
    return sorted(p.stem for p in d.glob("*.yaml")) if d.is_dir() else []


def read_data_config(name: str) -> dict[str, Any]:
    import yaml

    p = config_dir() / f"{name}.yaml"
    if not p.is_file():
        raise SceneError(f"{p}: no such dataset config; known names: {', '.join(dataset_names()) or '(none)'}")
    try:
        cfg = yaml.load(p.read_text(), Loader=UniqueKeyLoader) or {}
    except Exception as e:
        raise SceneError(f"{p}: cannot parse YAML ({e})") from e
    if "format" not in cfg:
        raise SceneError(f"{p}: no 'format' key")
    cfg.setdefault("options", {})
    cfg["_path"] = str(p)
    return cfg


def detect_format(path: str | Path) -> tuple[str, Path]:
    """-> (format, scene folder) for a path, or SceneError saying what was looked for."""
    p = Path(path).expanduser()
    if not p.exists():
        raise SceneError(f"{p}: does not exist")
    if p.is_file():
        if p.name == "poses_bounds.npy":
            return "llff", p.parent
        if p.name.startswith("transforms_") and p.suffix == ".json":
            return "blender", p.parent
        if p.suffix == ".json":
            return "nerfstudio", p
        if p.name == "cameras.npz":
            return "dtu", p.parent
        raise SceneError(f"{p}: not a scene description warpgs knows (transforms.json, poses_bounds.npy, cameras.npz)")
    if (p / "transforms.json").is_file() or (p / "nerfstudio" / "transforms.json").is_file():
        return "nerfstudio", p
    if (p / "transforms_train.json").is_file():
        return "blender", p
    if (p / "poses_bounds.npy").is_file():
        return "llff", p
    if (p / "cameras.npz").is_file():
        return "dtu", p
    try:
        find_colmap_model(p)
        return "colmap", p
    except SceneError:
        pass
    raise SceneError(
        f"{p}: unknown scene layout; expected transforms.json (nerfstudio/DL3DV), transforms_train.json (Blender), "
        "poses_bounds.npy (LLFF), cameras.npz + image/ (DTU) or a COLMAP model in sparse/0, colmap/sparse/0 or sparse/"
    )


def _roots(cfg: dict, root: str | Path | None) -> list[Path]:
    if root is not None:
        return [Path(root).expanduser()]
    if os.environ.get(ENV_ROOT):
        return [Path(os.environ[ENV_ROOT]).expanduser()]
    return [(REPO_ROOT / r).resolve() if not Path(r).is_absolute() else Path(r) for r in cfg.get("roots", ["data"])]


def _format_ok(fmt: str, found: str) -> bool:
    return found == fmt or (fmt in ("nerfstudio", "colmap") and found in ("nerfstudio", "colmap"))


def resolve_scene_dir(name: str, cfg: dict, scene: str | None = None, root: str | Path | None = None) -> tuple[Path, str]:
    """Finds the folder of a named dataset's scene -> (folder, detected format)."""
    roots = _roots(cfg, root)
    patterns = cfg.get("scene_dirs", ["{scene}"])
    looked: list[str] = []

    def try_scene(sc: str):
        for r in roots:
            for pat in patterns:
                cand = str(r / pat.format(scene=sc))
                hits = sorted(glob.glob(cand)) if any(ch in cand for ch in "*?[") else [cand]
                looked.append(cand)
                for h in hits:
                    if Path(h).is_dir():
                        try:
                            fmt, folder = detect_format(h)
                        except SceneError:
                            continue
                        if _format_ok(cfg["format"], fmt):
                            return folder, fmt
        return None

    wanted = scene or cfg.get("scene")
    if wanted:
        hit = try_scene(str(wanted))
        if hit:
            return hit
    if scene is None:  # default scene absent: take the first scene present
        hit = try_scene("*")
        if hit:
            return hit
    what = f"scene {wanted!r} of dataset {name!r}" if wanted else f"any scene of dataset {name!r}"
    shown = list(dict.fromkeys(looked))
    msg = [f"{what} not found. warpgs looked in:"] + [f"  {s}" for s in shown[:12]]
    if len(shown) > 12:
        msg.append(f"  ... and {len(shown) - 12} more")
    msg.append(f"(roots from {'--data-root' if root is not None else ENV_ROOT if os.environ.get(ENV_ROOT) else cfg.get('_path', 'the config')})")
    if cfg.get("obtain"):
        msg.append("How to get it: " + " ".join(str(cfg["obtain"]).split()))
    msg.append(f"Then point warpgs at it with --data-root DIR (or {ENV_ROOT}=DIR), or pass the scene folder as --data PATH.")
    raise DatasetNotFoundError("\n".join(msg))


def _call(loader, path: Path | None, kwargs: dict[str, Any]) -> Scene:
    params = inspect.signature(loader).parameters
    unknown = [k for k in kwargs if k not in params]
    if unknown:
        raise SceneError(f"{loader.__name__} does not take option(s) {unknown}; it takes {[p for p in params if p != 'path']}")
    return loader(**kwargs) if path is None else loader(path, **kwargs)


def load_scene(
    data: str | Path = "synthetic",
    *,
    scene: str | None = None,
    views: int | str | None = None,
    downscale: int | None = None,
    root: str | Path | None = None,
    device: str | None = None,
    **options: Any,
) -> Scene:
    """Loads ``--data NAME|PATH`` into a ``Scene``.

    ``views``: training views (None = the dataset's default, ``"all"`` = every non-test frame);
    ``downscale``: image pyramid level (None = the dataset's default); ``root``: dataset root
    (for ``synthetic``: the folder that holds generated scenes); ``device``: Warp device for
    generating the synthetic scene; ``options``: loader keyword arguments (e.g. ``white_background``,
    ``seed``), overriding the config's ``options``, and the allowances of ``warpgs.data.plausible``
    (``allow_implausible_camera``, ``allow_duplicate_frames``: True lets such data through).
    """
    allow = [k for k in plausible.OPTIONS if options.pop(k, False)]
    with plausible.allowing(*allow):
        return _load_scene(str(data), scene, views, downscale, root, device, options)


def _load_scene(data: str, scene, views, downscale, root, device, options: dict) -> Scene:
    names = dataset_names()
    if data in names and os.sep not in data:  # a folder with such a name is reached as ./NAME
        cfg = read_data_config(data)
        opts = {**cfg.get("options", {}), **options}
        v = cfg.get("views") if views is None else views
        d = cfg.get("downscale") if downscale is None else downscale
        v = None if v == "all" else v
        if cfg["format"] == "synthetic":
            from .synthetic import load_synthetic

            cache = None
            if root is not None:
                from .synthetic import SyntheticConfig

                sc = SyntheticConfig(**{k: opts[k] for k in ("seed", "width", "height", "frames", "kind", "samples_per_side") if k in opts})
                cache = Path(root).expanduser() / sc.dirname()
            return _call(load_synthetic, None, {"views": v, "downscale": d, "out_dir": cache, "device": device, **opts})
        folder, fmt = resolve_scene_dir(data, cfg, scene, root)
        return _call(LOADERS[fmt], folder, {"views": v, "downscale": d, **opts})
    if data in ("dl3dv", "llff", "dtu", "blender", "synthetic") and data not in names:
        raise SceneError(f"{config_dir() / (data + '.yaml')}: dataset config is missing")
    p = Path(data).expanduser()
    if not p.exists():
        raise SceneError(f"--data {data!r}: neither a dataset name ({', '.join(names)}) nor an existing path")
    fmt, folder = detect_format(p)
    defaults = read_data_config(FORMAT_CONFIG[fmt]) if fmt in FORMAT_CONFIG and FORMAT_CONFIG[fmt] in names else CAPTURE_DEFAULTS
    v = defaults.get("views") if views is None else views
    v = None if v == "all" else v
    d = defaults.get("downscale") if downscale is None else downscale
    return _call(LOADERS[fmt], folder, {"views": v, "downscale": d, **defaults.get("options", {}), **options})


# ----------------------------------------------------------------------------------------------
# command line


def add_data_args(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    g = parser.add_argument_group("data")
    g.add_argument("--data", default="synthetic", help=f"dataset name ({', '.join(dataset_names())}) or a scene folder (default: synthetic)")
    g.add_argument("--data-root", default=None, help=f"folder holding the datasets (default: ${ENV_ROOT} or the config's roots)")
    g.add_argument("--scene", default=None, help="scene of the dataset (e.g. fern, scan65, lego, a DL3DV hash)")
    g.add_argument("--views", default=None, help="training views (e.g. 3, 6, 9; 'all' for every non-test frame)")
    g.add_argument("--downscale", type=int, default=None, help="image downscale factor (images_N)")
    return parser


def load_scene_from_args(args: argparse.Namespace, device: str | None = None, **options: Any) -> Scene:
    views = args.views
    if views is not None and views != "all":
        try:
            views = int(views)
        except ValueError as e:
            raise SceneError(f"--views {views!r}: expected a number or 'all'") from e
    return load_scene(args.data, scene=args.scene, views=views, downscale=args.downscale, root=args.data_root, device=device, **options)
