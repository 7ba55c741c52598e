"""Model initialisation: the device, the background colour, the scene's scale, the initial points and the
configuration a run derives from them (``growth_schedule``, ``method_far_field``, ``hold_geometry``), and the initial Gaussians."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import torch

from warpgs.config import Config, to_dict
from warpgs.model import PARAM_NAMES, GaussianModel, read_point_cloud


def resolve_device(name: str) -> torch.device:
    """``train.device`` as a torch device: auto (CUDA when torch sees it, else the CPU), cpu, cuda or cuda:N.
    A name torch does not know, another kind of device, or CUDA where there is none raises ``ValueError``
    (one line naming the value), so a command can refuse it before any work."""
    if name in ("auto", "", None):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError):
        raise ValueError(f"device {name!r}: not a device name; give cpu, cuda, cuda:N or auto") from None
    if dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device {name!r}: warpgs runs on cpu or cuda (cuda:N), or auto")
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r} was asked for, but torch sees no CUDA device; use --device cpu")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ValueError(f"device {name!r}: torch sees {torch.cuda.device_count()} CUDA device(s)")
    return dev


def background_colour(cfg: Config, scene) -> list[float]:
    """The colour behind the Gaussians: ``train.background``, else white for a scene that says so, else black."""
    bg = cfg.train.background
    if bg is not None:
        return list(bg)
    return [1.0, 1.0, 1.0] if scene.white_background else [0.0, 0.0, 0.0]


def scene_scale_of(cameras) -> float:
    """3D-GS's ``cameras_extent``: 1.1 x the largest distance of a camera centre from their mean."""
    centres = np.stack([c.center for c in cameras])
    r = float(np.linalg.norm(centres - centres.mean(0), axis=1).max()) if len(centres) > 1 else 0.0
    return 1.1 * (r if r > 1e-6 else 1.0)


def prepare_geometry(cfg: Config, scene, log=None):
    """For ``model.init`` sfm / stereo / sfm+stereo: the points found between the training views
    (``warpgs.points.initial_geometry``), once per scene and settings (kept on ``scene.geometry``), and the
    scene's depth bounds measured on them (the loader's are kept in ``scene.metadata['loader_bounds']``).
    Returns the ``Geometry``, or None for the other initialisations."""
    from warpgs.points import METHODS, initial_geometry

    if cfg.model.init not in METHODS:
        return None
    key = (cfg.model.init, repr(to_dict(cfg.geometry)))
    geo = getattr(scene, "geometry", None)
    if geo is None or getattr(geo, "key", None) != key:
        log = log or (lambda msg: print(msg, file=sys.stderr))
        geo = initial_geometry(scene.train, cfg.model.init, cfg.geometry, device=resolve_device(cfg.train.device),
                               log=log)
        geo.key = key
        scene.geometry = geo
        scene.metadata.setdefault("loader_bounds", tuple(scene.bounds))
        if geo.bounds is not None:
            scene.bounds = geo.bounds
        log(f"warpgs: init {geo.method}: {len(geo.xyz)} points"
            + "".join(f", {k[:-2]} {v:.1f} s" for k, v in geo.times.items())
            + (f"; scene depth {geo.bounds[0]:.3g}..{geo.bounds[1]:.3g}" if geo.bounds else ""))
    return geo


def growth_schedule(cfg: Config, method: str = "baseline") -> Config:
    """The run's configuration with ``strategy.refine_stop_fraction`` (or, for the full method, ``full.
    refine_stop_fraction`` when set) resolved: growth, pruning and the opacity resets stop at that fraction of
    ``train.iterations`` when it comes before ``strategy.refine_stop_iter``. 3D-GS's schedule (growth to step
    15,000 of 30,000, a reset every 3000) kept as absolute steps lets a 3000-step run grow to its last step
    (the baseline's test PSNR at 6 / 9 views of the captures rose with growth stopped at half the run, with half
    the Gaussians or fewer; README)."""
    frac = cfg.strategy.refine_stop_fraction
    if method == "full" and cfg.full.refine_stop_fraction is not None:
        frac = cfg.full.refine_stop_fraction
    if not frac:
        return cfg
    stop = min(cfg.strategy.refine_stop_iter, int(round(frac * cfg.train.iterations)))
    return dataclasses.replace(cfg, strategy=dataclasses.replace(cfg.strategy, refine_stop_iter=stop))


def method_far_field(cfg: Config, method: str = "baseline") -> Config:
    """The run's configuration with ``full.far_field`` (when set, for the full method) as its far field's kind
    (``backgrounds.far_field.kind``)."""
    kind = cfg.full.far_field if method == "full" else None
    if kind is None:
        return cfg
    bg = cfg.backgrounds
    return dataclasses.replace(cfg, backgrounds=dataclasses.replace(bg, far_field=dataclasses.replace(bg.far_field,
                                                                                                     kind=kind)))


def hold_geometry(cfg: Config, geo) -> tuple[Config, dict | None]:
    """``hold.geometry``: the run's configuration with the initial geometry held (no densification or
    pruning by the strategy; the means', scales' and rotations' learning rates x ``hold.*_lr``), and a
    record of why (None: not held). ``stereo`` holds it only when ``geo`` (``prepare_geometry``'s points)
    came from plane-sweep stereo alone. At 3 views of a walk-around capture SfM finds too few points and the
    run starts from the stereo cloud; growth then bends it towards the inputs and the test views get worse
    than at step 300 (castle_p30 / herz_jesus_p25, 384x256, seeds 0-2: 13.62 / 17.28 with growth, 14.35 / 17.89
    held)."""
    t = cfg.hold
    mode = t.geometry
    if mode not in ("off", "on", "stereo"):
        raise ValueError(f"hold.geometry must be off, on or stereo, got {mode!r}")
    if mode == "off" or (mode == "stereo" and (geo is None or geo.method != "stereo")):
        return cfg, None
    o = cfg.optim
    optim = dataclasses.replace(o, means_lr=o.means_lr * t.means_lr, means_lr_final=o.means_lr_final * t.means_lr,
                                scales_lr=o.scales_lr * t.scales_lr, quats_lr=o.quats_lr * t.quats_lr)
    held = dataclasses.replace(cfg, optim=optim, strategy=dataclasses.replace(cfg.strategy, refine_stop_iter=0))
    why = "hold.geometry=on" if mode == "on" else "the initial points came from stereo"
    return held, {"mode": mode, "why": why, "means_lr": t.means_lr, "scales_lr": t.scales_lr, "quats_lr": t.quats_lr}


def init_model(cfg: Config, scene, generator: torch.Generator) -> GaussianModel:
    """The initial Gaussians (on the CPU) as ``cfg.model.init`` says."""
    m = cfg.model
    kw = dict(sh_degree=m.sh_degree, init_opacity=m.init_opacity, init_scale=m.init_scale)
    geo = prepare_geometry(cfg, scene)
    near, far = (m.init_depth if m.init_depth is not None else scene.bounds)
    if geo is not None:
        if len(geo.xyz) == 0:  # nothing found (said in one line): random points between the measured bounds
            return init_model(dataclasses.replace(cfg, model=dataclasses.replace(m, init="frustum")), scene, generator)
        xyz, rgb = geo.xyz, geo.rgb
        if m.init_fill > 0:  # what only one view sees: a point per empty block, at the nearest point's depth
            from warpgs.points.fill import fill_points

            fx, fc = fill_points(scene.train, xyz, m.init_fill)
            xyz, rgb = np.concatenate([xyz, fx]), np.concatenate([rgb, fc])
        model = GaussianModel.from_points(xyz, rgb, **kw)
        if m.init_random > 0:  # plus random Gaussians in the frusta, for what no method matched (sky, blank walls)
            extra = init_model(dataclasses.replace(cfg, model=dataclasses.replace(m, init="frustum", init_num=m.init_random)),
                               scene, generator)
            model = GaussianModel(*(torch.cat([model.params[n], extra.params[n]]) for n in PARAM_NAMES),
                                  max_sh_degree=m.sh_degree)
        return model
    if m.init == "points":
        if scene.points3d is None or len(scene.points3d) == 0:
            raise ValueError("model.init=points, but the scene has no points (the loaders read them with "
                             "data.options.load_points=true; note they are triangulated from all views)")
        return GaussianModel.from_points(scene.points3d, scene.points_rgb, **kw)
    if m.init == "ply":
        if not m.init_ply:
            raise ValueError("model.init=ply needs model.init_ply=/path/to/points.ply")
        xyz, rgb = read_point_cloud(m.init_ply, drop_invalid=m.drop_invalid)
        return GaussianModel.from_points(xyz, rgb, **kw)
    if m.init == "frustum":
        cams = scene.train
        return GaussianModel.random_frustum(m.init_num, [c.viewmat for c in cams], [c.K for c in cams],
                                            [(c.width, c.height) for c in cams], float(near), float(far),
                                            generator=generator, **kw)
    if m.init in ("box", "hull"):
        if m.init_box is not None:
            if len(m.init_box) != 6:
                raise ValueError(f"model.init_box must be [xmin, ymin, zmin, xmax, ymax, zmax], got {m.init_box}")
            lo, hi = m.init_box[:3], m.init_box[3:]
        else:  # the bounding box of the training frusta between near and far
            corners = []
            for c in scene.train:
                Kinv, c2w = np.linalg.inv(c.K.astype(np.float64)), c.c2w
                for u, v in ((0, 0), (c.width, 0), (0, c.height), (c.width, c.height)):
                    for z in (near, far):
                        p = Kinv @ np.array([u, v, 1.0]) * z
                        corners.append(c2w[:3, :3] @ p + c2w[:3, 3])
            corners = np.array(corners)
            lo, hi = corners.min(0), corners.max(0)
        if m.init == "hull":
            cams = scene.train
            if any(c.alpha is None for c in cams):
                raise ValueError(f"model.init=hull needs an alpha channel in every training view; {scene.name}'s "
                                 f"view {next(c.name for c in cams if c.alpha is None)} has none (use box or frustum)")
            return GaussianModel.random_hull(m.init_num, lo, hi, [c.viewmat for c in cams], [c.K for c in cams],
                                             [c.alpha for c in cams], generator=generator, **kw)
        return GaussianModel.random_box(m.init_num, lo, hi, generator=generator, **kw)
    raise ValueError(f"model.init={m.init!r}: expected sfm, stereo, sfm+stereo, box, hull, frustum, points or ply")

