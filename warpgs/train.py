"""Training and evaluation of a 3D-GS model on a ``Scene``: the sparse-view baseline.

    trainer = Trainer(cfg, scene, out_dir)       # initialises the model (or resumes: trainer.resume())
    trainer.train()                               # progress bar with loss / PSNR, checkpoints, Ctrl-C
    result = trainer.finish()                     # compaction, test metrics, renders, PLY, metrics.json

One input view per iteration (3D-GS's shuffled order); loss = 0.8 L1 + 0.2 D-SSIM (+ a Pearson depth term
when ``loss.depth_weight`` > 0 and the view has a depth prior); Adam with 3D-GS's learning rates and an
exponentially decaying position rate; densification by ``DefaultStrategy``.

Reproducibility: ``train.seed`` seeds the initialisation, the view order and the split noise (each
its own generator, all saved in checkpoints, so a resumed run continues exactly as an uninterrupted
one). On the CPU, Warp's kernels run on one thread, so two runs with one seed give identical numbers.

Checkpoints (``checkpoint.pt`` in the output folder) are written every ``train.checkpoint_every``
steps through a temporary file and a rename, so an interruption never leaves a broken one. Ctrl-C
finishes the current step, writes a checkpoint and stops (``TrainingInterrupted``); a second Ctrl-C
stops at once, keeping the last checkpoint.
"""

from __future__ import annotations

import dataclasses
import json
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
from warpgs.config import Config, config_from_dict, save_config, to_dict
from warpgs.metrics import LPIPSMetric, mean_or_none, peak_memory_mb, psnr, render_fps, ssim
from warpgs.model import GaussianModel, read_point_cloud

CHECKPOINT = "checkpoint.pt"


class TrainingInterrupted(Exception):
    """Training stopped on request (Ctrl-C) after saving a checkpoint."""

    def __init__(self, step: int, checkpoint: Path | None):
        super().__init__(f"interrupted at step {step}" + (f"; checkpoint {checkpoint}" if checkpoint else ""))
        self.step, self.checkpoint = step, checkpoint


class TrainingDiverged(RuntimeError):
    pass


def resolve_device(name: str) -> torch.device:
    if name in ("auto", "", None):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    dev = torch.device(name)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise RuntimeError(f"device {name!r} was asked for, but torch sees no CUDA device")
    if dev.type not in ("cpu", "cuda"):
        raise RuntimeError(f"device {name!r}: warpgs runs on cpu or cuda")
    return dev


def scene_scale_of(cameras) -> float:
    """3D-GS's ``cameras_extent``: 1.1 x the largest distance of a camera centre from their mean."""
    centres = np.stack([c.center for c in cameras])
    r = float(np.linalg.norm(centres - centres.mean(0), axis=1).max()) if len(centres) > 1 else 0.0
    return 1.1 * (r if r > 1e-6 else 1.0)


def init_model(cfg: Config, scene, generator: torch.Generator) -> GaussianModel:
    """The initial Gaussians (on the CPU) as ``cfg.model.init`` says."""
    m = cfg.model
    kw = dict(sh_degree=m.sh_degree, init_opacity=m.init_opacity, init_scale=m.init_scale)
    near, far = (m.init_depth if m.init_depth is not None else scene.bounds)
    if m.init == "points":
        if scene.points3d is None or len(scene.points3d) == 0:
            raise ValueError("model.init=points, but the scene has no points (the loaders read them with "
                             "data.options.load_points=true; note they are triangulated from all views)")
        return GaussianModel.from_points(scene.points3d, scene.points_rgb, **kw)
    if m.init == "ply":
        if not m.init_ply:
            raise ValueError("model.init=ply needs model.init_ply=/path/to/points.ply")
        xyz, rgb = read_point_cloud(m.init_ply)
        return GaussianModel.from_points(xyz, rgb, **kw)
    if m.init == "frustum":
        cams = scene.train
        return GaussianModel.random_frustum(m.init_num, [c.viewmat for c in cams], [c.K for c in cams],
                                            [(c.width, c.height) for c in cams], float(near), float(far),
                                            generator=generator, **kw)
    if m.init == "box":
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
        return GaussianModel.random_box(m.init_num, lo, hi, generator=generator, **kw)
    raise ValueError(f"model.init={m.init!r}: expected box, frustum, points or ply")


def make_optimizer(model: GaussianModel, cfg: Config, scene_scale: float) -> torch.optim.Adam:
    o = cfg.optim
    lrs = {"means": o.means_lr * scene_scale, "quats": o.quats_lr, "scales": o.scales_lr,
           "opacities": o.opacities_lr, "sh0": o.sh0_lr, "shN": o.shN_lr}
    groups = [{"params": [model.params[k]], "lr": lrs[k], "name": k} for k in model.params.keys()]
    return torch.optim.Adam(groups, eps=o.eps)


def save_png(path: Path, image: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path)


def _atomic_torch_save(obj, path: Path) -> None:
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    torch.save(obj, tmp)
    os.replace(tmp, path)


class Trainer:
    def __init__(self, cfg: Config, scene, out_dir: str | Path | None = None, *, log=None):
        self.cfg, self.scene = cfg, scene
        self.out = Path(out_dir) if out_dir is not None else None
        self.log = log or (lambda msg: print(msg, file=sys.stderr))
        self.device = resolve_device(cfg.train.device)
        if self.device.type == "cpu" and cfg.train.cpu_threads > 0:
            # The images are small and Warp's CPU kernels run on one thread: more torch threads gain
            # little, and on a busy machine their synchronisation made small ops 50x slower.
            torch.set_num_threads(cfg.train.cpu_threads)
        if not scene.train:
            raise ValueError(f"{scene.name}: no training views")
        self.train_cams = [c.to_torch(self.device) for c in scene.train]
        self.test_cams = [c.to_torch(self.device) for c in scene.test]
        bg = cfg.train.background
        if bg is None:
            bg = [1.0, 1.0, 1.0] if scene.white_background else [0.0, 0.0, 0.0]
        self.background = torch.tensor(bg, dtype=torch.float32, device=self.device)
        self.scene_scale = cfg.optim.scene_scale or scene_scale_of(scene.train)
        self.strategy = cfg.strategy
        seed = cfg.train.seed
        torch.manual_seed(seed)
        np.random.seed(seed % 2**32)
        init_gen = torch.Generator().manual_seed(seed)
        self.model = init_model(cfg, scene, init_gen).to(self.device)
        self.split_gen = torch.Generator(device=self.device).manual_seed(seed + 1)
        self.view_rng = np.random.default_rng(seed + 2)
        self.order: list[int] = []
        self.optimizer = make_optimizer(self.model, cfg, self.scene_scale)
        self.state = self.strategy.initialize_state(len(self.model), self.device)
        self.step = 0
        self.train_time = 0.0
        self.losses: list[float] = []
        self.nan_steps = 0
        self.curve: list[dict] = []  # test metrics every train.eval_every steps (PSNR against time)
        self.initial: dict | None = None
        self.n_before_compaction: int | None = None
        self._stop = False
        self._ema = {}

    # ------------------------------------------------------------------------------------------
    # training

    @property
    def total_steps(self) -> int:
        return self.cfg.train.iterations

    def means_lr(self, step: int) -> float:
        o = self.cfg.optim
        n = o.means_lr_decay_steps or self.total_steps
        t = min(max(step / max(n, 1), 0.0), 1.0)
        return self.scene_scale * math.exp((1 - t) * math.log(o.means_lr) + t * math.log(o.means_lr_final))

    def next_view(self) -> int:
        if not self.order:
            self.order = self.view_rng.permutation(len(self.train_cams)).tolist()
        return self.order.pop()

    def compute_loss(self, out, cam) -> tuple[torch.Tensor, dict]:
        lc = self.cfg.loss
        l1 = losses.l1(out.image, cam.image)
        loss = lc.l1_weight * l1
        parts = {"l1": l1}
        if lc.ssim_weight > 0:
            ds = losses.dssim(out.image, cam.image)
            loss = loss + lc.ssim_weight * ds
            parts["dssim"] = ds
        if lc.depth_weight > 0 and lc.depth_prior == "scene" and cam.depth is not None:
            dl = losses.pearson_depth_loss(out.depth, cam.depth)
            loss = loss + lc.depth_weight * dl
            parts["depth"] = dl
        return loss, parts

    def train_step(self) -> dict:
        """One iteration at ``self.step`` (does not advance it)."""
        step = self.step
        self.model.active_sh_degree = min(step // max(self.cfg.train.sh_degree_interval, 1), self.model.max_sh_degree)
        for g in self.optimizer.param_groups:
            if g["name"] == "means":
                g["lr"] = self.means_lr(step)
        cam = self.train_cams[self.next_view()]
        bg = self.background
        if self.cfg.train.random_background and cam.alpha is not None:
            # target over a random colour: image = rgb a + bg (1 - a)  ->  image + (1 - a) (new_bg - bg)
            bg = torch.rand(3, device=self.device, generator=self.split_gen)
            cam = dataclasses.replace(cam, image=cam.image + (1 - cam.alpha)[..., None] * (bg - self.background))
        out = self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg)
        loss, parts = self.compute_loss(out, cam)
        loss.backward()
        # one device sync for the whole guard: the loss and every gradient must be finite
        checks = [torch.isfinite(loss)] + [torch.isfinite(p.grad).all() for p in self.model.params.values()
                                           if p.grad is not None]
        if not bool(torch.stack(checks).all()):
            bad = [n for n, p in self.model.params.items() if p.grad is not None and not bool(torch.isfinite(p.grad).all())]
            return self._skip(step, "the loss is not finite" if not bool(torch.isfinite(loss))
                              else f"the gradient of {', '.join(bad)} is not finite")
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        self.nan_steps = 0
        info = self.strategy.step_post_backward(self.model, self.optimizer, self.state, step, out,
                                                cam.width, cam.height, self.scene_scale, generator=self.split_gen)
        s = self.strategy
        if (s.compact_when_full and s.max_gaussians > 0 and (info["cloned"] or info["split"] or info["pruned"])
                and len(self.model) >= s.max_gaussians):
            # the budget is spent: free what the training views do not use, so growth can go on where it helps
            info["compacted"] = s.compact(self.model, self.optimizer, self.state, self.train_cams, self.background)
        value = float(loss.detach())
        self.losses.append(value)
        with torch.no_grad():
            mse = float(((out.image.detach().clamp(0, 1) - cam.image) ** 2).mean())
        return {"loss": value, "psnr": -10 * math.log10(max(mse, 1e-10)), **info}

    def _skip(self, step: int, why: str) -> dict:
        self.optimizer.zero_grad(set_to_none=True)
        self.nan_steps += 1
        self.log(f"warpgs: step {step} skipped: {why}")
        if self.nan_steps >= self.cfg.train.max_nan_steps:
            where = f"; the last good checkpoint is {self.out / CHECKPOINT}" if self.out and (self.out / CHECKPOINT).exists() else ""
            raise TrainingDiverged(f"training diverged: {self.nan_steps} consecutive steps without a finite loss "
                                   f"and gradient (step {step}){where}")
        self.losses.append(float("nan"))
        return {"loss": float("nan"), "psnr": float("nan"), "skipped": 1}

    def train(self, iterations: int | None = None) -> None:
        """Trains until ``iterations`` (default ``train.iterations``) steps are done."""
        from tqdm import tqdm

        total = self.total_steps if iterations is None else iterations
        if self.initial is None and self.step == 0 and self.test_cams:
            self.initial = self.evaluate(save_dir=None, lpips=False)["mean"]
        restore = self._install_sigint()
        bar = tqdm(total=total, initial=self.step, desc=f"{self.cfg.method} {self.scene.name}", unit="it",
                   dynamic_ncols=True, disable=not self.cfg.train.progress, file=sys.stderr)
        every = self.cfg.train.checkpoint_every
        ev_every = self.cfg.train.eval_every
        t0 = time.perf_counter()
        try:
            while self.step < total:
                info = self.train_step()
                self.step += 1
                bar.update(1)
                self._update_bar(bar, info)
                if self._stop:
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

    def checkpoint_state(self) -> dict:
        return {
            "format": 1,
            "step": self.step,
            "config": to_dict(self.cfg),
            "scene": self.scene.name,
            "params": {k: v.detach().cpu() for k, v in self.model.params.items()},
            "max_sh_degree": self.model.max_sh_degree,
            "optimizer": self.optimizer.state_dict(),
            "strategy_state": {k: v.cpu() for k, v in self.state.items()},
            "split_gen": self.split_gen.get_state(),
            "view_rng": self.view_rng.bit_generator.state,
            "order": list(self.order),
            "torch_rng": torch.get_rng_state(),
            "train_time": self.train_time,
            "losses": list(self.losses),
            "curve": list(self.curve),
            "initial": self.initial,
            "n_before_compaction": self.n_before_compaction,
        }

    def save_checkpoint(self, path: str | Path | None = None) -> Path | None:
        if path is None:
            if self.out is None:
                return None
            path = self.out / CHECKPOINT
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        _atomic_torch_save(self.checkpoint_state(), path)
        return path

    def load_checkpoint(self, path: str | Path | None = None) -> None:
        path = Path(path) if path is not None else self.out / CHECKPOINT
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no checkpoint to resume from")
        ck = torch.load(path, map_location="cpu", weights_only=False)
        saved = config_from_dict(ck["config"])
        for section in ("model", "optim", "loss", "strategy"):
            if to_dict(getattr(saved, section)) != to_dict(getattr(self.cfg, section)):
                self.log(f"warpgs: note: the checkpoint's {section} config differs from this run's; using this run's")
        p = ck["params"]
        self.model = GaussianModel(p["means"], p["quats"], p["scales"], p["opacities"], p["sh0"], p["shN"],
                                   max_sh_degree=ck["max_sh_degree"]).to(self.device)
        self.optimizer = make_optimizer(self.model, self.cfg, self.scene_scale)
        self.optimizer.load_state_dict(ck["optimizer"])
        self.state = {k: v.to(self.device) for k, v in ck["strategy_state"].items()}
        self.split_gen.set_state(ck["split_gen"])
        self.view_rng.bit_generator.state = ck["view_rng"]
        self.order = list(ck["order"])
        torch.set_rng_state(ck["torch_rng"])
        self.step = int(ck["step"])
        self.model.active_sh_degree = min(self.step // max(self.cfg.train.sh_degree_interval, 1), self.model.max_sh_degree)
        self.train_time = float(ck["train_time"])
        self.losses = list(ck["losses"])
        self.curve = list(ck.get("curve", []))
        self.initial = ck.get("initial")
        self.n_before_compaction = ck.get("n_before_compaction")

    # ------------------------------------------------------------------------------------------
    # evaluation and outputs

    def render(self, cam):
        return self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=self.background)

    def evaluate(self, cameras=None, save_dir: str | Path | None = None, lpips: bool = True) -> dict:
        """Metrics over ``cameras`` (default: the test views), masked where the scene's protocol says;
        with ``save_dir``, writes each render beside its ground truth as a PNG."""
        cams = self.test_cams if cameras is None else cameras
        masked = bool(self.scene.eval_masked)
        lp = LPIPSMetric(self.cfg.eval.lpips_weights, self.device) if lpips else None
        views = []
        with torch.no_grad():
            for i, cam in enumerate(cams):
                img = self.render(cam).image.clamp(0, 1)
                mask = cam.mask if masked else None
                if masked and mask is None:
                    raise ValueError(f"{self.scene.name}: masked evaluation, but view {cam.name} has no mask")
                row = {"name": cam.name, "psnr": psnr(img, cam.image, mask), "ssim": ssim(img, cam.image, mask)}
                if lp is not None:
                    row["lpips"] = lp.value(img, cam.image, mask)
                views.append(row)
                if save_dir is not None:
                    pair = torch.cat([img, cam.image], dim=1).cpu().numpy()
                    save_png(Path(save_dir) / f"{i:03d}_{cam.name}.png", pair)
        mean = {"psnr": mean_or_none([v["psnr"] for v in views]), "ssim": mean_or_none([v["ssim"] for v in views])}
        result = {"mean": mean, "views": views, "masked": masked}
        if lp is not None:
            mean["lpips"] = mean_or_none([v["lpips"] for v in views])
            if lp.missing:
                result["lpips_missing"] = lp.missing
        return result

    def compact(self) -> int:
        """Final compaction (``train.compact``): drops what no training view uses."""
        if self.n_before_compaction is None:
            self.n_before_compaction = len(self.model)
        return self.strategy.compact(self.model, self.optimizer, self.state, self.train_cams, self.background)

    def export_ply(self, path: str | Path | None = None) -> Path:
        return self.model.save_ply(Path(path) if path is not None else self.out / "point_cloud.ply")

    def finish(self) -> dict:
        """After training: compaction, test metrics and renders, FPS, PLY, final checkpoint, metrics.json."""
        out = self.out
        if self.cfg.train.compact:
            removed = self.compact()
            if removed:
                self.log(f"warpgs: compaction removed {removed} of {self.n_before_compaction} Gaussians")
        ev = self.evaluate(save_dir=(out / "test") if out is not None and self.cfg.eval.save_images else None)
        train_ev = self.evaluate(self.train_cams, lpips=False)
        fps = render_fps(lambda i: self.render(self.test_cams[i] if self.test_cams else self.train_cams[i]),
                         len(self.test_cams) or len(self.train_cams), self.cfg.eval.fps_repeats, self.device)
        finite = [x for x in self.losses if math.isfinite(x)]
        cam0 = self.scene.test[0] if self.scene.test else self.scene.train[0]
        metrics = {
            "method": self.cfg.method,
            "scene": self.scene.name,
            "train_views": len(self.scene.train),
            "test_views": len(self.scene.test),
            "resolution": [cam0.width, cam0.height],
            "iterations": self.step,
            "psnr": ev["mean"]["psnr"],
            "ssim": ev["mean"]["ssim"],
            "lpips": ev["mean"].get("lpips"),
            "masked": ev["masked"],
            "initial_psnr": (self.initial or {}).get("psnr"),
            "train_psnr": train_ev["mean"]["psnr"],
            "num_gaussians": len(self.model),
            "num_gaussians_before_compaction": self.n_before_compaction,
            "train_time_s": round(self.train_time, 2),
            "render_fps": round(fps, 2),
            **peak_memory_mb(self.device),
            "device": str(self.device),
            "seed": self.cfg.train.seed,
            "final_loss": float(np.mean(finite[-50:])) if finite else None,
            "skipped_steps": sum(1 for x in self.losses if not math.isfinite(x)),
            "curve": self.curve,
            "per_view": ev["views"],
        }
        if "lpips_missing" in ev:
            metrics["lpips_missing"] = ev["lpips_missing"]
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            self.export_ply()
            self.save_checkpoint()
            save_config(self.cfg, out / "config.yaml")
            tmp = out / "metrics.json.tmp"
            tmp.write_text(json.dumps(metrics, indent=2))
            tmp.replace(out / "metrics.json")
        return metrics


def load_trained(path: str | Path, device="cpu") -> GaussianModel:
    """A model from a checkpoint (``checkpoint.pt``) or a 3D-GS PLY."""
    path = Path(path)
    if path.suffix == ".ply":
        return GaussianModel.load_ply(path, device=device)
    ck = torch.load(path, map_location="cpu", weights_only=False)
    p = ck["params"]
    m = GaussianModel(p["means"], p["quats"], p["scales"], p["opacities"], p["sh0"], p["shN"],
                      max_sh_degree=ck["max_sh_degree"])
    m.active_sh_degree = m.max_sh_degree
    return m.to(device)
