"""The generation-guided method (the paper's loop) as a ``Method`` of the one training loop
(``warpgs.engine.Trainer``): ``Trainer(cfg, scene, out, method=FullMethod())``.

    baseline phase (inputs only)
    for each cycle:
        pseudo views along trajectories between neighbouring inputs   (warpgs.pseudo)
        densification from them: stereo -> outlier removal -> radius-gated insertion   (warpgs.densify)
        training on one input and one pseudo view per iteration (full.restart_lr: the learning-rate
        schedule restarts, as in the paper)

Losses: inputs w1 L1 + w2 D-SSIM (+ w3 Pearson depth when a prior exists, as in the baseline); pseudo
views w4 LPIPS + w5 D-SSIM + w6 Pearson depth (against the plane-sweep depth of the views the stereo
used, where it is confident), scaled by ``pseudo_weight`` and restricted to pixels an input sees
(U < 1); with ``full.pseudo_depth_smooth`` > 0 also an edge-aware smoothness of their whole depth map.
Without LPIPS weights the pseudo views use L1 instead (the paper's own ablation), which is said at start
and recorded in metrics.json.

Training iterations are counted as in the baseline (``train.iterations`` in total, the baseline phase
included), so the two are compared at equal iterations. With ``full.cycle_iterations`` > 0 the run follows the
paper's schedule instead: the baseline phase is the whole baseline run, and each cycle trains that many steps more
(``train.iterations + cycles x cycle_iterations`` in all), from the baseline's final model.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from warpgs import losses
from warpgs.config import FullConfig, check_limits
from warpgs.console import warn_once
from warpgs.engine.checkpoint import TrainingInterrupted
from warpgs.engine.method import Method
from warpgs.model import rgb_to_sh
from warpgs.optim import STATE_PARTS
from warpgs.pseudo.views import GenerationStopped, prefetch_backend
from warpgs.regularizers.pathconsistency import check_one_camera, two_view_consistency

ABLATIONS = {
    # name: what it switches, as a config layer -- the paper's Table 4
    "render_guidance": {"full": {"guidance": "render"}},
    "no_geometric": {"pseudo": {"uncertainty": {"geometric": False}}},
    "no_photometric": {"pseudo": {"uncertainty": {"photometric": False}}},
    "no_filter": {"full": {"point_filter": False}},
    "no_densify": {"full": {"densify": False}},
    "l1_pseudo": {"full": {"pseudo_loss": "l1"}},
}


def check_settings(s: FullConfig) -> FullConfig:
    """The ranges of ``FullConfig.LIMITS``, for settings built in code (a config file's are checked as read)."""
    check_limits(s, "the full method's options", "full.")
    return s


def append_gaussians(ctx, means, colors, scales, opacity: float) -> int:
    """Adds Gaussians (centres, RGB colours, isotropic std devs) to the trainer's model, with zero Adam
    moments and zero densification statistics. ``ctx``: the trainer's narrow view (``Trainer.context``: its
    model, device, optimiser and densification state)."""
    from warpgs.strategy.ops import update_params

    n = int(means.shape[0])
    if n == 0:
        return 0
    model, dev = ctx.model, ctx.device
    means = means.to(dev, torch.float32)
    rgb = (colors[:, :3] if colors.shape[1] >= 3 else torch.full((n, 3), 0.5)).to(dev, torch.float32).clamp(0, 1)
    quats = torch.zeros(n, 4, device=dev)
    quats[:, 0] = 1.0
    new = {
        "means": means,
        "quats": quats,
        "scales": torch.log(scales.to(dev, torch.float32).clamp_min(1e-7)),
        "opacities": torch.full((n,), math.log(opacity / (1 - opacity)), device=dev),
        "sh0": rgb_to_sh(rgb)[:, None, :],
        "shN": torch.zeros(n, *model.params["shN"].shape[1:], device=dev),
    }
    update_params(model, ctx.optimizer, lambda name, p: torch.cat([p, new[name].to(p.dtype)]),
                  lambda k, v: torch.cat([v, torch.zeros((n, *v.shape[1:]), device=v.device, dtype=v.dtype)]))
    for k, v in ctx.state.items():
        ctx.state[k] = torch.cat([v, torch.zeros((n, *v.shape[1:]), device=v.device, dtype=v.dtype)])
    return n


class FullMethod(Method):
    """The paper's loop as a ``Method`` of the one training loop: a baseline phase, then per cycle pseudo
    views and densification from them, and training on one input and one pseudo view per iteration."""

    name = "full"

    def attach(self, trainer) -> None:
        super().attach(trainer)
        cfg = trainer.cfg
        self.settings = check_settings(cfg.full)
        if self.settings.drop_rate is not None:
            trainer.drop_rate = self.settings.drop_rate
        if self.settings.path_consistency > 0:  # the pseudo views carry their start input's intrinsics and size
            check_one_camera(trainer.train_cams, "full.path_consistency")
        self.pseudo_cams: list = []
        self.pseudo_reliable: dict[str, torch.Tensor] = {}  # full.reliable_weight: each pseudo view's U < delta
        self.pseudo_order: list[int] = []
        self.pseudo_rng = np.random.default_rng(cfg.train.seed + 3)
        self._pick = None  # the pseudo view of the step under way, once picked (``step_views``)
        self._bound = None  # the views a step being recorded as a CUDA graph reads (``graph_bind``)
        self._no_depth = None  # zeros: what a recording reads for a pseudo view without a depth (``graph_inputs``)
        self.cycles_done = 0
        self.history: list[dict] = []  # per cycle: test PSNR/SSIM, Gaussians, stage times
        self.input_depths: dict[str, torch.Tensor] = {}  # plane-sweep depth of the inputs (0: unknown)
        self.early_depth_s: float | None = None  # time of full.early_depth's stereo
        self.lpips_missing: str | None = None
        self._lpips = None
        if self.settings.pseudo_loss == "lpips" and self.settings.lpips_weight > 0:
            try:
                self._lpips = losses.LPIPS(cfg.eval.lpips_weights).to(trainer.device)
            except Exception as e:  # LPIPSUnavailable or a broken install
                self.lpips_missing = losses.one_line(e)
                warn_once(f"warpgs: pseudo views train with L1 (the paper's ablation), LPIPS is not reported: "
                          f"{self.lpips_missing}", key="lpips-missing")

    @property
    def pseudo_loss_used(self) -> str:
        return "lpips" if self._lpips is not None else "l1"

    # ------------------------------------------------------------------------------------------
    # training

    def next_pseudo(self) -> int:
        if not self.pseudo_order:
            self.pseudo_order = self.pseudo_rng.permutation(len(self.pseudo_cams)).tolist()
        return self.pseudo_order.pop()

    def pseudo_loss(self, out, cam, reliable: torch.Tensor | None = None) -> torch.Tensor:
        """The loss of the render ``out`` of the pseudo view ``cam``; ``reliable``: its U < delta (for
        ``full.reliable_weight``)."""
        s = self.settings
        m = cam.mask.to(out.image.dtype)[..., None] if cam.mask is not None else None
        pred = out.image * m if m is not None else out.image
        target = cam.image * m if m is not None else cam.image
        # reliable pixels x reliable_weight, the rest x 1; a mask keeps the unweighted terms' normalisation
        weight = None if reliable is None else torch.where(reliable, s.reliable_weight, 1.0).to(out.image.dtype)
        if self._lpips is not None:
            loss = s.lpips_weight * self._lpips(pred, target)
        elif weight is not None:
            loss = s.lpips_weight * losses.weighted_l1(out.image, cam.image, weight, cam.mask)
        else:
            loss = s.lpips_weight * losses.l1(out.image, cam.image, cam.mask)
        if s.ssim_weight > 0:
            loss = loss + s.ssim_weight * (losses.dssim(pred, target) if weight is None
                                           else losses.weighted_dssim(pred, target, weight))
        if s.depth_weight > 0 and cam.depth is not None:  # set only with enough confident pixels (depth_prior)
            loss = loss + s.depth_weight * losses.pearson_depth_loss(out.depth, cam.depth, cam.depth > 0)
        return loss

    def step_views(self, cam) -> dict:
        """What the step on the input ``cam`` reads besides it: ``prior`` (its depth prior) and, once pseudo views
        exist, ``pseudo`` (the one trained on, picked here from the host's generator), ``pseudo_bg`` (what it sees
        behind the Gaussians) and ``reliable`` (its U < delta, for ``full.reliable_weight``); each None where it has
        none. A step recorded as a CUDA graph reads the recording's copies of them (``graph_bind``)."""
        if self._bound is not None:
            return self._bound
        s, tr = self.settings, self.trainer
        views = {"prior": self.input_depths.get(cam.name) if s.input_depth_weight > 0 else None,
                 "pseudo": None, "pseudo_bg": None, "reliable": None}
        if self.pseudo_cams and s.pseudo_weight > 0:
            if self._pick is None:
                self._pick = self.pseudo_cams[self.next_pseudo()]
            pc = views["pseudo"] = self._pick
            views["pseudo_bg"] = tr.background_for(pc)
            views["reliable"] = self.pseudo_reliable.get(pc.name) if s.reliable_weight != 1.0 else None
        return views

    def loss_terms(self, out, cam, loss, parts):
        """The inputs' depth prior (from the cycles' stereo) and one pseudo view. The divergence guard judges
        ``parts["inputs"]`` without them: the prior appears with the first cycle, and its Pearson term (about 1
        at first) made the input loss jump 30x there and stopped a run."""
        tr = self.trainer
        views = self.step_views(cam)
        if self._bound is None:  # (a recording's warm-up and capture keep the pick for the step itself)
            self._pick = None  # used by this step
        prior = views["prior"]
        if prior is not None:
            dl = losses.pearson_depth_loss(out.depth, prior, prior > 0)
            loss = loss + self.settings.input_depth_weight * dl
            parts["input_depth"] = dl
        pc = views["pseudo"]
        if pc is not None:
            po = tr.model.render(pc.viewmat, pc.K, pc.width, pc.height, background=views["pseudo_bg"],
                                 opacity_scale=tr.opacity_scale(tr.step), check_finite=False,
                                 isect_capacity=tr.isect_capacity)  # no host read (the input render's reason)
            pl = self.pseudo_loss(po, pc, views["reliable"])
            loss = loss + self.settings.pseudo_weight * pl
            parts["pseudo"] = pl
            if self.settings.pseudo_depth_smooth > 0:  # where no input constrains the depth: flat between edges
                sm = losses.edge_aware_smoothness(po.depth, pc.image)
                loss = loss + self.settings.pseudo_depth_smooth * sm
                parts["pseudo_depth_smooth"] = sm
            if self.settings.path_consistency > 0:
                pair = pseudo_pair(pc.name, len(tr.train_cams))
                if pair is not None:
                    a, b = (tr.train_cams[k] for k in pair)
                    pcl = two_view_consistency(po.depth, pc, a, b)
                    loss = loss + self.settings.path_consistency * pcl
                    parts["path_consistency"] = pcl
        return loss

    # a step recorded as a CUDA graph (warpgs.engine.graphstep)

    def graph_safe(self) -> bool:
        """Before the first cycle ``loss_terms`` adds nothing. After it, a graph holds the pseudo view's render and
        loss (the view picked and its tensors copied in before each replay, ``graph_inputs``), except LPIPS (a
        network, not checked in a graph) and the path consistency (its two inputs depend on the view picked)."""
        if not self.pseudo_cams and not self.input_depths:
            return True
        return self._lpips is None and self.settings.path_consistency <= 0

    def graph_inputs(self, cam) -> tuple[tuple, dict[str, torch.Tensor], list]:
        """For the step on ``cam`` as a replay: (what the recording depends on, the tensors copied into its own
        before the replay, the extra cameras it renders, whose intersection counts bound its capacity). Picks the
        step's pseudo view; the step uses that pick, replayed or not (``graph_done`` after a replay)."""
        views = self.step_views(cam)
        tensors, key = {}, []
        pc = views["pseudo"]
        if pc is not None:
            views = dict(views, pseudo_viewmat=pc.viewmat, pseudo_K=pc.K, pseudo_image=pc.image,
                         pseudo_mask=pc.mask, pseudo_depth=self._graph_depth(pc))
            colour = views["pseudo_bg"] is self.trainer.background
            key.append(colour)  # (its size is the image's, in the key below)
            if colour:  # the colour the recording reads where it is
                views["pseudo_bg"] = None
        for name in ("prior", "pseudo_viewmat", "pseudo_K", "pseudo_image", "pseudo_mask", "pseudo_depth",
                     "pseudo_bg", "reliable"):
            t = views.get(name)
            key.append(None if t is None else (name, tuple(t.shape), t.dtype))
            if t is not None:
                tensors[name] = t
        return tuple(key), tensors, ([] if pc is None else [pc])

    def _graph_depth(self, pc) -> torch.Tensor | None:
        """The depth a recording of a step on the pseudo view ``pc`` reads: none while ``depth_weight`` is 0 (the
        loss does not read it), else the view's, or zeros where it has none. Only the views that densification's
        stereo reached have one; for zeros the Pearson term is exactly 0 with exactly zero gradients (no pixel > 0:
        ``pearson_depth_loss``), as the step without the term, so one recording serves the views with a depth and
        those without (else a new recording each time the pick changes kind: 440 of 454 on fern)."""
        if self.settings.depth_weight <= 0:
            return None
        if pc.depth is not None:
            return pc.depth
        z = self._no_depth
        if z is None or z.shape != (pc.height, pc.width) or z.device != pc.image.device:
            z = self._no_depth = torch.zeros(pc.height, pc.width, dtype=pc.image.dtype, device=pc.image.device)
        return z

    def graph_bind(self, tensors: dict[str, torch.Tensor] | None) -> None:
        """While a step is recorded: ``step_views`` gives the recording's own tensors (``graph_inputs``' names);
        None: the views are picked again."""
        if tensors is None:
            self._bound = None
            return
        pc = self._pick
        bound = {"prior": tensors.get("prior"), "reliable": tensors.get("reliable"), "pseudo": None,
                 "pseudo_bg": None}
        if pc is not None and "pseudo_viewmat" in tensors:
            bound["pseudo"] = dataclasses.replace(pc, viewmat=tensors["pseudo_viewmat"], K=tensors["pseudo_K"],
                                                  image=tensors["pseudo_image"], mask=tensors.get("pseudo_mask"),
                                                  depth=tensors.get("pseudo_depth"))
            bound["pseudo_bg"] = tensors.get("pseudo_bg", self.trainer.background)
        self._bound = bound

    def graph_done(self) -> None:
        """A replay made the step: its pick is used."""
        self._pick = None

    def extra_views(self) -> list:
        """This cycle's pseudo views."""
        return self.pseudo_cams

    # ------------------------------------------------------------------------------------------
    # one cycle's pseudo views and densification

    def pseudo_config(self):
        """``cfg.pseudo``, unguided for the render-guidance ablation."""
        pcfg = copy.deepcopy(self.trainer.cfg.pseudo)
        if self.settings.guidance == "render":
            pcfg.sampler.guided = False
        return pcfg

    def update_pseudo_views(self, cycle: int) -> dict:
        """Generates this cycle's pseudo views and densifies from them; returns stage times (s)."""
        from warpgs.pseudo.views import (backend_from_config, generate_pseudo_views, model_renderer, pseudo_times,
                                         save_sequences)

        tr = self.trainer
        times = {}
        t0 = time.perf_counter()
        pcfg = self.pseudo_config()
        backend = backend_from_config(pcfg, tr.device)  # loaded once a process: the first cycle's load is timed
        times["pseudo_model_load_s"] = time.perf_counter() - t0
        seqs = generate_pseudo_views(model_renderer(tr.model, tr.background_for), tr.train_cams, pcfg, device=tr.device,
                                     backend=backend, should_stop=tr.context.stop_requested)
        times["pseudo_views_s"] = time.perf_counter() - t0
        times.update(pseudo_times(seqs))  # the video model's stages, per cycle and per trajectory
        cams, reliable = [], {}
        limit = {"reliable": pcfg.sampler.delta, "all": math.inf}.get(self.settings.pseudo_mask, 1.0)
        for seq in seqs:
            seq_cams = seq.pseudo_cameras(prefix=f"c{cycle}_{seq.tag}", max_uncertainty=limit)
            if self.settings.reliable_weight != 1.0:
                reliable.update({c.name: r.to(tr.device)
                                 for c, r in zip(seq_cams, seq.interior_below(pcfg.sampler.delta), strict=True)})
            cams += seq_cams
        cycle_dir = tr.out / f"cycle_{cycle}" if tr.out is not None else None
        t0 = time.perf_counter()
        if cycle_dir is not None:
            save_sequences(seqs, cycle_dir / "pseudo")
        times["pseudo_save_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        added = 0
        if self.settings.densify and cams:
            added = self.densify(cams, cycle_dir)
        times["densify_s"] = time.perf_counter() - t0
        self.pseudo_cams = cams
        self.pseudo_reliable = reliable
        self.pseudo_order = []
        tr.log(f"warpgs: cycle {cycle}: {len(cams)} pseudo views ({times['pseudo_views_s']:.1f} s), "
               f"{added} Gaussians added by densification ({times['densify_s']:.1f} s), {len(tr.model)} in all")
        times["added"] = added
        return times

    def apply_growth_budget(self) -> None:
        """With ``growth_budget``: once the strategy's first growth period is over (its first opacity reset,
        or the end of refinement if that comes first), the cycles grow the model to at most that x the
        Gaussians it had then (or what it has now, if more). The reference is the first per-cycle record
        (the baseline phase's included) at or after that step; before one exists the configured budget holds.
        A baseline phase shorter than that growth period (a short run: 0.4 x 3000 steps) would otherwise fix
        the model at a fraction of the size the baseline reaches (castle_p30, 9 views, 384x256: 10.7k against
        67.6k Gaussians, -0.41 dB)."""
        tr = self.trainer
        if self.settings.growth_budget <= 0:
            return
        st = tr.cfg.strategy
        settled = min(st.reset_every, st.refine_stop_iter)
        ref = next((row for row in self.history if row.get("step", 0) >= settled), None)
        if ref is None:
            tr.strategy = dataclasses.replace(tr.strategy, max_gaussians=st.max_gaussians)
            return
        cap = int(self.settings.growth_budget * ref["num_gaussians"])
        if st.max_gaussians > 0:  # within strategy.max_gaussians, too
            cap = min(cap, st.max_gaussians)
        tr.strategy = dataclasses.replace(tr.strategy, max_gaussians=max(cap, len(tr.model)))

    def early_input_depths(self) -> None:
        """``full.early_depth``: the inputs' plane-sweep depth against each other (``densify.stereo``, the
        scene's bounds), where confident, is their depth prior (w3) from the first step, as the paper's input
        loss has its depth term throughout; without it the prior appears with the first cycle's stereo."""
        tr = self.trainer
        cams = list(tr.train_cams)
        if len(cams) < 2 or self.settings.input_depth_weight <= 0:
            return
        t0 = time.perf_counter()
        st = inputs_plane_sweep(cams, tr.scene.bounds, tr.cfg.densify.stereo)
        for v, c in enumerate(cams):
            depth = depth_prior(st.mask[v], st.depth[v], tr.device)
            if depth is not None:
                self.input_depths[c.name] = depth
        self.early_depth_s = time.perf_counter() - t0
        tr.log(f"warpgs: input depth prior from plane-sweep stereo between the inputs: "
               f"{len(self.input_depths)} of {len(cams)} views ({self.early_depth_s:.1f} s)")

    def densify(self, cams, cycle_dir: Path | None) -> int:
        from warpgs.densify import densify_gaussians, neighbour_views, select_views
        from warpgs.viz import save_origin_ply

        tr = self.trainer
        s = self.settings
        dcfg = copy.deepcopy(tr.cfg.densify)
        if not s.point_filter:
            dcfg.filter.std_ratio = float("inf")  # keeps every point: the 'no point filtering' ablation
        # the inputs take part as stereo references and sources (real multi-view evidence); the pseudo
        # views with the lowest covisibility to them and to each other are the other references.
        # stereo_sources 'inputs': every reference is matched against the inputs only. A pseudo view that
        # was filled from the current model's render carries the model's depth, so matching against
        # pseudo views reconstructs that depth, wrong where the model is.
        views = list(tr.train_cams) + list(cams)
        n_in = len(tr.train_cams)
        if s.stereo_sources == "inputs" and n_in < 2:
            tr.log("warpgs: densification skipped: stereo against the inputs needs at least 2 input views")
            return 0
        images = torch.stack([c.image for c in views]).float()
        viewmats = torch.stack([c.viewmat for c in views]).float()
        Ks = torch.stack([c.K for c in views]).float()
        neighbours = None
        if s.stereo_sources == "inputs":
            neighbours = neighbour_views(viewmats, min(dcfg.stereo.neighbours, n_in - 1),
                                         translation_scale=dcfg.stereo.translation_scale, candidates=range(n_in))
        refs = list(range(n_in)) + [int(i) for i in select_views(
            viewmats, dcfg.select.views, fixed=list(range(n_in)), translation_scale=dcfg.select.translation_scale,
            rotation_weight=dcfg.select.rotation_weight)]
        dens = densify_gaussians(tr.model.means.detach(), images, Ks, viewmats, depth_range=tr.scene.bounds,
                                 config=dcfg, references=refs, neighbours=neighbours)
        # the plane-sweep depth of the references, where confident, is their depth prior (w3 / w6)
        for v, ref in enumerate(dens.references):
            depth = depth_prior(dens.stereo.mask[v], dens.stereo.depth[v], tr.device)
            if ref < n_in:  # this cycle's depth replaces the last (none: no prior, as before this cycle)
                if depth is None:
                    self.input_depths.pop(views[ref].name, None)
                else:
                    self.input_depths[views[ref].name] = depth
            else:
                views[ref].depth = depth
        ins = dens.insertion
        keep = slice(None) if not s.max_new or len(ins.means) <= s.max_new else slice(0, s.max_new)
        if cycle_dir is not None:
            with torch.no_grad():
                from warpgs.model import sh_to_rgb

                colors = sh_to_rgb(tr.model.params["sh0"][:, 0]).clamp(0, 1)
            pts, cols, origin = dens.origin_cloud(tr.model.means.detach(), colors)
            save_origin_ply(cycle_dir / "densified.ply", pts, cols, origin)
        return append_gaussians(tr.context, ins.means[keep], ins.colors[keep], ins.scales[keep], s.init_opacity)

    # ------------------------------------------------------------------------------------------
    # the method's share of the training state

    def state_dict(self, parts=STATE_PARTS) -> dict:
        """``model``: the pseudo-view order and its generator (a rollback replays the same pseudo views);
        ``history``: the cycle reached, its pseudo views and input depth priors, the per-cycle records."""
        st = {}
        if "model" in parts:
            st["pseudo"] = (copy.deepcopy(self.pseudo_rng.bit_generator.state), list(self.pseudo_order))
        if "history" in parts:
            st["cycle"] = {
                "settings": asdict(self.settings),
                "cycles_done": self.cycles_done,
                "history": copy.deepcopy(self.history),
                "input_depths": {k: v.cpu() for k, v in self.input_depths.items()},
                "pseudo_cams": [{"name": c.name, "viewmat": c.viewmat.cpu(), "K": c.K.cpu(), "width": c.width,
                                 "height": c.height, "image": c.image.cpu(),
                                 "mask": None if c.mask is None else c.mask.cpu(),
                                 "depth": None if c.depth is None else c.depth.cpu()} for c in self.pseudo_cams],
                "pseudo_reliable": {k: v.cpu() for k, v in self.pseudo_reliable.items()},
            }
        return st

    def load_state_dict(self, st: dict) -> None:
        from warpgs.data.scene import CameraTensors

        if "pseudo" in st:
            self.pseudo_rng.bit_generator.state = copy.deepcopy(st["pseudo"][0])
            self.pseudo_order = list(st["pseudo"][1])
        ck = st.get("cycle")
        if ck is None:
            return
        self.cycles_done = int(ck["cycles_done"])
        self.history = copy.deepcopy(ck["history"])
        if "pseudo_rng" in ck:  # format-1 checkpoints keep the generator here
            self.pseudo_rng.bit_generator.state = ck["pseudo_rng"]
            self.pseudo_order = list(ck["pseudo_order"])
        dev = self.trainer.device
        self.input_depths = {k: v.to(dev) for k, v in ck.get("input_depths", {}).items()}
        self.pseudo_cams = [CameraTensors(name=c["name"], viewmat=c["viewmat"].to(dev), K=c["K"].to(dev),
                                          width=c["width"], height=c["height"], image=c["image"].to(dev),
                                          mask=None if c["mask"] is None else c["mask"].to(dev),
                                          depth=None if c["depth"] is None else c["depth"].to(dev))
                            for c in ck["pseudo_cams"]]
        self.pseudo_reliable = {k: v.to(dev) for k, v in ck.get("pseudo_reliable", {}).items()}

    # ------------------------------------------------------------------------------------------
    # the phases, and what the method adds after training

    def run(self) -> None:
        """Runs (or resumes) the whole loop: ``train.iterations`` steps, plus ``cycles x cycle_iterations``."""
        tr, s = self.trainer, self.settings
        bounds = phase_boundaries(tr.total_steps, s)
        if tr.phase_len is None:
            tr.phase_start, tr.phase_len = 0, bounds[0] if s.restart_lr else tr.total_steps
        if s.early_depth and not self.input_depths and not self.history:  # a resumed run has them checkpointed
            self.early_input_depths()
        # pseudo views still to make (the loop's test below): the video model's (svd) files are read while the baseline
        # trains, and it is built at the first cycle
        if self.cycles_done < s.cycles and tr.step <= bounds[s.cycles - 1]:
            prefetch_backend(self.pseudo_config(), tr.device)
        tr.train(bounds[0])
        if not self.history:  # the baseline phase, as cycle 0 of the PSNR-per-cycle chart
            self.history.append(self.record(0, {} if self.early_depth_s is None else
                                            {"input_depth_s": self.early_depth_s}))
        for c in range(self.cycles_done, s.cycles):
            start, end = bounds[c], bounds[c + 1]
            if tr.step <= start:  # this cycle's pseudo views are not made yet
                # Ctrl-C / SIGTERM while they are made: the generation stops at its next trajectory and the run
                # is checkpointed as it was before it (a resumed run makes this cycle's pseudo views again, the same)
                restore = tr.stop.install()
                try:
                    times = self.update_pseudo_views(c + 1)
                except GenerationStopped as e:
                    tr.log(f"warpgs: {e}")
                    raise TrainingInterrupted(tr.step, tr.save_checkpoint(), tr.stop.signum) from None
                finally:
                    restore()
                if s.restart_lr:  # the means' learning-rate schedule restarts (the paper)
                    tr.phase_start, tr.phase_len = start, end - start
                path = tr.save_checkpoint()
                if tr.context.stop_requested():
                    raise TrainingInterrupted(tr.step, path, tr.stop.signum)
            else:
                times = {}
            self.apply_growth_budget()  # every cycle, a resumed one too (the strategy's budget is not checkpointed)
            t0 = time.perf_counter()
            tr.train(end)
            times["train_s"] = time.perf_counter() - t0
            self.history.append(self.record(c + 1, times))
            self.cycles_done = c + 1
            tr.save_checkpoint()
        if tr.step < bounds[-1]:  # a resumed run given more iterations: continue the last phase
            tr.train(bounds[-1])

    def record(self, cycle: int, times: dict) -> dict:
        """One row of the per-cycle history: test PSNR/SSIM now, Gaussians, stage times."""
        tr = self.trainer
        ev = tr.evaluate(lpips=False)["mean"] if tr.test_cams else {}
        row = {"cycle": cycle, "step": tr.step, "psnr": ev.get("psnr"), "ssim": ev.get("ssim"),
               "num_gaussians": len(tr.model)}
        if cycle == 0:
            row["train_s"] = round(tr.train_time, 2)
        row.update({k: round(v, 2) if isinstance(v, float) else v for k, v in times.items()})
        return row

    def finish(self, metrics: dict, baseline: dict | None = None) -> dict:
        """The method's records in metrics.json, the fly-through and the report."""
        from warpgs.engine.evaluation import write_flythrough, write_metrics, write_report

        tr = self.trainer
        metrics["full"] = asdict(self.settings)
        metrics["cycles"] = self.history
        metrics["pseudo_loss"] = self.pseudo_loss_used
        if self.lpips_missing:
            metrics["lpips_fallback_reason"] = self.lpips_missing
        if tr.out is not None:
            # the method's records go into metrics.json before the slower fly-through and report, so a run
            # stopped while those are written keeps them
            write_metrics(tr.out, metrics)
            t0 = time.perf_counter()
            write_flythrough(tr, tr.out / "flythrough.gif", self.settings.flythrough_frames)
            t1 = time.perf_counter()
            write_report(tr.out, metrics, self.history, baseline)
            metrics["outputs_s"] = {"flythrough": round(t1 - t0, 2), "report": round(time.perf_counter() - t1, 2)}
        return metrics


def pseudo_pair(name: str, n_inputs: int) -> tuple[int, int] | None:
    """The indices of the two inputs a pseudo view lies between, from its name (``c{cycle}_{start}_{end}_{frame}``,
    ``FullMethod.update_pseudo_views``; checkpoints keep the names); None for a name of another form."""
    parts = name.split("_")
    if len(parts) != 4 or not (parts[1].isdigit() and parts[2].isdigit()):
        return None
    a, b = int(parts[1]), int(parts[2])
    return (a, b) if a != b and max(a, b) < n_inputs else None


def inputs_plane_sweep(cams, bounds, stereo_cfg):
    """Plane-sweep stereo of each input against its nearest inputs (``stereo_cfg``: ``densify.stereo``)
    within the scene's depth ``bounds``: the ``StereoResult`` of every input (``full.early_depth``'s prior)."""
    from warpgs.densify import neighbour_views, stereo_point_cloud

    viewmats = torch.stack([c.viewmat for c in cams]).float()
    nb = neighbour_views(viewmats, min(stereo_cfg.neighbours, len(cams) - 1),
                         translation_scale=stereo_cfg.translation_scale)
    return stereo_point_cloud(torch.stack([c.image for c in cams]).float(), torch.stack([c.K for c in cams]).float(),
                              viewmats, bounds, stereo_cfg, neighbours=nb)


def depth_prior(mask: torch.Tensor, depth: torch.Tensor, device, min_pixels: int = 16) -> torch.Tensor | None:
    """A view's depth prior: ``depth`` where ``mask`` (0 elsewhere), or None with ``min_pixels`` confident
    pixels or fewer (too few for a Pearson term). Decided once here, not at every step (a host read)."""
    if int(mask.sum()) <= min_pixels:
        return None
    return torch.where(mask, depth, torch.zeros_like(depth)).to(device)


def phase_boundaries(total: int, settings: FullConfig) -> list[int]:
    """Step at which each phase ends: [baseline, cycle 1, ..., cycle C]. The last is ``total``, or with
    ``cycle_iterations`` > 0 (the paper's schedule) the baseline phase is all of ``total`` and each cycle adds that
    many steps."""
    if settings.cycles == 0:
        return [total]
    if settings.cycle_iterations > 0:
        return [total] + [total + settings.cycle_iterations * (c + 1) for c in range(settings.cycles)]
    first = int(round(total * settings.baseline_fraction))
    per = (total - first) / settings.cycles
    return [first] + [int(round(first + per * (c + 1))) for c in range(settings.cycles)]
