"""Training and evaluation of a 3D-GS model on a ``Scene``: the sparse-view baseline.

    trainer = Trainer(cfg, scene, out_dir)       # initialises the model (trainer.load_checkpoint() resumes)
    trainer.run()                                 # the method's phases: progress bar, checkpoints, Ctrl-C
    result = trainer.finish()                     # stages, test metrics, renders, PLY, metrics.json

One loop serves every method: a ``Method`` (below; the baseline's adds nothing, the paper's is
``warpgs.pipelines.full.FullMethod``) adds loss terms, among them extra views, keeps its part of the
training state, runs its phases and adds its records after training.

The training state has one serialisation, ``Trainer.state_dict(parts)`` / ``load_state_dict``, in three
parts: ``model`` (parameters, Adam's moments, densification statistics), ``progress`` (step, RNGs, view
order) and ``history`` (times, losses, recoveries, curve). Checkpoints hold all three, the in-memory
snapshot of a divergence rollback ``model`` and ``progress``, compact mode's search (warpgs/compact.py)
``model``.

One input view per iteration (3D-GS's shuffled order); loss = 0.8 L1 + 0.2 D-SSIM (+ a Pearson depth term
when ``loss.depth_weight`` > 0 and the view has a depth prior); Adam with 3D-GS's learning rates and an
exponentially decaying position rate; densification by ``DefaultStrategy``. Weight-free regularisers, each
off by default: DropGaussian (``train.drop_rate``) and opacity noise (``train.opacity_noise``) on the
training renders' opacities (``Trainer.opacity_scale``; evaluation renders all Gaussians as they are), and
an anisotropy prior on the scales (``train.scale_reg``).

With ``train.co_reg`` (CoR-GS, ``warpgs.coreg``) a second model trains beside the first on the same views, with
its own optimiser, strategy and random streams; the two are co-pruned and co-regularised on poses between the
training views. Each step adds its loss to the first model's before the one backward, both optimisers step on the
guard's one verdict (``optimizers``; the guard checks both models' ``trained_parameters``), and its state goes
into every part of the state under ``pair``. The first model is the one evaluated and exported.

Reproducibility: ``train.seed`` seeds the initialisation, the view order and the split noise (each
its own generator, all saved in checkpoints, so a resumed run continues exactly as an uninterrupted
one). On the CPU, Warp's kernels run on one thread, so two runs with one seed give identical numbers;
on CUDA the rasterizer sums gradients in fixed point and cuDNN is set deterministic, for the same reason.

Checkpoints (``checkpoint.pt`` in the output folder) are written every ``train.checkpoint_every``
steps through a temporary file (flushed to disk) and a rename, so an interruption never leaves a broken
one, and the one they replace is kept beside them as ``checkpoint.prev.pt``. A checkpoint that cannot be
read is a ``CheckpointError`` in one line; resuming (``load_checkpoint()`` without a path) then falls back
to the previous one with a note. A write that fails (a full disk) leaves both files as they were and
raises ``CheckpointError`` naming the last good one. Ctrl-C finishes the current step, writes a
checkpoint and stops (``TrainingInterrupted``); a second Ctrl-C stops at once, keeping the last checkpoint.

Divergence (judged by ``warpgs.guard.DivergenceGuard``, acted on here): a step is skipped (no update)
when its loss or gradients are not finite, or when its loss on the input views (``parts["inputs"]`` of
``compute_loss``; pseudo views are left out) explodes: above ``train.explode_factor`` x the median of the
last ``train.explode_window`` finite losses (the statistic restarts with each ``train()`` call, i.e. each
phase of the full method, and after an opacity reset, whose expected jumps are not divergence). A
divergence is ``train.max_nan_steps`` skipped steps in a row, ``train.explode_patience`` exploding ones
in a row (one high loss alone, e.g. a hard view early in a phase, costs one step, never the run), or
parameters that are not finite after the optimiser step. The trainer keeps an in-memory snapshot of the
last good state (parameters, Adam moments, densification statistics, RNGs), taken at each ``train()``
call and every ``train.snapshot_every`` steps when all of it is finite; on a divergence it rolls back to
it, scales every learning rate by ``train.recovery_lr_factor`` and goes on (each recovery is logged and
listed in metrics.json). After ``train.max_recoveries`` recoveries the next divergence stops the run with
``TrainingDiverged``, naming the step, the cause and the last good checkpoint on disk; the model is left
at the last good state. A checkpoint is never written from a state that is not finite, so the one on disk
stays the last good one.

Host reads (``train.sync_every``; 10 on CUDA, every step on the CPU): reading a loss or a flag on the host
waits for the device, so on CUDA the verdicts are read every ``sync_every`` steps (and before every
snapshot, checkpoint, evaluation, the end of a phase and a stop). In between, a step is judged on the
device (finite loss and gradients; the exploding-loss median over ``warpgs.guard.LossWindow``, the same
statistic in the same arithmetic) and a bad step's update is skipped there (``masked_step``: fused Adam's
``found_inf``), so a non-finite gradient never reaches the parameters. The read replays the verdicts
through the guard in order; a divergence is acted on then, up to ``sync_every`` steps late, and rolls back
as above (the steps after it are undone with it). Only the reads move: a run gives the same numbers for
every ``sync_every``. The progress bar's loss and PSNR are those of the reading steps.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np
import torch

from warpgs import losses
from warpgs.config import Config, config_from_dict, to_dict
from warpgs.console import warn_once
from warpgs.evaluation import evaluate_views, run_metrics, write_run_outputs
from warpgs.farfield import FarFieldImages, make_far_field
from warpgs.guard import DivergenceGuard, LossWindow
from warpgs.metrics import render_fps
from warpgs.model import PARAM_NAMES, GaussianModel, read_point_cloud
from warpgs.optim import (STATE_PARTS, adam_options, base_learning_rates, finite_flags,  # noqa: F401
                          load_model_state, make_optimizer, masked_step, model_state, with_adam_options)

CHECKPOINT = "checkpoint.pt"
SYNC_EVERY_CUDA = 10  # train.sync_every's default on CUDA: host reads of the verdicts every this many steps
# a step's record (Trainer._step_record): [loss, loss finite, each gradient finite ..., exploding, MSE]
_VALUE, _LOSS_FINITE, _EXPLODING, _MSE = 0, 1, -2, -1
PREVIOUS_CHECKPOINT = "checkpoint.prev.pt"  # the one checkpoint.pt replaced, kept until the next write


class CheckpointError(RuntimeError):
    """A checkpoint cannot be read or written; the message is one line naming the file."""


def previous_checkpoint(path: str | Path) -> Path:
    """Where the checkpoint ``path`` replaced is kept (``checkpoint.pt`` -> ``checkpoint.prev.pt``)."""
    path = Path(path)
    return path.with_name(f"{path.stem}.prev{path.suffix}")


def read_checkpoint(path: str | Path) -> dict:
    """A checkpoint's content; ``CheckpointError`` in one line when it is missing, truncated, corrupt or not
    a warpgs checkpoint."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # zip reader, unpickler, EOF: a truncated or overwritten file
        why = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__).split(". ")[0]
        raise CheckpointError(f"{path}: cannot be read, it is truncated or corrupt ({type(e).__name__}: "
                              f"{why[:120]})") from None
    missing = [k for k in ("config", "params") if not isinstance(ck, dict) or k not in ck]
    if missing:
        raise CheckpointError(f"{path}: not a warpgs checkpoint (no {', '.join(missing)})")
    return ck


def resumable_checkpoint(folder: str | Path, log=None) -> tuple[Path, dict] | None:
    """The checkpoint to resume ``folder``'s run from, read: ``checkpoint.pt``, or when that cannot be read
    (or is missing) the previous one, ``checkpoint.prev.pt``, with a one-line note through ``log`` (default
    ``warn_once``: once per process). None when the folder holds neither; ``CheckpointError`` when no file
    there can be read."""
    current = Path(folder) / CHECKPOINT
    prev = previous_checkpoint(current)
    if not current.is_file() and not prev.is_file():
        return None
    try:
        return current, read_checkpoint(current)
    except CheckpointError as e:
        if not prev.is_file():
            raise
        try:
            ck = read_checkpoint(prev)
        except CheckpointError as e2:
            raise CheckpointError(f"{e}; the previous one cannot be read either ({e2})") from None
        msg = f"warpgs: {e}; resuming from the previous checkpoint {prev.name} (step {ck.get('step')})"
        (log or warn_once)(msg)
        return prev, ck


class TrainingInterrupted(Exception):
    """Training stopped on request (Ctrl-C) after saving a checkpoint."""

    def __init__(self, step: int, checkpoint: Path | None):
        super().__init__(f"interrupted at step {step}" + (f"; checkpoint {checkpoint}" if checkpoint else ""))
        self.step, self.checkpoint = step, checkpoint


class TrainingDiverged(RuntimeError):
    """Training stopped because it diverged and the recoveries did not help (see the module docstring).

    ``step``: where the last divergence was found; ``cause``: what it was; ``checkpoint``: the last good
    checkpoint on disk (None when none was written)."""

    def __init__(self, message: str, step: int | None = None, cause: str | None = None,
                 checkpoint: Path | None = None):
        super().__init__(message)
        self.step, self.cause, self.checkpoint = step, cause, checkpoint


def resolve_device(name: str) -> torch.device:
    if name in ("auto", "", None):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(name)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise RuntimeError(f"device {name!r} was asked for, but torch sees no CUDA device")
    if dev.type not in ("cpu", "cuda"):
        raise RuntimeError(f"device {name!r}: warpgs runs on cpu or cuda")
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
    (session 35: the baseline's test PSNR at 6 / 9 views of the captures rose with growth stopped at half the run,
    with half the Gaussians or fewer; README)."""
    frac = cfg.strategy.refine_stop_fraction
    if method == "full" and cfg.full.refine_stop_fraction is not None:
        frac = cfg.full.refine_stop_fraction
    if not frac:
        return cfg
    stop = min(cfg.strategy.refine_stop_iter, int(round(frac * cfg.train.iterations)))
    return dataclasses.replace(cfg, strategy=dataclasses.replace(cfg.strategy, refine_stop_iter=stop))


def hold_geometry(cfg: Config, geo) -> tuple[Config, dict | None]:
    """``train.hold_geometry``: the run's configuration with the initial geometry held (no densification or
    pruning by the strategy; the means', scales' and rotations' learning rates x ``train.hold_*``), and a
    record of why (None: not held). ``stereo`` holds it only when ``geo`` (``prepare_geometry``'s points)
    came from plane-sweep stereo alone. At 3 views of a walk-around capture SfM finds too few points and the
    run starts from the stereo cloud; growth then bends it towards the inputs and the test views get worse
    than at step 300 (session 21, castle_p30 / herz_jesus_p25, 384x256, seeds 0-2: 13.62 / 17.28 with growth,
    14.35 / 17.89 held; bench/results/s21)."""
    t = cfg.train
    mode = t.hold_geometry
    if mode not in ("off", "on", "stereo"):
        raise ValueError(f"train.hold_geometry must be off, on or stereo, got {mode!r}")
    if mode == "off" or (mode == "stereo" and (geo is None or geo.method != "stereo")):
        return cfg, None
    o = cfg.optim
    optim = dataclasses.replace(o, means_lr=o.means_lr * t.hold_means_lr, means_lr_final=o.means_lr_final * t.hold_means_lr,
                                scales_lr=o.scales_lr * t.hold_scales_lr, quats_lr=o.quats_lr * t.hold_quats_lr)
    held = dataclasses.replace(cfg, optim=optim, strategy=dataclasses.replace(cfg.strategy, refine_stop_iter=0))
    why = "train.hold_geometry=on" if mode == "on" else "the initial points came from stereo"
    return held, {"mode": mode, "why": why, "means_lr": t.hold_means_lr, "scales_lr": t.hold_scales_lr,
                  "quats_lr": t.hold_quats_lr}


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


def _all_finite(tensors) -> bool:
    """Whether every tensor is finite, with one device sync."""
    checks = [torch.isfinite(t).all() for t in tensors if isinstance(t, torch.Tensor) and t.is_floating_point()]
    if not checks:
        return True
    dev = checks[0].device  # tensors may live on several devices (CPU-side state next to CUDA parameters)
    return bool(torch.stack([c.to(dev) for c in checks]).all())


def _atomic_torch_save(obj, path: Path, keep_previous: bool = True) -> None:
    """Writes ``obj`` to a temporary file beside ``path``, flushes it to disk and renames it into place;
    with ``keep_previous`` the file it replaces becomes ``previous_checkpoint(path)``. When writing fails
    (``OSError``, e.g. a full disk) the temporary file goes and ``path`` and its previous one stay as they were."""
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            torch.save(obj, f)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if keep_previous and path.is_file():
        prev = previous_checkpoint(path)
        try:  # a second name for the current file, then renamed over the previous one: path exists throughout
            link = prev.with_name(prev.name + f".tmp{os.getpid()}")
            link.unlink(missing_ok=True)
            os.link(path, link)
            os.replace(link, prev)
        except OSError:  # no hard links here: the current one moves
            os.replace(path, prev)
    os.replace(tmp, path)



class Method:
    """What a training method adds to the one loop of ``Trainer``; this base is the baseline, which adds
    nothing. Hooks, each called by the trainer:

    - ``attach(trainer)``: once, at the end of ``Trainer.__init__`` (the method keeps ``self.trainer``);
    - ``loss_terms(out, cam, loss, parts)``: the training loss of a step from the inputs' ``loss``; extra
      views are rendered and added here, and each term's value goes into ``parts``;
    - ``extra_views()``: the views it trains on besides the inputs (compact mode's importance counts them);
    - ``state_dict(parts)`` / ``load_state_dict(st)``: the method's share of ``Trainer.state_dict``;
    - ``run()``: the phases of training (``Trainer.run``);
    - ``finish(metrics, baseline)``: records and outputs after ``Trainer.finish``'s own."""

    name = "baseline"

    def attach(self, trainer) -> None:
        self.trainer = trainer

    def loss_terms(self, out, cam, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        return loss

    def graph_safe(self) -> bool:
        """Whether ``loss_terms`` now adds only torch operations with no host read and no random draw, so that
        a CUDA graph can hold the step (``warpgs.graphstep``)."""
        return True

    def extra_views(self) -> list:
        return []

    def state_dict(self, parts=STATE_PARTS) -> dict:
        return {}

    def load_state_dict(self, st: dict) -> None:
        pass

    def run(self) -> None:
        self.trainer.train()

    def finish(self, metrics: dict, baseline: dict | None = None) -> dict:
        return metrics


def _upgrade_format_1(ck: dict, sh_degree_interval: int) -> dict:
    """A checkpoint of format 1 (the same keys; the full method's under ``full``, no SH degree in use) as
    ``Trainer.state_dict`` writes it."""
    ck = dict(ck)
    full = ck.pop("full", None)
    ck["active_sh_degree"] = min(int(ck["step"]) // max(sh_degree_interval, 1), ck["max_sh_degree"])
    ck["method"] = {"cycle": full} if full is not None else {}
    if full is not None:
        ck["phase"] = tuple(full["phase"])
    return ck


class Trainer:
    def __init__(self, cfg: Config, scene, out_dir: str | Path | None = None, *, method: Method | None = None,
                 log=None):
        self.cfg, self.scene = cfg, scene
        # the configuration as requested: what checkpoints and config.yaml hold. self.cfg (below) is derived from it
        # (growth_schedule, hold_geometry), and a resumed run derives it again from the saved one
        self.requested_cfg = cfg
        self.out = Path(out_dir) if out_dir is not None else None
        self.log = log or (lambda msg: print(msg, file=sys.stderr))
        self.device = resolve_device(cfg.train.device)
        if self.device.type == "cpu" and cfg.train.cpu_threads > 0:
            # The images are small and Warp's CPU kernels run on one thread: more torch threads gain
            # little, and on a busy machine their synchronisation made small ops 50x slower.
            torch.set_num_threads(cfg.train.cpu_threads)
        if self.device.type == "cuda":
            # the rasterizer's backward is deterministic (fixed-point sums); cuDNN's convolutions (SSIM)
            # must be too, so two runs with one seed give the same numbers
            torch.backends.cudnn.deterministic = True
            torch.backends.cudnn.benchmark = False
        if not scene.train:
            raise ValueError(f"{scene.name}: no training views")
        self.train_cams = [c.to_torch(self.device) for c in scene.train]
        self.test_cams = [c.to_torch(self.device) for c in scene.test]
        self.background = torch.tensor(background_colour(cfg, scene), dtype=torch.float32, device=self.device)
        self.scene_scale = cfg.optim.scene_scale or scene_scale_of(scene.train)
        seed = cfg.train.seed
        torch.manual_seed(seed)
        np.random.seed(seed % 2**32)
        # the initial points (found here or earlier, then kept on the scene) decide train.hold_geometry
        geo = prepare_geometry(cfg, scene, self.log)
        cfg = growth_schedule(cfg, method.name if method is not None else "baseline")
        cfg, self.held = hold_geometry(cfg, geo)  # the same cfg when not held
        self.cfg = cfg
        # fitted on the training views (and their points) only, deterministic: a resumed run computes the same one
        self._far_images = FarFieldImages()
        self.far_field = self.fit_far_field(cfg.train.far_field, geo)
        if self.held is not None:
            self.log(f"warpgs: geometry held ({self.held['why']}): no densification; means / scales / rotations "
                     f"learning rates x {self.held['means_lr']:g} / {self.held['scales_lr']:g} / {self.held['quats_lr']:g}")
        self.strategy = cfg.strategy
        init_gen = torch.Generator().manual_seed(seed)
        self.model = init_model(cfg, scene, init_gen).to(self.device)
        self.split_gen = torch.Generator(device=self.device).manual_seed(seed + 1)
        self.drop_gen = torch.Generator(device=self.device).manual_seed(seed + 5)
        self.drop_rate = cfg.train.drop_rate  # the full method may set its own (full.drop_rate)
        if not 0.0 <= self.drop_rate < 1.0:
            raise ValueError(f"train.drop_rate must be in [0, 1), got {self.drop_rate}")
        self._drop_t = (torch.zeros((), device=self.device), torch.zeros((), device=self.device))  # drop_rate_tensors
        if not 0.0 <= cfg.train.opacity_noise <= 1.0:  # a factor 1 + eps with |eps| <= sigma stays >= 0
            raise ValueError(f"train.opacity_noise must be in [0, 1], got {cfg.train.opacity_noise}")
        self.clearance = None  # train.path_clearance: the camera path's free space (warpgs/clearance.py)
        if cfg.train.path_clearance > 0 or cfg.train.view_clearance > 0:
            from warpgs.clearance import PathClearance

            geo = getattr(scene, "geometry", None)
            c0 = scene.train[0]
            self.clearance = PathClearance.build(
                np.stack([c.viewmat for c in scene.train]), cfg.train.path_clearance * float(scene.bounds[0]),
                order=cfg.pseudo.trajectory.order, geometry=None if geo is None else geo.xyz, device=self.device,
                K=c0.K, size=(c0.width, c0.height), view_depth=cfg.train.view_clearance * float(scene.bounds[0]))
        self.floaters = None  # train.path_floaters: what poses of the camera path see and no input does
        if cfg.train.path_floaters > 0 and len(scene.train) >= 2:
            from warpgs.clearance import PathFloaters

            c0 = scene.train[0]
            self.floaters = PathFloaters.build(
                np.stack([c.viewmat for c in scene.train]), c0.K, (c0.width, c0.height), cfg.train.path_floaters,
                per_pair=cfg.train.path_floaters_poses, order=cfg.pseudo.trajectory.order, device=self.device,
                paths=cfg.train.path_floaters_paths)
        # seconds its passes took (metrics.json stage_times_s path_floaters_s, part of train_s but the final pass)
        self.path_floaters_time = None if self.floaters is None else 0.0
        self.view_rng = np.random.default_rng(seed + 2)
        self.order: list[int] = []
        self.optimizer = make_optimizer(self.model, cfg, self.scene_scale)
        self.state = self.strategy.initialize_state(len(self.model), self.device)
        self.step = 0
        self.train_time = 0.0
        self.losses: list[float] = []
        # divergence handling (module docstring): the guard's verdicts, the learning-rate scale, recoveries so
        # far, the last good state
        self.guard = DivergenceGuard(cfg.train)
        self.phase_start, self.phase_len = 0, None  # the running learning-rate schedule (means_lr)
        self.lr_scale = 1.0
        self.recoveries: list[dict] = []
        self._snapshot: dict | None = None
        self.curve: list[dict] = []  # test metrics every train.eval_every steps (PSNR against time)
        self.initial: dict | None = None
        self.n_before_compaction: int | None = None
        self._stop = False
        self._ema = {}
        # host reads every train.sync_every steps (train_step): the deferred steps' records, the end of the
        # running phase (None: outside train(), every step reads), the guard's statistic on the device
        self._pending: list[tuple[int, int, torch.Tensor]] = []
        self._phase_end: int | None = None
        self._window: LossWindow | None = None
        self.saved_step: int | None = None  # the step of the checkpoint last written or read (messages)
        self.in_phase = False  # inside train()'s loop: a checkpoint written now is in the middle of a phase
        self.resumed = False  # a checkpoint of the middle of a phase was loaded: the next train() continues it
        self.compact_report: dict | None = None
        self.stopped_early: dict | None = None  # set by the caller when training stopped before the end
        self.reserved_steps = 0  # compact mode: the last steps, taken by the search's fine-tunes (warpgs/compact.py)
        # stages above training (compact mode, warpgs/compact.py): objects with ``before_evaluation(trainer)``
        # that ``finish`` calls in order, after training and before the test metrics. They are attached by
        # whoever builds the trainer (warpgs.pipelines.sparse.make_trainer), so this module imports none of them.
        self.stages: list = []
        # Binocular3DGS's binocular consistency (train.binocular; warpgs/binocular.py): a moved render a step from
        # train.binocular_start x the run on. Its opacity decay (train.opacity_decay) is decay_opacities
        self.binocular = None
        if cfg.train.binocular > 0:
            from warpgs.binocular import Binocular

            tc = cfg.train
            path = None
            if tc.binocular_partner == "path":  # poses of the capture path next to each input (warpgs/binocular.py)
                from warpgs.clearance import path_partners

                path = path_partners(np.stack([c.viewmat for c in scene.train]), [c.name for c in scene.train],
                                     cfg.pseudo.trajectory.order, tc.binocular_reach)
            self.binocular = Binocular(tc.binocular, tc.binocular_shift, int(tc.binocular_start * tc.iterations),
                                       tc.binocular_smooth, self.device, seed, path=path, axes=tc.binocular_axes)
        # the two inputs' agreement at a pose of the path (train.path_consistency; warpgs/pathconsistency.py)
        self.path_consistency = None
        if cfg.train.path_consistency > 0 and len(scene.train) >= 2:
            from warpgs.pathconsistency import PathConsistency

            tc = cfg.train
            self.path_consistency = PathConsistency(tc.path_consistency, int(tc.path_consistency_start * tc.iterations),
                                                    scene.train, cfg.pseudo.trajectory.n_frames,
                                                    cfg.pseudo.trajectory.order, seed, self.device)
        # CoR-GS (train.co_reg): the second model of the co-regularised pair, its optimiser and strategy
        self.pair = None
        if cfg.train.co_reg:
            from warpgs.coreg import CoRegPair

            self.pair = CoRegPair(self)
        self.method = method if method is not None else Method()
        self.method.attach(self)
        # train.cuda_graph: deferred steps replayed as one CUDA graph (warpgs/graphstep.py)
        self.graph = None
        if self.device.type == "cuda" and cfg.train.cuda_graph and cfg.train.guard_kernels:
            from warpgs.graphstep import StepGraph

            self.graph = StepGraph(self)

    # ------------------------------------------------------------------------------------------
    # training

    def run(self) -> None:
        """Trains (or resumes) to ``train.iterations`` steps, phase by phase as the method runs them."""
        self.method.run()

    @property
    def total_steps(self) -> int:
        return self.cfg.train.iterations - self.reserved_steps

    @property
    def optimizers(self) -> list[torch.optim.Optimizer]:
        """The optimisers of the models being trained: the model's, then (``train.co_reg``) its partner's."""
        return [self.optimizer] + ([self.pair.optimizer] if self.pair is not None else [])

    def trained_parameters(self) -> dict[str, torch.Tensor]:
        """The parameters being trained, by name: the model's, then (``train.co_reg``) its partner's as
        ``partner.<name>``. The divergence guard checks them all."""
        params = dict(self.model.params)
        if self.pair is not None:
            params.update({f"partner.{k}": v for k, v in self.pair.model.params.items()})
        return params

    def means_lr(self, step: int) -> float:
        """The means' learning rate: exponential decay over the running schedule, from ``phase_start``
        over ``phase_len`` steps (None: ``optim.means_lr_decay_steps``, else the whole run)."""
        o = self.cfg.optim
        n = self.phase_len or o.means_lr_decay_steps or self.total_steps
        t = min(max((step - self.phase_start) / max(n, 1), 0.0), 1.0)
        return self.scene_scale * math.exp((1 - t) * math.log(o.means_lr) + t * math.log(o.means_lr_final))

    def next_view(self) -> int:
        if not self.order:
            self.order = self.view_rng.permutation(len(self.train_cams)).tolist()
        return self.order.pop()

    def compute_loss(self, out, cam) -> tuple[torch.Tensor, dict]:
        """The training loss of the render ``out`` of the input view ``cam``: the inputs' (``input_loss``) and
        the method's terms (``Method.loss_terms``); (loss, its parts by name)."""
        loss, parts = self.input_loss(out, cam)
        loss = self.parameter_priors(self.model, loss, parts)
        return self.method.loss_terms(out, cam, loss, parts), parts

    def input_loss(self, out, cam) -> tuple[torch.Tensor, dict]:
        """The loss of a render ``out`` of the input view ``cam`` against it: w1 L1 + w2 D-SSIM, and the alpha
        and depth-prior terms where they are on (``loss.*``); its parts by name, the whole as ``inputs``."""
        lc = self.cfg.loss
        l1 = losses.l1(out.image, cam.image)
        loss = lc.l1_weight * l1
        parts = {"l1": l1}
        if lc.ssim_weight > 0:
            ds = losses.dssim(out.image, cam.image)
            loss = loss + lc.ssim_weight * ds
            parts["dssim"] = ds
        if lc.alpha_weight > 0 and cam.alpha is not None:
            al = (out.alpha - cam.alpha).abs().mean()
            loss = loss + lc.alpha_weight * al
            parts["alpha"] = al
        if lc.depth_weight > 0 and lc.depth_prior == "scene" and cam.depth is not None:
            dl = losses.pearson_depth_loss(out.depth, cam.depth)
            loss = loss + lc.depth_weight * dl
            parts["depth"] = dl
        # what the divergence guard judges: the inputs' loss, which the method's terms (extra views, priors
        # that appear in a later phase) and the priors on the parameters leave out
        parts["inputs"] = loss
        if self.cfg.train.alpha_binary > 0:
            ab = (out.alpha * (1 - out.alpha)).mean()
            loss = loss + self.cfg.train.alpha_binary * ab
            parts["alpha_binary"] = ab
        return loss, parts

    def parameter_priors(self, model: GaussianModel, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        """``loss`` plus the priors on ``model``'s parameters that are on (``train.scale_reg``: the scale
        anisotropy term), each recorded in ``parts``; the divergence guard's ``inputs`` part leaves them out."""
        tc = self.cfg.train
        if tc.scale_reg > 0:
            sr = losses.scale_anisotropy_loss(model.params["scales"], tc.scale_reg_ratio)
            loss = loss + tc.scale_reg * sr
            parts["scale_reg"] = sr
        return loss

    def fit_far_field(self, kind: str, geo=None):
        """``make_far_field`` of ``kind`` on the training views, with the initial points for
        ``train.far_field_proxy``; its choice in one line when something was chosen."""
        tc = self.cfg.train
        points = None if geo is None or not len(geo.xyz) else geo.xyz
        t0 = time.perf_counter()
        ff = make_far_field(kind, self.train_cams, tc.far_field_bins, self.background, tc.far_field_blur,
                            tc.far_field_proxy, points)
        took = time.perf_counter() - t0
        if ff is not None:  # the run's per-stage timings (metrics.json stage_times_s far_field_s)
            self.far_field_time = getattr(self, "far_field_time", 0.0) + took
        if ff is not None and (tc.far_field_blur == "auto" or ff.proxy):
            self.log(f"warpgs: {ff.describe()} ({took:.1f} s)")
        return ff

    def background_for(self, cam, keep: bool = True) -> torch.Tensor:
        """What ``cam`` (anything with viewmat, K, width, height) sees behind the Gaussians: the far field's
        [H, W, 3] image when ``train.far_field`` is on, else the [3] ``background`` colour. The image is kept
        for the next render of the same camera (``FarFieldImages``) unless ``keep`` is False (a one-off pose)."""
        if self.far_field is None:
            return self.background
        return self._far_images.image(self.far_field, cam, keep)

    def with_training_background(self, cam, generator: torch.Generator):
        """(camera, background) for one training step: with ``train.random_background`` and an alpha
        channel, a random colour from ``generator`` and the target composited over it; else as they are."""
        if not (self.cfg.train.random_background and cam.alpha is not None):
            return cam, self.background_for(cam)
        # target over a random colour: image = rgb a + bg (1 - a)  ->  image + (1 - a) (new_bg - bg)
        bg = torch.rand(3, device=self.device, generator=generator)
        return dataclasses.replace(cam, image=cam.image + (1 - cam.alpha)[..., None] * (bg - self.background)), bg

    def train_step(self) -> dict:
        """One iteration at ``self.step`` (does not advance it). On a divergence that a recovery handles it
        rolls back (``self.step`` becomes the snapshot's) and returns ``{"rolled_back": 1, ...}``.

        A step that reads its verdict on the host (``_sync_due``: every ``train.sync_every`` steps, and
        before snapshots, checkpoints, evaluations and the end of a phase) first replays the verdicts of the
        steps deferred before it, then judges itself as the guard says. A deferred step judges itself on
        the device and makes or skips its update there (``_deferred_step``). Either way a non-finite or
        exploding step's gradient never reaches the parameters."""
        step = self.step
        self.model.active_sh_degree = min(step // max(self.cfg.train.sh_degree_interval, 1), self.model.max_sh_degree)
        lr = self.means_lr(step) * self.lr_scale
        for opt in self.optimizers:
            opt.set_lr("means", lr)
        cam = self.train_cams[self.next_view()]
        if self.graph is not None and not self._sync_due(step) and self.graph.covers(step, cam):
            info = self.graph.step(step, cam)  # the deferred step below as one CUDA graph (warpgs.graphstep)
            if info is not None:
                return info
        cam, bg = self.with_training_background(cam, self.split_gen)
        out, loss, inputs = self.forward_backward(step, cam, bg)
        if not self._sync_due(step):
            return self._deferred_step(step, loss, inputs, out, cam)
        record = self._step_record(loss, inputs)
        with torch.no_grad():
            record[_MSE] = ((out.image.detach().clamp(0, 1) - cam.image) ** 2).mean()
        rolled_back, row = self._resolve(record)  # the one host read of the step, with the deferred steps'
        if rolled_back is not None:
            return rolled_back
        value = row[_VALUE]
        if not all(row[_LOSS_FINITE:_EXPLODING]):
            return self._skip(step, self._nonfinite_cause(row))
        exploding = self.guard.exploding(value, self.losses)
        if exploding:
            if self.guard.exploded():
                return self._diverge(step, f"{self.guard.explode_steps} consecutive steps with an exploding loss "
                                           f"(the last: {exploding})")
            return self._skip(step, exploding)
        for opt in self.optimizers:
            opt.step()
            opt.zero_grad(set_to_none=True)
        self.decay_opacities(step)
        self.guard.healthy()
        info = self._after_update(step, out, cam)
        bad = self.nonfinite_parameters()
        if bad:
            return self._diverge(step, f"the parameters {', '.join(bad)} are not finite after the optimiser step")
        self.losses.append(value)
        if self._window is not None:
            self._window.push(step, value)
        every = self.cfg.train.snapshot_every
        if every and (step + 1) % every == 0:
            self.take_snapshot(step + 1)
        return {"loss": value, "psnr": -10 * math.log10(max(row[_MSE], 1e-10)), **info}

    def forward_backward(self, step: int, cam, bg, isect_capacity: int | None = None):
        """Step ``step``'s render of the view ``cam`` over ``bg``, its loss (``compute_loss``, and the co-regularised
        partner's) and the backward pass; returns (the render, the loss, the input views' loss), both detached.
        ``isect_capacity``: the render's fixed-capacity buffers (``rasterize``; a CUDA graph of the step)."""
        # no input checks in the rasterizer (each is a host read): the guard checks the loss, the gradients and
        # the parameters, and a step with non-finite ones makes no update
        out = self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg,
                                opacity_scale=self.opacity_scale(step), check_finite=False,
                                isect_capacity=isect_capacity)
        loss, parts = self.compute_loss(out, cam)
        if self.binocular_active(step):
            loss = loss + self.binocular.loss(self.model, out, cam, bg, parts)
        if self.path_consistency_active(step):
            loss = loss + self.path_consistency.loss(self.model, self.train_cams, self.background,
                                                     self.opacity_scale(step), parts)
        if self.pair is not None:  # its partner on the same view, and the two co-regularised (one backward for both)
            loss = loss + self.pair.loss(step, cam, bg, parts)
        loss.backward()
        # the guard judges the input views' loss: extra views (the full method's pseudo views) change what is
        # optimised and can be far off at first without anything diverging
        return out, loss.detach(), parts.get("inputs", loss).detach()

    def _after_update(self, step: int, out, cam, apply: torch.Tensor | None = None) -> dict:
        """What follows a step's update: densification (``densify``), the co-regularised partner's and the
        co-pruning (``train.co_reg``), and a new statistic after an opacity reset (whose jump in the loss is
        expected). ``apply``: a deferred step's verdict (``out``'s radii are already masked with it)."""
        info = self.densify(self.strategy, self.model, self.optimizer, self.state, step, out, cam, self.split_gen)
        if self.pair is not None:
            info["co_pruned"] = self.pair.after_update(step, cam, apply)
        if info.get("reset"):
            self._restart_statistic(step + 1)
        return info

    def densify_only_updates_state(self, step: int) -> bool:
        """Whether ``densify`` at ``step`` does no more than the strategy's ``update_state`` (no growth, pruning,
        reset, nor pruning on the camera path): such a step can be part of a CUDA graph (``warpgs.graphstep``)."""
        s = self.strategy
        only = getattr(s, "only_updates_state", None)
        return (only is not None and only(step)
                and not (self.clearance is not None and step % s.refine_every == 0)
                and not self._floaters_due(step))

    def _floaters_due(self, step: int) -> bool:
        """Whether ``densify`` at ``step`` removes the camera path's floaters (``train.path_floaters``)."""
        return self.floaters is not None and step > 0 and step % self.cfg.train.path_floaters_every == 0

    def densify(self, strategy, model: GaussianModel, optimizer, state: dict, step: int, out, cam,
                generator: torch.Generator) -> dict:
        """The strategy's densification of ``model`` after step ``step``'s update (``out``: its render of the
        view ``cam``), and pruning the unseen when it finds the budget spent; returns what changed."""
        info = strategy.step_post_backward(model, optimizer, state, step, out, cam.width, cam.height,
                                           self.scene_scale, generator=generator)
        s = strategy
        if self.clearance is not None and step % s.refine_every == 0 and model is self.model:
            on_path = self.clearance.inside(model.means)
            n = int(on_path.sum())
            if 0 < n < len(model):
                from warpgs.strategy import remove

                remove(model, optimizer, state, on_path)
                info["pruned_on_path"] = n
        if self._floaters_due(step) and model is self.model:
            info["pruned_floaters"] = self.remove_path_floaters(step)
        if (s.prune_unseen_when_full and s.max_gaussians > 0 and (info["cloned"] or info["split"] or info["pruned"])
                and len(model) >= s.max_gaussians):
            # the budget is spent: free what the training views do not use, so growth can go on where it helps
            info["pruned_unseen"] = s.prune_unseen(model, optimizer, state, self.train_cams, self.background)
        return info

    def drop_rate_at(self, step: int) -> float:
        """DropGaussian's rate at ``step``: ``train.drop_rate`` x step / iterations."""
        return self.drop_rate * min(step / max(self.total_steps, 1), 1.0)

    def drop_rate_tensors(self, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        """(rate, 1 - rate) at ``step`` as float32 scalars on the device, which the dropout reads, so that a CUDA
        graph of the step (``warpgs.graphstep``) draws at each replay's rate: they are filled here, except while
        a graph records (its replays read what ``StepGraph.step`` filled before each one)."""
        if not (self.device.type == "cuda" and torch.cuda.is_current_stream_capturing()):
            rate = self.drop_rate_at(step)
            self._drop_t[0].fill_(rate)
            self._drop_t[1].fill_(1.0 - rate)
        return self._drop_t

    def dropout_scale(self, step: int, model: GaussianModel | None = None,
                      generator: torch.Generator | None = None) -> torch.Tensor | None:
        """DropGaussian's factors for one training render of ``model`` (default: the trainer's) at ``step``: 0
        for a Gaussian dropped at the rate ``train.drop_rate`` x step / iterations, 1 / (1 - rate) for the
        others, drawn from ``generator`` (default: ``drop_gen``); None when off. The rate is read from the
        device (``drop_rate_tensors``; in float32, as a Python number would be: the same factors)."""
        if self.drop_rate_at(step) <= 0:
            return None
        n = len(model if model is not None else self.model)
        rate, keep_fraction = self.drop_rate_tensors(step)
        keep = torch.rand(n, device=self.device, generator=generator or self.drop_gen) >= rate
        return keep.float() / keep_fraction

    def opacity_scale(self, step: int, model: GaussianModel | None = None,
                      generator: torch.Generator | None = None) -> torch.Tensor | None:
        """The per-Gaussian opacity factors of one training render at ``step`` (evaluation renders use none):
        DropGaussian's (``dropout_scale``) times Co-Adaptation's opacity noise (``train.opacity_noise`` = sigma:
        1 + eps, eps ~ N(0, sigma^2) clipped to [-sigma, sigma] as in the authors' code). Both come from
        ``drop_gen``, the mask first, so a run without noise draws exactly what it drew before. None when
        both are off. The rasterizer caps alpha at ``alpha_max`` where a factor above 1 would pass it.
        ``model`` and ``generator`` as in ``dropout_scale`` (the co-regularised pair's second model)."""
        model = model if model is not None else self.model
        generator = generator or self.drop_gen
        scale = self.dropout_scale(step, model, generator)
        sigma = self.cfg.train.opacity_noise
        if sigma <= 0:
            return scale
        eps = torch.randn(len(model), device=self.device, generator=generator) * sigma
        noise = 1.0 + eps.clamp(-sigma, sigma)
        return noise if scale is None else scale * noise

    def opacity_scale_bound(self, step: int) -> float | None:
        """The largest factor ``opacity_scale`` can put on an opacity at ``step`` (None when it puts none): the
        projection's screen box grows with the opacity, so counting tile intersections on opacities scaled by it
        bounds what the step's render emits (a CUDA graph's fixed-capacity buffers, ``warpgs.graphstep``)."""
        rate, sigma = self.drop_rate_at(step), self.cfg.train.opacity_noise
        if rate <= 0 and sigma <= 0:
            return None
        return (1.0 + max(sigma, 0.0)) / (1.0 - max(rate, 0.0)) * (1.0 + 1e-5)

    def _skip(self, step: int, why: str) -> dict:
        """A step judged on the host that makes no update."""
        for opt in self.optimizers:
            opt.zero_grad(set_to_none=True)
        result = self._skipped(step, why)
        if self._window is not None and not result.get("rolled_back"):
            self._window.push(step, float("nan"))
        return result

    def _skipped(self, step: int, why: str) -> dict:
        """Counts a step that made no update: the log line, the guard's count (a divergence when it is the
        ``train.max_nan_steps``-th in a row), a NaN loss."""
        self.log(f"warpgs: step {step} skipped: {why}")
        if self.guard.skipped():
            return self._diverge(step, f"{self.guard.nan_steps} consecutive steps without a usable loss and gradient "
                                       f"(the last: {why})")
        self.losses.append(float("nan"))
        return {"loss": float("nan"), "psnr": float("nan"), "skipped": 1}

    # ------------------------------------------------------------------------------------------
    # host reads (train.sync_every): deferred verdicts

    @property
    def sync_every(self) -> int:
        """Steps between host reads of the verdicts (``train.sync_every``; None: ``SYNC_EVERY_CUDA`` on CUDA,
        every step on the CPU, where a read costs nothing)."""
        n = self.cfg.train.sync_every
        if n is None:
            n = SYNC_EVERY_CUDA if self.device.type == "cuda" else 1
        return max(int(n), 1)

    def _sync_due(self, step: int) -> bool:
        """Whether step ``step`` reads the verdicts on the host: every ``sync_every`` steps, and where what comes
        after the step needs them all (a snapshot, a checkpoint, an evaluation, the end of the phase, a stop).
        Outside ``train()`` every step does."""
        every, end = self.sync_every, self._phase_end
        if every <= 1 or end is None:
            return True
        n, tc = step + 1, self.cfg.train
        return (n % every == 0 or n >= end or self._stop
                or any(k and n % k == 0 for k in (tc.snapshot_every, tc.checkpoint_every, tc.eval_every)))

    def _step_record(self, loss: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        """A step's record, float64 on the device: [the input views' loss, whether the loss and each
        parameter's gradient are finite (1 / 0), exploding (a deferred verdict's), the render's MSE (where
        read)]."""
        flags = finite_flags(self._guarded_tensors(loss))
        record = torch.zeros(len(flags) + 3, dtype=torch.float64, device=loss.device)
        record[_VALUE] = inputs
        record[_LOSS_FINITE:_EXPLODING] = flags
        return record

    def _guarded_tensors(self, loss: torch.Tensor) -> list[torch.Tensor]:
        """What must be finite for a step to make its update: the loss and each trained parameter's gradient
        (a zero for one without)."""
        grads = [p.grad for p in self.trained_parameters().values()]
        if any(g is None for g in grads):
            zero = loss.new_zeros(())
            grads = [zero if g is None else g for g in grads]
        return [loss] + grads

    def _nonfinite_cause(self, row: list[float]) -> str:
        if not row[_LOSS_FINITE]:
            return "the loss is not finite"
        bad = [n for n, ok in zip(self.trained_parameters(), row[_LOSS_FINITE + 1:_EXPLODING]) if not ok]
        return f"the gradient of {', '.join(bad)} is not finite"

    def _deferred_step(self, step: int, loss: torch.Tensor, inputs: torch.Tensor, out, cam) -> dict:
        """A step whose verdict the host reads later: the guard's verdict on the device (non-finite, or an
        exploding loss against ``LossWindow``, which gets the step's entry; ``DivergenceGuard.step_on_device``
        with ``train.guard_kernels``, else ``_deferred_verdict``), the update made or skipped there
        (``masked_step``), and only a step that made its update counts in the densification statistics. The
        record waits in ``_pending`` for the next read (``_resolve``)."""
        record, apply = self.update_on_device(step, loss, inputs)
        self._pending.append((step, self.guard.stat_start, record))
        # a step without its update is one in which no Gaussian was seen, for the densification statistics
        return self._after_update(step, out._replace(radii=out.radii * apply), cam, apply)

    def update_on_device(self, step: int | None, loss: torch.Tensor, inputs: torch.Tensor):
        """A deferred step's verdict and its update, made or skipped on the device (``masked_step``); returns
        (the step's record, whether the update applies). ``step`` None: the guard kernels' window slot was set
        beforehand (a CUDA graph's replay, ``warpgs.graphstep``, which needs ``train.guard_kernels``)."""
        if self.cfg.train.guard_kernels:
            window = self._window if step is None else self._loss_window(step)
            record, apply, found_inf = self.guard.step_on_device(self._guarded_tensors(loss), inputs, window, step)
        else:
            record, apply, found_inf = self._deferred_verdict(step, loss, inputs)
        for opt in self.optimizers:
            masked_step(opt, apply, found_inf)
            opt.zero_grad(set_to_none=True)
        self.decay_opacities(self.step if step is None else step)
        return record, apply

    def path_consistency_active(self, step: int) -> bool:
        """Whether ``train.path_consistency`` adds its term to the loss of ``step``."""
        return self.path_consistency is not None and self.path_consistency.active(step)

    def binocular_active(self, step: int) -> bool:
        """Whether ``train.binocular`` adds its term to the loss of ``step`` (from ``train.binocular_start`` on)."""
        return self.binocular is not None and self.binocular.active(step)

    def decay_active(self, step: int) -> bool:
        """Whether ``train.opacity_decay`` acts after the update of ``step``: from ``strategy.refine_start_iter`` on."""
        return self.cfg.train.opacity_decay > 0 and step >= self.strategy.refine_start_iter

    def decay_opacities(self, step: int) -> None:
        """Binocular3DGS's opacity decay after the update of ``step`` (``train.opacity_decay``): every opacity x
        (1 - rate), on the logits the model holds (device ops only: a CUDA graph of the step holds them)."""
        if not self.decay_active(step):
            return
        with torch.no_grad():
            o = self.model.params["opacities"]
            o.copy_(torch.logit(torch.sigmoid(o) * (1.0 - self.cfg.train.opacity_decay), eps=1e-6))

    def _deferred_verdict(self, step: int, loss: torch.Tensor, inputs: torch.Tensor):
        """``DivergenceGuard.step_on_device``'s results from torch ops (record, apply, found_inf): the step's
        record, its verdict on the device and its entry in the loss window."""
        record = self._step_record(loss, inputs)
        value = record[_VALUE]
        finite = record[_LOSS_FINITE:_EXPLODING].all()
        exploding = finite & self.guard.exploding_on_device(value, self._loss_window(step))
        apply = finite & ~exploding
        record[_EXPLODING] = exploding
        self._window.push(step, torch.where(apply, value, float("inf")))
        return record, apply, (~apply).to(torch.float32)  # one flag for every optimiser (fused Adam's skip)

    def _loss_window(self, step: int):
        if self._window is None:  # after a new statistic: from the host's losses (none, at a phase's start)
            self._window = LossWindow(self.cfg.train.explode_window, self.device)
            self._window.rebuild(self.losses, self.guard.stat_start, step)
        return self._window

    def _restart_statistic(self, step: int) -> None:
        """The exploding-loss statistic starts again at ``step`` (``DivergenceGuard.restart``), on the device too."""
        self.guard.restart(step)
        self._window = None

    def _resolve(self, record: torch.Tensor | None = None) -> tuple[dict | None, list[float] | None]:
        """The host read: the deferred steps' records, ``record`` (the reading step's own, if given) and, after
        deferred steps, the parameters' flags, in one transfer. Replays the deferred verdicts (``_replay``); the
        parameters must be finite after their updates. Returns (the rollback's result when they diverged, else
        None; ``record`` as a list)."""
        pending, self._pending = self._pending, []
        parts = [r for _, _, r in pending] + ([record] if record is not None else [])
        if not parts:
            return None, None
        if pending:
            parts.append(self._parameter_flags().double())
        values = torch.cat(parts).tolist()
        w = parts[0].numel()
        rows = [values[i * w:(i + 1) * w] for i in range(len(pending) + (record is not None))]
        if pending:
            result = self._replay(pending, rows[:len(pending)])
            if result is None:
                bad = [n for n, ok in zip(self.trained_parameters(), values[len(rows) * w:]) if not ok]
                if bad:
                    first, last = pending[0][0], pending[-1][0]
                    result = self._diverge(last, f"the parameters {', '.join(bad)} are not finite after the optimiser "
                                                 f"step (of one of steps {first}-{last}, read at step {last + 1})")
            if result is not None:
                return result, None
        return None, (rows[-1] if record is not None else None)

    def _replay(self, pending: list, rows: list[list[float]]) -> dict | None:
        """The host's part of the deferred verdicts, in order (their updates were made or skipped on the device):
        the log lines, the guard's counts and ``max_loss_ratio``, the losses. A divergence rolls back at the
        step it happened (its result is returned; the later steps are undone with it)."""
        latest = self.guard.stat_start
        for (k, stat_start, _), row in zip(pending, rows):
            if len(self.losses) != k:
                raise RuntimeError(f"warpgs: internal error: {len(self.losses)} losses recorded before step {k}")
            self.guard.stat_start = stat_start  # the statistic as it was at that step
            value = row[_VALUE]
            if not all(row[_LOSS_FINITE:_EXPLODING]):
                result = self._skipped(k, self._nonfinite_cause(row))
            else:
                why = self.guard.exploding(value, self.losses)  # the same verdict, with its numbers
                if not row[_EXPLODING]:
                    self.guard.healthy()
                    self.losses.append(value)
                    continue
                why = why or f"the loss {value:.4g} is above train.explode_factor x the running median"
                if self.guard.exploded():
                    return self._diverge(k, f"{self.guard.explode_steps} consecutive steps with an exploding loss "
                                            f"(the last: {why})")
                result = self._skipped(k, why)
            if result.get("rolled_back"):
                return result
        self.guard.stat_start = latest
        return None

    def _abandon_pending(self) -> None:
        """Training left by an exception between host reads: the deferred steps' losses go into the history as
        the device judged them (NaN where the update was skipped), and nothing else is acted on."""
        pending, self._pending = self._pending, []
        try:
            rows = torch.stack([r for _, _, r in pending]).tolist()
        except Exception:  # noqa: BLE001 - the device may be what failed
            rows = [None] * len(pending)
        for row in rows:
            ok = row is not None and all(row[_LOSS_FINITE:_EXPLODING]) and not row[_EXPLODING]
            self.losses.append(row[_VALUE] if ok else float("nan"))
        self._window = None

    # ------------------------------------------------------------------------------------------
    # divergence: exploding losses, snapshots of the last good state, rollback

    def nonfinite_parameters(self) -> list[str]:
        """Names of the parameters that are not finite, or whose value as rendered is not (a log-scale
        above ~88 is an infinite scale, which the rasterizer refuses); one device sync."""
        flags = self._parameter_flags().tolist()
        return [n for n, ok in zip(self.trained_parameters(), flags) if not ok]

    def _parameter_flags(self) -> torch.Tensor:
        """Per parameter (in ``trained_parameters``' order), on the device: whether it is finite, as stored and
        as rendered."""
        p = self.trained_parameters()
        flags = finite_flags([t.detach() for t in p.values()])
        for i, (name, t) in enumerate(p.items()):
            if name.rsplit(".", 1)[-1] == "scales":
                flags[i] = flags[i] & torch.isfinite(torch.exp(t.detach())).all()
        return flags

    def state_is_finite(self) -> bool:
        """Whether the parameters (as rendered), the optimisers' moments and the densification statistics
        are all finite."""
        tensors = list(self.state.values()) + (list(self.pair.state.values()) if self.pair is not None else [])
        for opt in self.optimizers:
            for st in opt.state.values():
                tensors += [v for v in st.values() if isinstance(v, torch.Tensor)]
        return not self.nonfinite_parameters() and _all_finite(tensors)

    # ------------------------------------------------------------------------------------------
    # the training state: one serialisation for checkpoints, rollback snapshots and compact mode

    def state_dict(self, parts=STATE_PARTS, device="cpu") -> dict:
        """A copy of the training state (its tensors on ``device``: the CPU but for the snapshots of
        ``take_snapshot``), in ``parts`` (module docstring):

        - ``model``: the parameters (and SH degrees), Adam's moments, the densification statistics;
        - ``progress``: the step, the RNGs, the view order, where the guard's statistic starts, whether this is
          the middle of a phase (a resume continues that phase's statistic);
        - ``history``: training time, losses, learning-rate scale, recoveries, curve, initial metrics,
          the running learning-rate schedule, the guard's largest loss ratio (metrics.json's ``max_loss_ratio``);

        and the method's share of each (``Method.state_dict``) under ``method``, the co-regularised pair's second
        model's (``train.co_reg``; ``warpgs.coreg.CoRegPair.state_dict``) under ``pair``."""
        st: dict = {"parts": list(parts)}
        if "model" in parts:
            st.update(model_state(self.model, self.optimizer, self.state, device))
        if "progress" in parts:
            if self.binocular is not None:
                st["binocular_gen"] = self.binocular.gen.get_state()
            if self.path_consistency is not None:
                st["path_consistency_rng"] = copy.deepcopy(self.path_consistency.rng.bit_generator.state)
            st.update(step=self.step, split_gen=self.split_gen.get_state(), drop_gen=self.drop_gen.get_state(),
                      view_rng=copy.deepcopy(self.view_rng.bit_generator.state), order=list(self.order),
                      torch_rng=torch.get_rng_state(), stat_start=self.guard.stat_start, in_phase=self.in_phase)
        if "history" in parts:
            st.update(train_time=self.train_time, losses=list(self.losses), lr_scale=self.lr_scale,
                      recoveries=copy.deepcopy(self.recoveries), curve=copy.deepcopy(self.curve),
                      initial=copy.deepcopy(self.initial), n_before_compaction=self.n_before_compaction,
                      phase=(self.phase_start, self.phase_len), max_loss_ratio=self.guard.max_loss_ratio)
        st["method"] = self.method.state_dict(parts)
        if self.pair is not None:
            st["pair"] = self.pair.state_dict(parts, device)
        return st

    def load_state_dict(self, st: dict) -> None:
        """Puts back the parts ``st`` holds (copies of them: ``st`` stays usable). The model object stays
        (the strategy may hold it); with ``progress`` the learning rates are set for the restored step and
        learning-rate scale, else they are as saved in the optimiser's state."""
        parts = st.get("parts", STATE_PARTS)
        self._window = None  # the guard's statistic on the device: rebuilt from the restored losses
        if "model" in parts:
            self.optimizer, self.state = load_model_state(st, self.model, self.cfg, self.scene_scale, self.device)
        if "history" in parts:
            self.train_time = float(st["train_time"])
            self.losses = list(st["losses"])
            self.lr_scale = float(st.get("lr_scale", 1.0))
            self.recoveries = copy.deepcopy(st.get("recoveries", []))
            self.curve = copy.deepcopy(st.get("curve", []))
            self.initial = copy.deepcopy(st.get("initial"))
            self.n_before_compaction = st.get("n_before_compaction")
            if "phase" in st:
                self.phase_start, self.phase_len = st["phase"]
            self.guard.max_loss_ratio = float(st.get("max_loss_ratio", self.guard.max_loss_ratio))
        if "progress" in parts:
            self.step = int(st["step"])
            self.split_gen.set_state(st["split_gen"])
            if "drop_gen" in st:
                self.drop_gen.set_state(st["drop_gen"])
            if self.binocular is not None and "binocular_gen" in st:
                self.binocular.gen.set_state(st["binocular_gen"])
            if self.path_consistency is not None and "path_consistency_rng" in st:
                self.path_consistency.rng.bit_generator.state = copy.deepcopy(st["path_consistency_rng"])
            self.view_rng.bit_generator.state = copy.deepcopy(st["view_rng"])
            self.order = list(st["order"])
            torch.set_rng_state(st["torch_rng"])
            if "stat_start" in st:
                self.guard.stat_start = st["stat_start"]
        if self.pair is not None:
            self.pair.load_state_dict(st.get("pair"), parts)
        if "progress" in parts:
            self.apply_lr_scale()
        self.method.load_state_dict(st.get("method", {}))

    def take_snapshot(self, step: int | None = None) -> bool:
        """Keeps the current ``model`` and ``progress`` in memory as the last good state, if it is all finite;
        returns whether it did. On CUDA with ``train.snapshot_on_device`` (default) the copy stays in GPU memory
        (the training state once more; a copy there takes microseconds, where one to the CPU stops the host
        for each transfer: about 160 MB every 100 steps for 225,000 Gaussians), else it goes to the CPU."""
        if not self.state_is_finite():
            return False
        on_device = self.device.type == "cuda" and self.cfg.train.snapshot_on_device
        self._snapshot = None  # the old copy goes first: at most one extra copy of the state at a time
        try:
            self._snapshot = self.state_dict(("model", "progress"), device=self.device if on_device else "cpu")
        except torch.cuda.OutOfMemoryError:  # no room for a second copy on the GPU: this one goes to the CPU
            self._snapshot = self.state_dict(("model", "progress"))
        if step is not None:
            self._snapshot["step"] = step
        return True

    def restore_snapshot(self) -> int:
        """Puts the last good state back (the learning-rate scale stays as it is now; the losses and curve
        after its step go); returns its step."""
        self.load_state_dict(self._snapshot)
        del self.losses[self.step:]
        self.curve = [row for row in self.curve if row["step"] <= self.step]
        self._restart_statistic(self._snapshot["stat_start"])
        self.guard.healthy()
        return self.step

    def after_out_of_memory(self) -> int | None:
        """After the device ran out of memory in a step (another process took it, or the model outgrew it):
        drops the step's gradients and the step graph, frees the allocator's cache and puts the last good state
        back; returns its step, or None when there is none (the model then stays as the failed step left it)."""
        for opt in self.optimizers:
            opt.zero_grad(set_to_none=True)
        self.graph = None  # a capture or replay cut short is not replayed again
        if self.device.type == "cuda":
            torch.cuda.empty_cache()
        if self._snapshot is None:
            return None
        return self.restore_snapshot()

    def apply_lr_scale(self) -> None:
        """Sets every group's learning rate to its base rate x ``lr_scale`` (the means' is set each step)."""
        base = base_learning_rates(self.cfg, self.scene_scale)
        for opt in self.optimizers:
            for g in opt.param_groups:
                g["lr"] = (self.means_lr(self.step) if g["name"] == "means" else base[g["name"]]) * self.lr_scale

    def last_checkpoint(self) -> Path | None:
        path = self.out / CHECKPOINT if self.out is not None else None
        return path if path is not None and path.is_file() else None

    def _diverge(self, step: int, cause: str) -> dict:
        """A divergence at ``step``: rolls back to the last good state with lower learning rates, or, when
        ``train.max_recoveries`` are spent (or there is no good state), stops with ``TrainingDiverged``."""
        tc = self.cfg.train
        for opt in self.optimizers:
            opt.zero_grad(set_to_none=True)
        if self._snapshot is None or len(self.recoveries) >= tc.max_recoveries:
            if self._snapshot is not None:
                self.restore_snapshot()  # leave the model at the last good state, never at the diverged one
            ck = self.last_checkpoint()
            if self._snapshot is None:
                tried = "there was no finite state to roll back to"
            elif tc.max_recoveries <= 0:
                tried = "recovery is off (train.max_recoveries=0)"
            else:
                tried = (f"{len(self.recoveries)} recoveries (each a rollback to the last good state with the learning "
                         f"rates x{tc.recovery_lr_factor:g}, now x{self.lr_scale:g}) did not help")
            if ck is not None:
                saved = self.saved_step
                if saved is None:  # a file this trainer neither wrote nor read
                    try:
                        saved = read_checkpoint(ck).get("step")
                    except CheckpointError:
                        saved = "unreadable"
                where = f"The last good checkpoint is {ck} (step {saved}); it was not overwritten."
            else:
                where = ("No checkpoint was written before it "
                         f"({'no output folder' if self.out is None else f'train.checkpoint_every={tc.checkpoint_every}'}), "
                         "so there is nothing on disk to resume from.")
            raise TrainingDiverged(f"training diverged at step {step}: {cause}; {tried}. {where} Lower the learning "
                                   f"rates (--set optim.NAME_lr=...) or check the inputs (poses, images).",
                                   step=step, cause=cause, checkpoint=ck)
        self.lr_scale *= tc.recovery_lr_factor
        back_to = self.restore_snapshot()
        self.recoveries.append({"step": step, "cause": cause, "rolled_back_to": back_to, "lr_scale": self.lr_scale})
        self.log(f"warpgs: step {step}: {cause}; rolled back to step {back_to} (the last good state) with the learning "
                 f"rates x{self.lr_scale:g} (recovery {len(self.recoveries)} of {tc.max_recoveries})")
        return {"loss": float("nan"), "psnr": float("nan"), "rolled_back": 1}

    def train(self, iterations: int | None = None) -> None:
        """Trains until ``iterations`` (default ``train.iterations``) steps are done."""
        from tqdm import tqdm

        total = self.total_steps if iterations is None else iterations
        if self.initial is None and self.step == 0 and self.test_cams:
            self.initial = self.evaluate(save_dir=None, lpips=False)["mean"]
        # a new phase (the full method's cycles): its losses make their own statistic. A run resumed from the
        # middle of a phase continues that phase's statistic (stat_start came with the checkpoint), so it judges
        # every step as the uninterrupted run did. Either way this is a good state to come back to.
        if not self.resumed:
            self._restart_statistic(self.step)
        elif self.step < total:  # (a call with nothing to train, the full method's earlier phases, keeps it)
            self.resumed = False
        if not self.take_snapshot():  # e.g. what was added between phases is not finite: back to the last good state
            self._diverge(self.step, f"the model is not finite at the start of training (step {self.step}: "
                                     f"{', '.join(self.nonfinite_parameters()) or 'optimiser state'})")
        restore = self._install_sigint()
        bar = tqdm(total=total, initial=self.step, desc=f"{self.cfg.method} {self.scene.name}", unit="it",
                   dynamic_ncols=True, disable=not self.cfg.train.progress, file=sys.stderr)
        every = self.cfg.train.checkpoint_every
        ev_every = self.cfg.train.eval_every
        t0 = time.perf_counter()
        self._phase_end = total
        self.in_phase = True
        try:
            while self.step < total:
                info = self.train_step()
                if info.get("rolled_back"):
                    bar.n = self.step
                    bar.refresh()
                    continue
                self.step += 1
                bar.update(1)
                self._update_bar(bar, info)
                if self._stop:
                    if self._pending and self._resolve()[0] is not None:  # Ctrl-C during a deferred step: the
                        bar.n = self.step                                  # verdicts rolled back; that state is saved
                        bar.refresh()
                    self.train_time += time.perf_counter() - t0
                    t0 = time.perf_counter()
                    path = self.save_checkpoint()
                    raise TrainingInterrupted(self.step, path)
                if every and self.step % every == 0 and self.step < total:
                    self.train_time += time.perf_counter() - t0
                    t0 = time.perf_counter()
                    self.save_checkpoint()
                if ev_every and self.step % ev_every == 0 and self.test_cams:
                    self.train_time += time.perf_counter() - t0
                    self.record_curve()
                    t0 = time.perf_counter()
        finally:
            self._phase_end = None
            self.in_phase = False
            if self._pending:  # an exception between host reads
                self._abandon_pending()
            self.train_time += time.perf_counter() - t0
            bar.close()
            restore()

    def record_curve(self) -> dict:
        """Appends the test views' PSNR/SSIM now (training time so far, Gaussian count) to ``curve``;
        evaluation time is not counted as training time."""
        m = self.evaluate(save_dir=None, lpips=False)["mean"]
        row = {"step": self.step, "train_time_s": round(self.train_time, 3), "psnr": m["psnr"], "ssim": m["ssim"],
               "num_gaussians": len(self.model)}
        self.curve.append(row)
        return row

    def _update_bar(self, bar, info: dict) -> None:
        for k in ("loss", "psnr"):
            v = info.get(k)
            if v is not None and math.isfinite(v):
                self._ema[k] = v if k not in self._ema else 0.9 * self._ema[k] + 0.1 * v
        if self.step % 10 == 0 or self.step == 1:
            bar.set_postfix(loss=f"{self._ema.get('loss', float('nan')):.4f}",
                            psnr=f"{self._ema.get('psnr', float('nan')):.2f}", n=len(self.model), refresh=False)

    def request_stop(self) -> None:
        """Stop after the current step, saving a checkpoint (what Ctrl-C does)."""
        self._stop = True

    def _install_sigint(self):
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        previous = signal.getsignal(signal.SIGINT)

        def handler(signum, frame):
            if self._stop:  # second Ctrl-C: stop now; the last checkpoint on disk stays intact
                signal.signal(signal.SIGINT, signal.default_int_handler)
                raise KeyboardInterrupt
            self._stop = True
            self.log("\nwarpgs: Ctrl-C: finishing this step and saving a checkpoint (Ctrl-C again to stop at once)")

        signal.signal(signal.SIGINT, handler)
        return lambda: signal.signal(signal.SIGINT, previous)

    # ------------------------------------------------------------------------------------------
    # checkpoints

    def save_checkpoint(self, path: str | Path | None = None) -> Path | None:
        """Writes a checkpoint (atomically); returns its path, or None when there is no output folder or
        the state is not finite (a checkpoint is never written from a diverged state: the one on disk
        stays the last good one)."""
        if path is None:
            if self.out is None:
                return None
            path = self.out / CHECKPOINT
        path = Path(path)
        if not self.state_is_finite():
            self.log(f"warpgs: step {self.step}: the model or optimiser state is not finite; {path} is not written "
                     "(the checkpoint there, if any, is the last good one)")
            return None
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            _atomic_torch_save({"format": 2, "config": to_dict(self.requested_cfg), "scene": self.scene.name,
                                "method_name": self.method.name, **self.state_dict()}, path)
        except OSError as e:
            kept = (f"the last good checkpoint {path} (step {self.saved_step}) is intact" if path.is_file()
                    and self.saved_step is not None else f"{path} as it was is left untouched" if path.is_file()
                    else "no checkpoint was written before it")
            raise CheckpointError(f"{path}: cannot write the checkpoint of step {self.step} "
                                  f"({e.strerror or e}); {kept}") from None
        self.saved_step = self.step
        return path

    def load_checkpoint(self, path: str | Path | None = None) -> Path:
        """Restores the training state from ``path``, or (None) from the output folder's checkpoint, falling
        back to the previous one when it cannot be read (``resumable_checkpoint``); returns the file used.
        ``CheckpointError`` (one line) when there is none or none can be read."""
        if path is not None:
            path = Path(path)
            ck = read_checkpoint(path)
        else:
            found = resumable_checkpoint(self.out) if self.out is not None else None  # its note: once per process
            if found is None:
                raise CheckpointError(f"{self.out / CHECKPOINT if self.out else 'no output folder'}: "
                                      "no checkpoint to resume from")
            path, ck = found
        saved = config_from_dict(ck["config"], str(path))
        for section in ("model", "optim", "loss", "strategy"):
            if to_dict(getattr(saved, section)) != to_dict(getattr(self.requested_cfg, section)):
                self.log(f"warpgs: note: the checkpoint's {section} config differs from this run's; using this run's")
        if ck.get("format", 1) == 1:
            ck = _upgrade_format_1(ck, self.cfg.train.sh_degree_interval)
        if ck.get("pair") is not None and self.pair is None:
            self.log("warpgs: note: the checkpoint holds a co-regularised pair (train.co_reg); this run goes on with "
                     "its first model alone")
        try:
            self.load_state_dict(ck)
        except (KeyError, TypeError, ValueError, RuntimeError) as e:  # a file of another model or version
            raise CheckpointError(f"{path}: does not fit this run ({type(e).__name__}: "
                                  f"{str(e).splitlines()[0][:120] if str(e) else ''})") from None
        self.saved_step = self.step
        self.resumed = bool(ck.get("in_phase"))
        return path

    # ------------------------------------------------------------------------------------------
    # evaluation and outputs

    def render(self, cam):
        return self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=self.background_for(cam))

    def evaluate(self, cameras=None, save_dir: str | Path | None = None, lpips: bool = True) -> dict:
        """Metrics over ``cameras`` (default: the test views); ``warpgs.evaluation.evaluate_views``."""
        return evaluate_views(self.render, self.test_cams if cameras is None else cameras,
                              masked=bool(self.scene.eval_masked), scene_name=self.scene.name,
                              lpips_weights=self.cfg.eval.lpips_weights, device=self.device, save_dir=save_dir,
                              lpips=lpips)

    def remove_path_floaters(self, step: int) -> int:
        """``train.path_floaters``: removes the Gaussians that poses of the camera path see and no input does
        (``warpgs.clearance.PathFloaters``); returns how many. Runs on its schedule in ``densify`` and once more
        before the final evaluation."""
        if self.floaters is None:
            return 0
        t0 = time.perf_counter()
        found = self.floaters.find(self.model, self.train_cams, self.background)
        n = int(found.sum())  # a read of the device: the pass's work is done when it returns
        removing = 0 < n < len(self.model)
        if removing:
            from warpgs.strategy import remove

            remove(self.model, self.optimizer, self.state, found)
        self.path_floaters_time += time.perf_counter() - t0
        if not removing:
            return 0
        self.log(f"warpgs: step {step}: {n} Gaussians removed that poses of the camera path see and no input does "
                 f"(train.path_floaters)")
        return n

    def prune_unseen(self) -> int:
        """The final pruning (``train.prune_unseen_at_end``): drops what no training view uses."""
        if self.n_before_compaction is None:
            self.n_before_compaction = len(self.model)
        return self.strategy.prune_unseen(self.model, self.optimizer, self.state, self.train_cams, self.background)

    def export_ply(self, path: str | Path | None = None) -> Path:
        return self.model.save_ply(Path(path) if path is not None else self.out / "point_cloud.ply")

    def finish(self, baseline: dict | None = None) -> dict:
        """After training: a checkpoint of the trained state (unless one was written at this step), the final
        pruning (if asked), the stages, test metrics and renders, FPS, PLY, final checkpoint, metrics.json, then
        the method's records and outputs (``baseline``: the baseline run's metrics, for its report)."""
        out = self.out
        if out is not None and self.saved_step != self.step:
            # the trained state, before the final pruning changes it: an interrupt while the results are written
            # loses no training (--resume writes them from here, as an uninterrupted run would)
            self.save_checkpoint()
        if self.cfg.train.path_floaters_final:
            self.remove_path_floaters(self.step)
        if self.cfg.train.prune_unseen_at_end:
            removed = self.prune_unseen()
            if removed:
                self.log(f"warpgs: pruning the unseen removed {removed} of {self.n_before_compaction} Gaussians")
        for stage in self.stages:
            stage.before_evaluation(self)
        ev = self.evaluate(save_dir=(out / "test") if out is not None and self.cfg.eval.save_images else None)
        train_ev = self.evaluate(self.train_cams, lpips=False)
        fps = render_fps(lambda i: self.render(self.test_cams[i] if self.test_cams else self.train_cams[i]),
                         len(self.test_cams) or len(self.train_cams), self.cfg.eval.fps_repeats, self.device)
        metrics = run_metrics(self, ev, train_ev, fps)
        if self.pair is not None:
            metrics["co_reg"] = self.pair.report()
        if out is not None:
            write_run_outputs(self, metrics)
        return self.method.finish(metrics, baseline)


def load_trained(path: str | Path, device="cpu", drop_invalid: bool = False) -> GaussianModel:
    """A model from a checkpoint (``checkpoint.pt``) or a 3D-GS PLY (``drop_invalid``: ``load_ply``'s)."""
    path = Path(path)
    if path.suffix == ".ply":
        return GaussianModel.load_ply(path, device=device, drop_invalid=drop_invalid)
    ck = read_checkpoint(path)
    p = ck["params"]
    m = GaussianModel(p["means"], p["quats"], p["scales"], p["opacities"], p["sh0"], p["shN"],
                      max_sh_degree=ck["max_sh_degree"])
    m.active_sh_degree = m.max_sh_degree
    return m.to(device)
