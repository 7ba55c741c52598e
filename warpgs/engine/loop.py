"""The training loop of a 3D-GS model on a ``Scene``: one loop for every method.

    trainer = Trainer(cfg, scene, out_dir)       # initialises the model (trainer.load_checkpoint() resumes)
    trainer.run()                                 # the method's phases: progress bar, checkpoints, Ctrl-C / SIGTERM
    result = trainer.finish()                     # stages, test metrics, renders, PLY, metrics.json

A ``Method`` (``warpgs.methods``; the baseline's adds nothing, the paper's is ``warpgs.methods.full``) adds loss
terms, among them extra views, keeps its part of the training state, runs its phases and adds its records after
training. One input view per iteration (3D-GS's shuffled order); loss = 0.8 L1 + 0.2 D-SSIM (+ a Pearson depth
term when ``loss.depth_weight`` > 0 and the view has a depth prior); Adam with 3D-GS's learning rates and an
exponentially decaying position rate; densification by ``DefaultStrategy``, then the pruning on the camera path
(``warpgs.strategy.clearance.PathPruning``). The regularisers (``warpgs.regularizers``: dropout, opacity noise and decay,
the parameter priors, the binocular term, the path consistency) add their terms in their registry's order.

The trainer's parts: ``warpgs.engine.init`` (the initial model and the configuration derived for the run),
``warpgs.engine.stepguard`` (each step's verdict, deferred host reads, snapshots and rollback),
``warpgs.engine.state`` (the training state and checkpoints), ``warpgs.engine.signals`` (graceful stops),
``warpgs.engine.context`` (the narrow view the collaborators get).

With ``corgs.pair`` (CoR-GS, ``warpgs.coreg``) a second model trains beside the first on the same views, with
its own optimiser, strategy and random streams; the two are co-pruned and co-regularised on poses between the
training views. Each step adds its loss to the first model's before the one backward, both optimisers step on the
guard's one verdict (``optimizers``; the guard checks both models' ``trained_parameters``), and its state goes
into every part of the state under ``pair``. The first model is the one evaluated and exported.

Reproducibility: ``train.seed`` seeds the initialisation, the view order and the split noise (each its own
generator, all saved in checkpoints, so a resumed run continues exactly as an uninterrupted one). On the CPU,
Warp's kernels run on one thread, so two runs with one seed give identical numbers; on CUDA the rasterizer sums
gradients in fixed point and cuDNN is set deterministic, for the same reason.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

from warpgs import losses
from warpgs.strategy.clearance import PathPruning
from warpgs.config import Config
from warpgs.engine import state as training_state
from warpgs.engine.background import Background
from warpgs.engine.cameras import SceneCameras
from warpgs.engine.checkpoint import CHECKPOINT, TrainingInterrupted
from warpgs.engine.context import Context
from warpgs.engine.evaluation import evaluate_views, finish_run
from warpgs.engine.init import (background_colour, growth_schedule, hold_geometry, init_model, method_far_field,
                                prepare_geometry, resolve_device, scene_scale_of)
from warpgs.engine.signals import StopRequest
from warpgs.engine.stepguard import StepGuard
from warpgs.engine.method import Method
from warpgs.model import GaussianModel
from warpgs.optim import base_learning_rates, make_optimizer
from warpgs.regularizers import Regularizers


def _update_bar(bar, ema: dict, info: dict, step: int, n: int) -> None:
    """The progress bar's loss and PSNR: running averages of the steps that read them."""
    for k in ("loss", "psnr"):
        v = info.get(k)
        if v is not None and math.isfinite(v):
            ema[k] = v if k not in ema else 0.9 * ema[k] + 0.1 * v
    if step % 10 == 0 or step == 1:
        bar.set_postfix(loss=f"{ema.get('loss', float('nan')):.4f}", psnr=f"{ema.get('psnr', float('nan')):.2f}", n=n,
                        refresh=False)


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
        if self.device.type == "cpu" and cfg.guard.cpu_threads > 0:
            # The images are small and Warp's CPU kernels run on one thread: more torch threads gain
            # little, and on a busy machine their synchronisation made small ops 50x slower.
            torch.set_num_threads(cfg.guard.cpu_threads)
        if self.device.type == "cuda":
            # the rasterizer's backward is deterministic (fixed-point sums); cuDNN's convolutions (SSIM)
            # must be too, so two runs with one seed give the same numbers
            torch.backends.cudnn.deterministic = True
            torch.backends.cudnn.benchmark = False
        if not scene.train:
            raise ValueError(f"{scene.name}: no training views")
        # the scene's cameras and their capture path, built once and handed out
        self.cameras = SceneCameras(scene, self.device, cfg.pseudo.trajectory.order)
        colour = torch.tensor(background_colour(cfg, scene), dtype=torch.float32, device=self.device)
        self.scene_scale = cfg.optim.scene_scale or scene_scale_of(scene.train)
        seed = cfg.train.seed
        torch.manual_seed(seed)
        np.random.seed(seed % 2**32)
        # the initial points (found here or earlier, then kept on the scene) decide hold.geometry
        self.geometry = geo = prepare_geometry(cfg, scene, self.log)
        name = method.name if method is not None else "baseline"
        cfg = method_far_field(growth_schedule(cfg, name), name)
        cfg, self.held = hold_geometry(cfg, geo)  # the same cfg when not held
        self.cfg = cfg
        self.bg = Background(colour, cfg.train)
        if self.held is not None:
            self.log(f"warpgs: geometry held ({self.held['why']}): no densification; means / scales / rotations "
                     f"learning rates x {self.held['means_lr']:g} / {self.held['scales_lr']:g} / {self.held['quats_lr']:g}")
        self.strategy = cfg.strategy
        init_gen = torch.Generator().manual_seed(seed)
        self.model = init_model(cfg, scene, init_gen).to(self.device)
        self.model.alpha_max = cfg.model.alpha_max
        self.split_gen = torch.Generator(device=self.device).manual_seed(seed + 1)
        self.drop_gen = torch.Generator(device=self.device).manual_seed(seed + 5)
        self.context = Context(self)
        # the background components (warpgs.backgrounds: the far field), fitted on the training views (and their
        # points) only, deterministic: a resumed run computes the same ones
        self.bg.build(cfg, self.context)
        self.stop = StopRequest(lambda msg: self.log(msg))
        # the regularisers on for this run, in the registry's order (warpgs.regularizers)
        self.regularizers = Regularizers.build(cfg, self.context)
        self.path_pruning = PathPruning.build(cfg.clearance, scene, self.cameras, self.device)
        self.view_rng = np.random.default_rng(seed + 2)
        self.order: list[int] = []
        self.optimizer = make_optimizer(self.model, cfg, self.scene_scale)
        self.state = self.strategy.initialize_state(len(self.model), self.device)
        self.step = 0
        self.train_time = 0.0
        self.losses: list[float] = []
        # divergence handling (warpgs.engine.stepguard): the verdicts, the snapshots, the deferred host reads
        self.stepguard = StepGuard(self)
        self.phase_start, self.phase_len = 0, None  # the running learning-rate schedule (means_lr)
        self.lr_scale = 1.0
        self.recoveries: list[dict] = []
        self.curve: list[dict] = []  # test metrics every train.eval_every steps (PSNR against time)
        self.initial: dict | None = None
        self.n_before_compaction: int | None = None
        self._ema = {}
        self.saved_step: int | None = None  # the step of the checkpoint last written or read (messages)
        self.in_phase = False  # inside train()'s loop: a checkpoint written now is in the middle of a phase
        self.resumed = False  # a checkpoint of the middle of a phase was loaded: the next train() continues it
        self.stage_records: dict = {}  # each stage's record by its name (metrics.json's ``compact``)
        self.stopped_early: dict | None = None  # set by the caller when training stopped before the end
        self.reserved_steps = 0  # the run's last steps, trained by a stage (compact mode's search's fine-tunes)
        self.stages: list = []  # stages above training (``add_stage``; warpgs.engine.stage)
        # CoR-GS (--method corgs, or corgs.pair with any method): the second model of the co-regularised pair,
        # its optimiser and strategy
        self.pair = None
        if cfg.corgs.pair or getattr(method, "pair", False):
            from warpgs.coreg import CoRegPair

            self.pair = CoRegPair(self.context)
        self.method = method if method is not None else Method()
        self.method.attach(self)
        # train.cuda_graph: deferred steps replayed as one CUDA graph (warpgs/engine/graphstep.py)
        self.graph = None
        self.isect_capacity: int | None = None  # the fixed capacity of the renders of a step being recorded
        if self.device.type == "cuda" and cfg.guard.cuda_graph and cfg.guard.guard_kernels:
            from warpgs.engine.graphstep import StepGraph

            self.graph = StepGraph(self)

    # ------------------------------------------------------------------------------------------
    # what the trainer holds, by the names its users read

    train_cams = property(lambda self: self.cameras.train)
    test_cams = property(lambda self: self.cameras.test)
    background = property(lambda self: self.bg.colour)  # the [3] colour behind the Gaussians
    guard = property(lambda self: self.stepguard.guard)  # warpgs.guard.DivergenceGuard: the verdicts' counts
    clearance = property(lambda self: self.path_pruning.clearance)
    floaters = property(lambda self: self.path_pruning.floaters)
    path_floaters_time = property(lambda self: self.path_pruning.time)
    stop_requested = property(lambda self: self.stop.requested)
    sync_every = property(lambda self: self.stepguard.sync_every)

    @property
    def drop_rate(self) -> float:
        """DropGaussian's final rate (``train.drop_rate``; the full method may set its own)."""
        return self.regularizers.get("dropout").rate

    @drop_rate.setter
    def drop_rate(self, rate: float) -> None:
        if not 0.0 <= rate < 1.0:
            raise ValueError(f"drop_rate must be in [0, 1), got {rate}")
        self.regularizers.get("dropout").rate = rate

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
        """The optimisers of the models being trained: the model's, then (``corgs.pair``) its partner's."""
        return [self.optimizer] + ([self.pair.optimizer] if self.pair is not None else [])

    def trained_parameters(self) -> dict[str, torch.Tensor]:
        """The parameters being trained, by name: the model's, then (``corgs.pair``) its partner's as
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

    def apply_lr_scale(self) -> None:
        """Sets every group's learning rate to its base rate x ``lr_scale`` (the means' is set each step)."""
        base = base_learning_rates(self.cfg, self.scene_scale)
        for opt in self.optimizers:
            for g in opt.param_groups:
                g["lr"] = (self.means_lr(self.step) if g["name"] == "means" else base[g["name"]]) * self.lr_scale

    def next_view(self) -> int:
        if not self.order:
            self.order = self.view_rng.permutation(len(self.train_cams)).tolist()
        return self.order.pop()

    def compute_loss(self, out, cam) -> tuple[torch.Tensor, dict]:
        """The training loss of the render ``out`` of the input view ``cam``: the inputs' (``input_loss``), the
        priors on the parameters and the method's terms (``Method.loss_terms``); (loss, its parts by name)."""
        loss, parts = self.input_loss(out, cam)
        loss = self.parameter_priors(self.model, loss, parts)
        return self.method.loss_terms(out, cam, loss, parts), parts

    def input_loss(self, out, cam) -> tuple[torch.Tensor, dict]:
        """The loss of a render ``out`` of the input view ``cam`` against it (``losses.input_loss``: its parts by
        name, the whole as ``inputs``), then the regularisers' terms on the render (``Regularizer.input_term``)."""
        loss, parts = losses.input_loss(self.cfg.loss, out, cam)
        return self.regularizers.input_term(out, loss, parts), parts

    def parameter_priors(self, model: GaussianModel, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        """``loss`` plus the regularisers' priors on ``model``'s parameters (``Regularizer.model_term``), each
        recorded in ``parts``; the divergence guard's ``inputs`` part leaves them out."""
        return self.regularizers.model_term(model, loss, parts)

    def background_for(self, cam, keep: bool = True) -> torch.Tensor:
        """What ``cam`` sees behind the Gaussians (``Background.for_cam``)."""
        return self.bg.for_cam(cam, keep)

    def with_training_background(self, cam, generator: torch.Generator):
        """(camera, background) for one training step (``Background.for_training``)."""
        return self.bg.for_training(cam, generator)

    def opacity_scale(self, step: int, model: GaussianModel | None = None,
                      generator: torch.Generator | None = None) -> torch.Tensor | None:
        """The per-Gaussian opacity factors of one training render of ``model`` (default: the trainer's) at
        ``step``, drawn from ``generator`` (default: ``drop_gen``): the regularisers' (DropGaussian's mask, then
        the opacity noise); None when none is on. Evaluation renders use none."""
        model = model if model is not None else self.model
        return self.regularizers.opacity_scale(self.context, step, len(model), generator or self.drop_gen)

    def train_step(self) -> dict:
        """One iteration at ``self.step`` (does not advance it). On a divergence that a recovery handles it
        rolls back (``self.step`` becomes the snapshot's) and returns ``{"rolled_back": 1, ...}``. The verdict
        and the update are the step guard's (``StepGuard.judge``): either way a non-finite or exploding step's
        gradient never reaches the parameters."""
        step = self.step
        self.model.active_sh_degree = min(step // max(self.cfg.train.sh_degree_interval, 1), self.model.max_sh_degree)
        lr = self.means_lr(step) * self.lr_scale
        for opt in self.optimizers:
            opt.set_lr("means", lr)
        cam = self.train_cams[self.next_view()]
        if self.graph is not None and not self.stepguard.sync_due(step) and self.graph.covers(step, cam):
            info = self.graph.step(step, cam)  # the deferred step as one CUDA graph (warpgs.engine.graphstep)
            if info is not None:
                return info
        cam, bg = self.with_training_background(cam, self.split_gen)
        out, loss, inputs = self.forward_backward(step, cam, bg)
        return self.stepguard.judge(step, loss, inputs, out, cam)

    def forward_backward(self, step: int, cam, bg, isect_capacity: int | None = None):
        """Step ``step``'s render of the view ``cam`` over ``bg``, its loss (``compute_loss``, the regularisers'
        step terms, and the co-regularised partner's) and the backward pass; returns (the render, the loss, the
        input views' loss), both detached. ``isect_capacity``: the render's fixed-capacity buffers
        (``rasterize``; a CUDA graph of the step)."""
        # no input checks in the rasterizer (each is a host read): the guard checks the loss, the gradients and
        # the parameters, and a step with non-finite ones makes no update
        self.isect_capacity = isect_capacity  # the step's other renders (extra views, regularisers) use it too
        try:
            out = self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg,
                                    opacity_scale=self.opacity_scale(step), check_finite=False,
                                    isect_capacity=isect_capacity)
            loss, parts = self.compute_loss(out, cam)
            loss = self.regularizers.step_terms(self.context, step, out, cam, bg, loss, parts)
            if self.pair is not None:  # its partner on the same view, the two co-regularised (one backward for both)
                loss = loss + self.pair.loss(step, cam, bg, parts)
            loss.backward()
        finally:
            self.isect_capacity = None
        # the guard judges the input views' loss: extra views (the full method's pseudo views) change what is
        # optimised and can be far off at first without anything diverging
        return out, loss.detach(), parts.get("inputs", loss).detach()

    def after_update(self, step: int, out, cam, apply: torch.Tensor | None = None) -> dict:
        """What follows a step's update: densification (``densify``), the co-regularised partner's and the
        co-pruning (``corgs.pair``), and a new statistic after an opacity reset or a pruning (the loss's jump
        after either is expected, not divergence: gsplat's recipe on fern at 3 views prunes the Gaussians over
        ``prune_scale3d`` at step 3100 and the loss jumps 13x, which rolling back only repeats). ``apply``: a
        deferred step's verdict (``out``'s radii are already masked with it)."""
        info = self.densify(self.strategy, self.model, self.optimizer, self.state, step, out, cam, self.split_gen)
        if self.pair is not None:
            info["co_pruned"] = self.pair.after_update(step, cam, apply)
        if info.get("reset") or info.get("pruned"):
            self.stepguard.restart_statistic(step + 1)
        return info

    def densify_only_updates_state(self, step: int) -> bool:
        """Whether ``densify`` at ``step`` does no more than the strategy's ``update_state`` (no growth, pruning,
        reset, nor pruning on the camera path): such a step can be part of a CUDA graph (``warpgs.engine.graphstep``)."""
        s = self.strategy
        only = getattr(s, "only_updates_state", None)
        return only is not None and only(step) and not self.path_pruning.prunes_at(step, s.refine_every)

    def densify(self, strategy, model: GaussianModel, optimizer, state: dict, step: int, out, cam,
                generator: torch.Generator) -> dict:
        """The strategy's densification of ``model`` after step ``step``'s update (``out``: its render of the
        view ``cam``), the pruning on the camera path (the trained model's), and pruning the unseen when it finds
        the budget spent; returns what changed."""
        info = strategy.step_post_backward(model, optimizer, state, step, out, cam.width, cam.height,
                                           self.scene_scale, generator=generator)
        s = strategy
        if model is self.model:
            self.path_pruning.after_densify(self.context, step, s.refine_every, info)
        if (s.prune_unseen_when_full and s.max_gaussians > 0 and (info["cloned"] or info["split"] or info["pruned"])
                and len(model) >= s.max_gaussians):
            # the budget is spent: free what the training views do not use, so growth can go on where it helps
            info["pruned_unseen"] = s.prune_unseen(model, optimizer, state, self.train_cams, self.background)
        return info

    def train(self, iterations: int | None = None) -> None:
        """Trains until ``iterations`` (default ``train.iterations``) steps are done."""
        from tqdm import tqdm

        sg = self.stepguard
        total = self.total_steps if iterations is None else iterations
        if self.initial is None and self.step == 0 and self.test_cams:
            self.initial = self.evaluate(save_dir=None, lpips=False)["mean"]
        # a new phase (the full method's cycles): its losses make their own statistic. A run resumed from the
        # middle of a phase continues that phase's statistic (stat_start came with the checkpoint), so it judges
        # every step as the uninterrupted run did. Either way this is a good state to come back to.
        if not self.resumed:
            sg.restart_statistic(self.step)
        elif self.step < total:  # (a call with nothing to train, the full method's earlier phases, keeps it)
            self.resumed = False
        if not sg.take_snapshot():  # e.g. what was added between phases is not finite: back to the last good state
            sg.diverge(self.step, f"the model is not finite at the start of training (step {self.step}: "
                                  f"{', '.join(sg.nonfinite_parameters()) or 'optimiser state'})")
        restore = self.stop.install()
        # into a log file (not a terminal) the bar writes at most every 30 s, not ten times a second
        bar = tqdm(total=total, initial=self.step, desc=f"{self.cfg.method} {self.scene.name}", unit="it",
                   dynamic_ncols=True, disable=not self.cfg.train.progress, file=sys.stderr,
                   mininterval=0.1 if sys.stderr.isatty() else 30.0)
        every = self.cfg.train.checkpoint_every
        ev_every = self.cfg.train.eval_every
        t0 = time.perf_counter()
        sg.phase_end = total
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
                _update_bar(bar, self._ema, info, self.step, len(self.model))
                if self.stop.requested:
                    if sg.pending and sg.resolve()[0] is not None:  # a stop during a deferred step: the verdicts
                        bar.n = self.step                            # rolled back; that state is saved
                        bar.refresh()
                    self.train_time += time.perf_counter() - t0
                    t0 = time.perf_counter()
                    path = self.save_checkpoint()
                    raise TrainingInterrupted(self.step, path, self.stop.signum)
                if every and self.step % every == 0 and self.step < total:
                    self.train_time += time.perf_counter() - t0
                    t0 = time.perf_counter()
                    self.save_checkpoint()
                if ev_every and self.step % ev_every == 0 and self.test_cams:
                    self.train_time += time.perf_counter() - t0
                    self.record_curve()
                    t0 = time.perf_counter()
        finally:
            sg.phase_end = None
            self.in_phase = False
            if sg.pending:  # an exception between host reads
                sg.abandon_pending()
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

    def add_stage(self, stage) -> None:
        """A stage above training (``warpgs.engine.stage.Stage``, before training or resuming): the run's last
        steps it reserves, its wrap of the strategy; ``finish`` runs it. A stage of a kind already added: nothing."""
        if any(type(s) is type(stage) for s in self.stages):
            return
        self.stages.append(stage)
        self.reserved_steps = max(self.reserved_steps, stage.reserve_steps(self.cfg.train.iterations))
        self.strategy = stage.wrap_strategy(self.strategy, self.context)

    def request_stop(self) -> None:
        """Stop after the current step, saving a checkpoint (what Ctrl-C and SIGTERM do)."""
        self.stop.request()

    # ------------------------------------------------------------------------------------------
    # the training state and checkpoints (warpgs.engine.state), the last good state (warpgs.engine.stepguard)

    state_dict = training_state.state_dict  # (parts=STATE_PARTS, device="cpu") -> dict
    load_state_dict = training_state.load_state_dict  # (st)
    save_checkpoint = training_state.save_checkpoint  # (path=None) -> Path | None
    load_checkpoint = training_state.load_checkpoint  # (path=None) -> Path

    def last_checkpoint(self) -> Path | None:
        path = self.out / CHECKPOINT if self.out is not None else None
        return path if path is not None and path.is_file() else None

    def after_out_of_memory(self) -> int | None:
        """``StepGuard.after_out_of_memory``: back to the last good state after the device ran out of memory."""
        return self.stepguard.after_out_of_memory()

    # ------------------------------------------------------------------------------------------
    # evaluation and outputs

    def render(self, cam):
        return self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=self.background_for(cam))

    def evaluate(self, cameras=None, save_dir: str | Path | None = None, lpips: bool = True, render=None) -> dict:
        """Metrics over ``cameras`` (default: the test views) of ``render`` (default: the model's);
        ``warpgs.engine.evaluation.evaluate_views``."""
        return evaluate_views(render or self.render, self.test_cams if cameras is None else cameras,
                              masked=bool(self.scene.eval_masked), scene_name=self.scene.name,
                              lpips_weights=self.cfg.eval.lpips_weights, device=self.device, save_dir=save_dir,
                              lpips=lpips)

    def export_ply(self, path: str | Path | None = None) -> Path:
        return self.model.save_ply(Path(path) if path is not None else self.out / "point_cloud.ply")

    finish = finish_run  # (baseline=None) -> metrics: after training, the outputs (warpgs.engine.evaluation)
