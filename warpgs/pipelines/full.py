"""The generation-guided method (the paper's loop) on top of the baseline trainer.

    baseline phase (inputs only)
    for each cycle:
        pseudo views along trajectories between neighbouring inputs   (warpgs.pseudo)
        densification from them: stereo -> outlier removal -> radius-gated insertion   (warpgs.densify)
        training on one input and one pseudo view per iteration, learning-rate schedule restarted

Losses: inputs w1 L1 + w2 D-SSIM (+ w3 Pearson depth when a prior exists, as in the baseline); pseudo
views w4 LPIPS + w5 D-SSIM + w6 Pearson depth (against the plane-sweep depth of the views the stereo
used, where it is confident), scaled by ``pseudo_weight`` and restricted to pixels an input sees
(U < 1). Without LPIPS weights the pseudo views use L1 instead (the paper's own ablation), which is
said at start and recorded in metrics.json.

Training iterations are counted as in the baseline (``train.iterations`` in total, the baseline phase
included), so the two are compared at equal iterations.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from warpgs import losses
from warpgs.config import FullConfig
from warpgs.model import rgb_to_sh
from warpgs.train import CHECKPOINT, Trainer

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
    if s.pseudo_loss not in ("lpips", "l1"):
        raise ValueError(f"full.pseudo_loss must be lpips or l1, got {s.pseudo_loss!r}")
    if s.stereo_sources not in ("inputs", "all"):
        raise ValueError(f"full.stereo_sources must be inputs or all, got {s.stereo_sources!r}")
    if s.guidance not in ("warped", "render"):
        raise ValueError(f"full.guidance must be warped or render, got {s.guidance!r}")
    if s.pseudo_mask not in ("seen", "reliable"):
        raise ValueError(f"full.pseudo_mask must be seen or reliable, got {s.pseudo_mask!r}")
    if s.drop_rate is not None and not 0.0 <= s.drop_rate < 1.0:
        raise ValueError(f"full.drop_rate must be in [0, 1), got {s.drop_rate}")
    if s.growth_budget < 0:
        raise ValueError(f"full.growth_budget must be >= 0, got {s.growth_budget}")
    if s.cycles < 0 or not 0.0 <= s.baseline_fraction < 1.0:
        raise ValueError("full.cycles must be >= 0 and full.baseline_fraction in [0, 1)")
    return s


def append_gaussians(trainer: Trainer, means, colors, scales, opacity: float) -> int:
    """Adds Gaussians (centres, RGB colours, isotropic std devs) to the trainer's model, with zero Adam
    moments and zero densification statistics."""
    from warpgs.strategy import update_params

    n = int(means.shape[0])
    if n == 0:
        return 0
    model, dev = trainer.model, trainer.device
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
    update_params(model, trainer.optimizer, lambda name, p: torch.cat([p, new[name].to(p.dtype)]),
                  lambda k, v: torch.cat([v, torch.zeros((n, *v.shape[1:]), device=v.device, dtype=v.dtype)]))
    for k, v in trainer.state.items():
        trainer.state[k] = torch.cat([v, torch.zeros((n, *v.shape[1:]), device=v.device, dtype=v.dtype)])
    return n


class GenerativeTrainer(Trainer):
    """The baseline trainer plus pseudo views: one input and one pseudo view per iteration."""

    def __init__(self, cfg, scene, out_dir=None, *, log=None):
        super().__init__(cfg, scene, out_dir, log=log)
        self.settings = check_settings(cfg.full)
        if self.settings.drop_rate is not None:
            self.drop_rate = self.settings.drop_rate
        self.pseudo_cams: list = []
        self.pseudo_order: list[int] = []
        self.pseudo_rng = np.random.default_rng(cfg.train.seed + 3)
        self.cycles_done = 0
        self.history: list[dict] = []  # per cycle: test PSNR/SSIM, Gaussians, stage times
        self.input_depths: dict[str, torch.Tensor] = {}  # plane-sweep depth of the inputs (0: unknown)
        self.lpips_missing: str | None = None
        self._lpips = None
        if self.settings.pseudo_loss == "lpips" and self.settings.lpips_weight > 0:
            try:
                self._lpips = losses.LPIPS(cfg.eval.lpips_weights).to(self.device)
            except Exception as e:  # LPIPSUnavailable or a broken install
                self.lpips_missing = losses.one_line(e)
                self.log("warpgs: LPIPS weights are not available, so pseudo views are trained with L1 in place of "
                         f"LPIPS (the paper's 'L1 instead of LPIPS' ablation). Reason: {self.lpips_missing}")

    @property
    def pseudo_loss_used(self) -> str:
        return "lpips" if self._lpips is not None else "l1"

    # ------------------------------------------------------------------------------------------
    # training

    def next_pseudo(self) -> int:
        if not self.pseudo_order:
            self.pseudo_order = self.pseudo_rng.permutation(len(self.pseudo_cams)).tolist()
        return self.pseudo_order.pop()

    def pseudo_loss(self, out, cam) -> torch.Tensor:
        s = self.settings
        m = cam.mask.to(out.image.dtype)[..., None] if cam.mask is not None else None
        pred = out.image * m if m is not None else out.image
        target = cam.image * m if m is not None else cam.image
        if self._lpips is not None:
            loss = s.lpips_weight * self._lpips(pred, target)
        else:
            loss = s.lpips_weight * losses.l1(out.image, cam.image, cam.mask)
        if s.ssim_weight > 0:
            loss = loss + s.ssim_weight * losses.dssim(pred, target)
        if s.depth_weight > 0 and cam.depth is not None:
            valid = cam.depth > 0
            if int(valid.sum()) > 16:
                loss = loss + s.depth_weight * losses.pearson_depth_loss(out.depth, cam.depth, valid)
        return loss

    def compute_loss(self, out, cam):
        loss, parts = super().compute_loss(out, cam)
        # what the divergence guard judges (warpgs/train.py): the inputs' photometric loss, the same before and
        # after a cycle starts. The depth prior below appears with the first cycle's stereo, and its Pearson
        # term (about 1 at first) made the input loss jump 30x there and stopped a run (castle_p30, 3 views)
        parts["inputs"] = loss
        prior = self.input_depths.get(cam.name)
        if prior is not None and self.settings.input_depth_weight > 0:
            valid = prior > 0
            if int(valid.sum()) > 16:
                dl = losses.pearson_depth_loss(out.depth, prior, valid)
                loss = loss + self.settings.input_depth_weight * dl
                parts["input_depth"] = dl
        if self.pseudo_cams and self.settings.pseudo_weight > 0:
            pc = self.pseudo_cams[self.next_pseudo()]
            po = self.model.render(pc.viewmat, pc.K, pc.width, pc.height, background=self.background,
                                   opacity_scale=self.dropout_scale(self.step))
            pl = self.pseudo_loss(po, pc)
            loss = loss + self.settings.pseudo_weight * pl
            parts["pseudo"] = pl
        return loss, parts

    # ------------------------------------------------------------------------------------------
    # one cycle's pseudo views and densification

    def pseudo_config(self):
        """``cfg.pseudo``, unguided for the render-guidance ablation."""
        pcfg = copy.deepcopy(self.cfg.pseudo)
        if self.settings.guidance == "render":
            pcfg.sampler.guided = False
        return pcfg

    def update_pseudo_views(self, cycle: int) -> dict:
        """Generates this cycle's pseudo views and densifies from them; returns stage times (s)."""
        from warpgs.pseudo.views import generate_pseudo_views, model_renderer, save_sequence

        times = {}
        t0 = time.perf_counter()
        pcfg = self.pseudo_config()
        seqs = generate_pseudo_views(model_renderer(self.model, self.background), self.train_cams, pcfg,
                                     device=self.device)
        times["pseudo_views_s"] = time.perf_counter() - t0
        cams = []
        limit = pcfg.sampler.delta if self.settings.pseudo_mask == "reliable" else 1.0
        for seq in seqs:
            cams += seq.pseudo_cameras(prefix=f"c{cycle}_{seq.start}_{seq.end}", max_uncertainty=limit)
        cycle_dir = self.out / f"cycle_{cycle}" if self.out is not None else None
        if cycle_dir is not None:
            for seq in seqs:
                save_sequence(seq, cycle_dir / "pseudo")
        t0 = time.perf_counter()
        added = 0
        if self.settings.densify and cams:
            added = self.densify(cams, cycle_dir)
        times["densify_s"] = time.perf_counter() - t0
        self.pseudo_cams = cams
        self.pseudo_order = []
        self.log(f"warpgs: cycle {cycle}: {len(cams)} pseudo views ({times['pseudo_views_s']:.1f} s), "
                 f"{added} Gaussians added by densification ({times['densify_s']:.1f} s), {len(self.model)} in all")
        times["added"] = added
        return times

    def apply_growth_budget(self) -> None:
        """With ``growth_budget``: the cycles grow the model to at most that x the Gaussians the baseline
        phase ended with (or what it has now, if more)."""
        if self.settings.growth_budget > 0 and self.history:
            cap = int(self.settings.growth_budget * self.history[0]["num_gaussians"])
            if self.cfg.strategy.max_gaussians > 0:  # within strategy.max_gaussians, too
                cap = min(cap, self.cfg.strategy.max_gaussians)
            self.strategy = dataclasses.replace(self.strategy, max_gaussians=max(cap, len(self.model)))

    def densify(self, cams, cycle_dir: Path | None) -> int:
        from warpgs.densify import densify_gaussians, neighbour_views, select_views
        from warpgs.viz import save_origin_ply

        s = self.settings
        dcfg = copy.deepcopy(self.cfg.densify)
        if not s.point_filter:
            dcfg.filter.std_ratio = float("inf")  # keeps every point: the 'no point filtering' ablation
        # the inputs take part as stereo references and sources (real multi-view evidence); the pseudo
        # views with the lowest covisibility to them and to each other are the other references.
        # stereo_sources 'inputs': every reference is matched against the inputs only. A pseudo view that
        # was filled from the current model's render carries the model's depth, so matching against
        # pseudo views reconstructs that depth, wrong where the model is (synthetic room: median depth
        # error 19% against 0.8% with the inputs as the only sources).
        views = list(self.train_cams) + list(cams)
        n_in = len(self.train_cams)
        if s.stereo_sources == "inputs" and n_in < 2:
            self.log("warpgs: densification skipped: stereo against the inputs needs at least 2 input views")
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
        dens = densify_gaussians(self.model.means.detach(), images, Ks, viewmats, depth_range=self.scene.bounds,
                                 config=dcfg, references=refs, neighbours=neighbours)
        # the plane-sweep depth of the references, where confident, is their depth prior (w3 / w6)
        for v, ref in enumerate(dens.references):
            depth = torch.where(dens.stereo.mask[v], dens.stereo.depth[v], torch.zeros_like(dens.stereo.depth[v]))
            if ref < n_in:
                self.input_depths[views[ref].name] = depth.to(self.device)
            else:
                views[ref].depth = depth.to(self.device)
        ins = dens.insertion
        keep = slice(None) if not s.max_new or len(ins.means) <= s.max_new else slice(0, s.max_new)
        if cycle_dir is not None:
            with torch.no_grad():
                from warpgs.model import sh_to_rgb

                colors = sh_to_rgb(self.model.params["sh0"][:, 0]).clamp(0, 1)
            pts, cols, origin = dens.origin_cloud(self.model.means.detach(), colors)
            save_origin_ply(cycle_dir / "densified.ply", pts, cols, origin)
        return append_gaussians(self, ins.means[keep], ins.colors[keep], ins.scales[keep], s.init_opacity)

    # ------------------------------------------------------------------------------------------
    # checkpoints: the baseline state plus the cycle and its pseudo views

    def method_state(self) -> dict:
        """The pseudo-view order and its generator: a rollback replays the same pseudo views."""
        return {"pseudo": (copy.deepcopy(self.pseudo_rng.bit_generator.state), list(self.pseudo_order))}

    def load_method_state(self, st: dict) -> None:
        if "pseudo" in st:
            self.pseudo_rng.bit_generator.state = copy.deepcopy(st["pseudo"][0])
            self.pseudo_order = list(st["pseudo"][1])

    def checkpoint_state(self) -> dict:
        st = super().checkpoint_state()
        st["full"] = {
            "settings": asdict(self.settings),
            "cycles_done": self.cycles_done,
            "phase": (self.phase_start, self.phase_len),
            "history": self.history,
            "pseudo_rng": self.pseudo_rng.bit_generator.state,
            "pseudo_order": list(self.pseudo_order),
            "input_depths": {k: v.cpu() for k, v in self.input_depths.items()},
            "pseudo_cams": [{"name": c.name, "viewmat": c.viewmat.cpu(), "K": c.K.cpu(), "width": c.width,
                             "height": c.height, "image": c.image.cpu(),
                             "mask": None if c.mask is None else c.mask.cpu(),
                             "depth": None if c.depth is None else c.depth.cpu()} for c in self.pseudo_cams],
        }
        return st

    def load_checkpoint(self, path=None) -> None:
        super().load_checkpoint(path)
        from warpgs.data.scene import CameraTensors

        path = Path(path) if path is not None else self.out / CHECKPOINT
        ck = torch.load(path, map_location="cpu", weights_only=False).get("full")
        if ck is None:
            return
        self.cycles_done = int(ck["cycles_done"])
        self.phase_start, self.phase_len = ck["phase"]
        self.history = list(ck["history"])
        self.pseudo_rng.bit_generator.state = ck["pseudo_rng"]
        self.pseudo_order = list(ck["pseudo_order"])
        dev = self.device
        self.input_depths = {k: v.to(dev) for k, v in ck.get("input_depths", {}).items()}
        self.pseudo_cams = [CameraTensors(name=c["name"], viewmat=c["viewmat"].to(dev), K=c["K"].to(dev),
                                          width=c["width"], height=c["height"], image=c["image"].to(dev),
                                          mask=None if c["mask"] is None else c["mask"].to(dev),
                                          depth=None if c["depth"] is None else c["depth"].to(dev))
                            for c in ck["pseudo_cams"]]


def phase_boundaries(total: int, settings: FullConfig) -> list[int]:
    """Step at which each phase ends: [baseline, cycle 1, ..., cycle C] (the last is ``total``)."""
    if settings.cycles == 0:
        return [total]
    first = int(round(total * settings.baseline_fraction))
    per = (total - first) / settings.cycles
    return [first] + [int(round(first + per * (c + 1))) for c in range(settings.cycles)]


def train_full(trainer: GenerativeTrainer) -> None:
    """Runs (or resumes) the whole loop up to ``train.iterations`` steps."""
    s = trainer.settings
    bounds = phase_boundaries(trainer.total_steps, s)
    if trainer.phase_len is None:
        trainer.phase_start, trainer.phase_len = 0, bounds[0] if s.restart_lr else trainer.total_steps
    trainer.train(bounds[0])
    if not trainer.history:  # the baseline phase, as cycle 0 of the PSNR-per-cycle chart
        ev = trainer.evaluate(lpips=False)["mean"] if trainer.test_cams else {}
        trainer.history.append({"cycle": 0, "step": trainer.step, "psnr": ev.get("psnr"), "ssim": ev.get("ssim"),
                                "num_gaussians": len(trainer.model), "train_s": round(trainer.train_time, 2)})
    for c in range(trainer.cycles_done, s.cycles):
        start, end = bounds[c], bounds[c + 1]
        if trainer.step <= start:  # this cycle's pseudo views are not made yet
            times = trainer.update_pseudo_views(c + 1)
            if s.restart_lr:  # the means' learning-rate schedule restarts (the paper)
                trainer.phase_start, trainer.phase_len = start, end - start
            trainer.save_checkpoint()
        else:
            times = {}
        trainer.apply_growth_budget()  # every cycle, a resumed one too (the strategy's budget is not checkpointed)
        t0 = time.perf_counter()
        trainer.train(end)
        times["train_s"] = time.perf_counter() - t0
        ev = trainer.evaluate(lpips=False)["mean"] if trainer.test_cams else {}
        trainer.history.append({"cycle": c + 1, "step": trainer.step, "psnr": ev.get("psnr"), "ssim": ev.get("ssim"),
                                "num_gaussians": len(trainer.model), **{k: round(v, 2) if isinstance(v, float) else v
                                                                         for k, v in times.items()}})
        trainer.cycles_done = c + 1
        trainer.save_checkpoint()
    if trainer.step < trainer.total_steps:  # a resumed run given more iterations: continue the last phase
        trainer.train(trainer.total_steps)


# ----------------------------------------------------------------------------------------------------
# outputs beside the baseline's: fly-through, charts, report


def write_flythrough(trainer: Trainer, path: Path, frames_per_segment: int = 24, order: str | None = None) -> Path | None:
    """A GIF along the interpolated path through the inputs (the trajectories the pseudo views use;
    ``order`` as ``trajectory.order``)."""
    from PIL import Image

    from warpgs.pseudo.trajectory import path_trajectories

    cams = trainer.train_cams
    if len(cams) < 2:
        return None
    V = np.stack([c.viewmat.detach().cpu().double().numpy() for c in cams])
    cam0 = cams[0]
    frames = []
    with torch.no_grad():
        for traj in path_trajectories(V, max(frames_per_segment, 2), order):
            for vm in traj.viewmats:
                v = torch.as_tensor(vm, dtype=torch.float32, device=trainer.device)
                img = trainer.model.render(v, cam0.K, cam0.width, cam0.height, background=trainer.background).image
                frames.append(Image.fromarray((img.clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)))
    path.parent.mkdir(parents=True, exist_ok=True)
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=80, loop=0)
    return path


def write_report(out: Path, metrics: dict, history: list[dict], baseline: dict | None = None) -> Path:
    """report.md with PNG charts: test PSNR per cycle (baseline as a line) and time per stage."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    charts = out / "charts"
    charts.mkdir(parents=True, exist_ok=True)
    cyc = [h["cycle"] for h in history]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    ax.plot(cyc, [h["psnr"] for h in history], "o-", label="full method")
    if baseline is not None and baseline.get("psnr") is not None:
        ax.axhline(baseline["psnr"], color="gray", ls="--", label=f"baseline ({baseline['iterations']} it)")
    ax.set_xlabel("cycle (0 = before the first pseudo views)")
    ax.set_ylabel("test PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(charts / "psnr_per_cycle.png", dpi=120)
    plt.close(fig)

    stages = [("train_s", "training"), ("pseudo_views_s", "pseudo views"), ("densify_s", "densification")]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    bottom = np.zeros(len(history))
    for key, label in stages:
        vals = np.array([h.get(key, 0.0) or 0.0 for h in history])
        ax.bar(cyc, vals, bottom=bottom, label=label)
        bottom += vals
    ax.set_xlabel("cycle")
    ax.set_ylabel("wall time (s)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(charts / "time_per_stage.png", dpi=120)
    plt.close(fig)

    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    lines = [f"# {metrics['method']} on {metrics['scene']}", "",
             f"{metrics['train_views']} training views, {metrics['test_views']} test views at "
             f"{metrics['resolution'][0]}x{metrics['resolution'][1]}, {metrics['iterations']} iterations on "
             f"{metrics['device']}.", "",
             "| run | PSNR | SSIM | LPIPS | Gaussians | training time (s) |", "|---|---|---|---|---|---|"]
    for name, m in (("baseline", baseline), ("full method", metrics)):
        if m is not None:
            lines.append(f"| {name} | {f(m['psnr'], '.2f')} | {f(m['ssim'], '.3f')} | {f(m.get('lpips'), '.3f')} | "
                         f"{m['num_gaussians']} | {f(m['train_time_s'], '.1f')} |")
    lines += ["", "## Per cycle", "", "| cycle | step | PSNR | SSIM | Gaussians | added | pseudo views (s) | "
              "densification (s) | training (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for h in history:
        lines.append(f"| {h['cycle']} | {h['step']} | {f(h['psnr'], '.2f')} | {f(h['ssim'], '.3f')} | "
                     f"{h['num_gaussians']} | {h.get('added', '-')} | {f(h.get('pseudo_views_s'), '.1f')} | "
                     f"{f(h.get('densify_s'), '.1f')} | {f(h.get('train_s'), '.1f')} |")
    lines += ["", f"Pseudo-view loss: {metrics.get('pseudo_loss', 'n/a')}"
              + (f" (LPIPS unavailable: {metrics['lpips_fallback_reason']})" if metrics.get("lpips_fallback_reason")
                 else ""), "",
              "![test PSNR per cycle](charts/psnr_per_cycle.png)", "", "![time per stage](charts/time_per_stage.png)",
              "", "Outputs: `cycle_N/pseudo/` (pseudo views, guidance, uncertainty), `cycle_N/densified.ply` "
              "(`python -m warpgs.viz` colours kept / added / removed), `point_cloud.ply`, `test/`, "
              "`flythrough.gif`, `metrics.json`."]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def finish_full(trainer: GenerativeTrainer, baseline: dict | None = None) -> dict:
    """``Trainer.finish`` plus the method's own records, the fly-through and the report."""
    metrics = trainer.finish()
    metrics["full"] = asdict(trainer.settings)
    metrics["cycles"] = trainer.history
    metrics["pseudo_loss"] = trainer.pseudo_loss_used
    if trainer.lpips_missing:
        metrics["lpips_fallback_reason"] = trainer.lpips_missing
    if trainer.out is not None:
        # the method's records go into metrics.json before the slower fly-through and report, so a run
        # stopped while those are written keeps them
        tmp = trainer.out / "metrics.json.tmp"
        tmp.write_text(json.dumps(metrics, indent=2))
        tmp.replace(trainer.out / "metrics.json")
        write_flythrough(trainer, trainer.out / "flythrough.gif", trainer.settings.flythrough_frames,
                         trainer.pseudo_config().trajectory.order)
        write_report(trainer.out, metrics, trainer.history, baseline)
    return metrics
