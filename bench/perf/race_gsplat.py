"""A like-for-like race: gsplat 1.5.3's own training recipe against warpgs's trainer configured to the same recipe.

    python bench/perf/race_gsplat.py --all                      # fern3, castle9, lego8; CUDA + gsplat 1.5.3
    python bench/perf/race_gsplat.py --scale lego8 --profile    # one scale, with a profile where the ratio > 0.75
    python bench/perf/race_gsplat.py --device cpu --shrink 8 --iterations 60 --all   # the warpgs side only (plumbing)

Scales (``SCALES``): ``fern3`` (LLFF fern, 3 views, 504x378), ``castle9`` (castle_p30, DL3DV layout, 9 views at
images_4: 768x512) and ``lego8`` (Blender lego, 8 views at 800x800, trained and tested at full size). Each scale
loads its scene with warpgs's loaders (``--data-root``: the folder of the real scenes, default ``../shared/data``
or ``shared/data``), finds the initial points once with warpgs's initialisation for that dataset (fern: SfM +
plane-sweep stereo between the 3 views; castle: SfM between the 9 views; lego: random points in the visual hull
of the inputs) and gives both sides the same initial Gaussians, built as gsplat's examples/simple_trainer.py
builds them from points: scales log(3-NN mean distance), quats ``torch.rand`` after ``torch.manual_seed(42)``
(unnormalised, as simple_trainer draws them), opacities logit(0.1), sh0 from the points' colours, shN zero.

The recipe (gsplat 1.5.3, examples/simple_trainer.py's defaults; ``RECIPE``, ``gsplat_strategy_defaults``):
SH degree 3, one more degree every 1000 steps; Adam per parameter (eps 1e-15) at means 1.6e-4 x scene scale
decaying exponentially to 0.01x over the run (``ExponentialLR``, gamma 0.01^(1/steps)), scales 5e-3, quats 1e-3,
opacities 5e-2, sh0 2.5e-3, shN 2.5e-3/20; loss 0.8 L1 + 0.2 (1 - SSIM); ``DefaultStrategy()`` as its dataclass
defaults (grow_grad2d 2e-4, grow_scale3d 0.01, prune_scale3d 0.1, prune_opa 0.005, refine 500..15000 every 100,
opacity reset every 3000, absgrad off), ``rasterization(packed=False, rasterize_mode="classic")``, batch 1, no
random background, no regulariser. Both sides train the views in one shuffled order (the trainer's, for
``--seed``) and over the same background (black; white for lego, whose images are composited on white).

- ``gsplat`` side (CUDA, gsplat importable): that loop written with gsplat's library API only (``rasterization``,
  ``DefaultStrategy.step_pre_backward / step_post_backward``), ``torch.optim.Adam`` per parameter as
  simple_trainer makes it, the strategy called after the optimisers and the scheduler, as there. Its D-SSIM is
  ``fused_ssim(..., padding="valid")`` where the ``fused_ssim`` package is importable (simple_trainer's), else
  warpgs's own D-SSIM (``warpgs.losses.dssim``: the same loss code on both sides; the JSON says which). Left out
  of simple_trainer's loop: its per-step ``loss.item()`` (the progress bar), tensorboard every 100 steps, the
  viewer, checkpoints and the DataLoader (the images sit on the GPU, as the trainer's do): host reads and I/O that
  would only slow gsplat down, so its time here is a lower bound on simple_trainer's.
- ``warpgs`` side: ``Trainer.train`` as ``python -m warpgs.pipelines.sparse --method baseline`` builds it (its
  step guard, deferred host reads, CUDA graphs), with ``recipe_overrides``: every regulariser and every dataset
  default that is not 3D-GS off (dropout, opacity noise and decay, the binocular term, the far field, path
  clearance and floaters, held geometry, random background, the final pruning, compact mode, the budget), the
  strategy's thresholds set to gsplat's, and the race's scene scale. ``plain_problems`` checks the built
  trainer (no regulariser, nothing held, nothing that prunes but the strategy); the race refuses to run otherwise.

Scene scale: simple_trainer's is 1.1 x the largest distance of a camera centre from their mean over every image its
Parser reads (test views too); warpgs's (``scene_scale_of``) is the same formula over the training views. The race
gives both sides the training views' value (``optim.scene_scale``; a gsplat run on the sparse inputs reads only
them); the JSON also records the value over training and test views. gsplat's Parser also normalises the world
(a similarity): every threshold that is in world units is x scene scale, so this changes nothing but the near
plane (0.01 in both).

Timing: each side first trains ``--warmup`` steps with a compressed schedule (every SH degree, growth, pruning and
an opacity reset: gsplat's CUDA kernels compile on first use, about a minute, and Warp's load), untimed; then
``--iterations`` steps (default 7000) timed with ``time.perf_counter`` between two ``torch.cuda.synchronize()``;
gsplat's run first. Reported per scale: seconds, it/s, final Gaussian count, train and test PSNR of each side
(each rendered by its own rasterizer; the loader's test views: LLFF's / DL3DV's every 8th frame, Blender's test
split as warpgs's loader lists it, here at 800x800), the ratio warpgs / gsplat of the times, the counts' relative
difference, and ``counts_within_5pct``, ``psnr_within_0p2db``, ``goal_0p75`` (ratio <= 0.75). With ``--repeats N``
each side runs N times, alternating, the checks use the medians, and the JSON keeps every run (``<side>_runs``) and
each side's spread (``<side>_spread``: gsplat against itself is what the checks are judged by). With ``--profile``,
each scale whose ratio is over 0.75 (every scale on the CPU) trains ``--profile-steps`` more steps on each side
under ``torch.profiler`` (continuing the timed run: the grown model, refinements included) and the JSON gets
each side's wall time, its total device time and its top CUDA kernels and CPU ops.

Output: bench/results/perf/race_gsplat_<gpu>.json (``cpu`` on the CPU; the scales of a run replace those of an
earlier file, so scales may be run one by one), with the machine (GPU, torch, Warp, gsplat, the commit, the date)
and the seeds; one line per scale on stdout.

Time on one H200 (1f001bc, 2026-11-29): gsplat's first-use compilation 66 s; castle9: SfM 12 s, then 50 s of
gsplat's training and 24 s of warpgs's; lego8's whole call 97 s (compiled already); fern3 (150,000 initial
Gaussians from SfM + stereo) had not finished both sides after 3 minutes. Under a 10-minute limit run
``--scale fern3``, then ``--scale castle9 --scale lego8``: each call writes into the same JSON (written after every
scale). The CPU smoke (``--device cpu --shrink 8 --iterations 60 --all``) takes about a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import datetime
import gc
import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench.perf.rasterizer import write_result  # noqa: E402
from bench.perf.train_speed import gsplat_available, load_scene, machine, mean_psnr, sync, view_order  # noqa: E402

# scale -> the scene (warpgs.pipelines.sparse's flags: --data, --scene, --views, --downscale) and its extra --set
SCALES = {
    "fern3": {"data": "llff", "scene": "fern", "views": 3},
    "castle9": {"data": "{root}/castle_p30", "views": 9, "downscale": 4},
    "lego8": {"data": "blender", "scene": "lego", "views": 8, "downscale": 1, "set": ["data.options.test_downscale=1"]},
}

# gsplat 1.5.3 examples/simple_trainer.py Config's defaults that the race uses
RECIPE = {"sh_degree": 3, "sh_degree_interval": 1000, "init_opa": 0.1, "init_scale": 1.0, "ssim_lambda": 0.2,
          "means_lr": 1.6e-4, "means_lr_final_factor": 0.01, "scales_lr": 5e-3, "quats_lr": 1e-3,
          "opacities_lr": 5e-2, "sh0_lr": 2.5e-3, "shN_lr": 2.5e-3 / 20, "adam_eps": 1e-15, "batch_size": 1,
          "packed": False, "absgrad": False, "rasterize_mode": "classic", "near_plane": 0.01, "far_plane": 1e10,
          "random_bkgd": False, "seed": 42,
          # not Config fields, what the package does: its kernels cap a Gaussian's alpha at 0.999, and its
          # DefaultStrategy never resets the opacities (`step % reset_every == 0 & step > 0` parses as a chained
          # comparison ending in `0 > 0`; gsplat PR #776), while it prunes the too large after reset_every
          "alpha_max": 0.999, "reset_opacity": False}

# gsplat 1.5.3 gsplat/strategy/default.py: DefaultStrategy's dataclass defaults (the keys warpgs's strategy shares)
GSPLAT_STRATEGY = {"prune_opa": 0.005, "grow_grad2d": 0.0002, "grow_scale3d": 0.01, "grow_scale2d": 0.05,
                   "prune_scale3d": 0.1, "prune_scale2d": 0.15, "refine_scale2d_stop_iter": 0, "refine_start_iter": 500,
                   "refine_stop_iter": 15_000, "reset_every": 3000, "refine_every": 100, "pause_refine_after_reset": 0}

# the warm-up's compressed schedule: every SH degree, growth, pruning and an opacity reset within a few dozen steps
WARMUP_SCHEDULE = {"sh_degree_interval": 8, "refine_start_iter": 10, "refine_every": 10, "reset_every": 30}

GOAL = 0.75


def gsplat_strategy_defaults() -> dict:
    """DefaultStrategy's dataclass defaults: gsplat's own where it is importable, else ``GSPLAT_STRATEGY``."""
    if not gsplat_available():
        return dict(GSPLAT_STRATEGY)
    from gsplat.strategy import DefaultStrategy

    d = DefaultStrategy()
    return {k: getattr(d, k) for k in GSPLAT_STRATEGY}


def recipe_overrides(strategy: dict, scene_scale: float | None = None) -> list[str]:
    """warpgs's config set to the recipe (``--set`` values): the baseline's learning rates, loss and SH schedule as
    simple_trainer's, every regulariser and every non-3D-GS dataset default off, the strategy's thresholds
    ``strategy``, and ``scene_scale`` when given."""
    r = RECIPE
    sets = {
        "model.sh_degree": r["sh_degree"], "model.init_opacity": r["init_opa"], "model.init_scale": r["init_scale"],
        "model.alpha_max": r["alpha_max"], "strategy.reset_opacity": str(r["reset_opacity"]).lower(),
        "train.sh_degree_interval": r["sh_degree_interval"],
        "optim.means_lr": r["means_lr"], "optim.means_lr_final": r["means_lr"] * r["means_lr_final_factor"],
        "optim.means_lr_decay_steps": "null", "optim.scales_lr": r["scales_lr"], "optim.quats_lr": r["quats_lr"],
        "optim.opacities_lr": r["opacities_lr"], "optim.sh0_lr": r["sh0_lr"], "optim.shN_lr": r["shN_lr"],
        "optim.eps": r["adam_eps"],
        "loss.l1_weight": 1.0 - r["ssim_lambda"], "loss.ssim_weight": r["ssim_lambda"], "loss.depth_weight": 0,
        "loss.alpha_weight": 0,
        # the regularisers (warpgs.regularizers), each off
        "regularizers.alpha_binary.weight": 0, "regularizers.scale_reg.weight": 0, "regularizers.dropout.rate": 0,
        "regularizers.opacity_noise.sigma": 0, "regularizers.opacity_decay.rate": 0,
        "regularizers.binocular.weight": 0, "regularizers.path_consistency.weight": 0,
        # the datasets' defaults that are not 3D-GS (configs/datasets/*.yaml)
        "train.random_background": "false", "backgrounds.far_field.kind": "none", "clearance.path": 0,
        "clearance.view": 0, "clearance.floaters": 0, "hold.geometry": "off",
        "strategy.prune_unseen_at_end": "false", "corgs.pair": "false", "train.eval_every": 0,
        "compact.enabled": "false",
        "strategy.refine_stop_fraction": 0, "strategy.max_gaussians": 0,
        **{f"strategy.{k}": v for k, v in strategy.items()},
    }
    if scene_scale is not None:
        sets["optim.scene_scale"] = repr(float(scene_scale))
    return [f"{k}={v}" for k, v in sets.items()]


def scale_argv(scale: str, data_root: str | None, iterations: int, device: str, seed: int) -> list[str]:
    """``python -m warpgs.pipelines.sparse``'s arguments for a scale (before the recipe's ``--set``)."""
    s = SCALES[scale]
    argv = ["--data", s["data"].format(root=data_root or "../shared/data"), "--views", str(s["views"]),
            "--method", "baseline", "--iterations", str(iterations), "--device", device, "--seed", str(seed),
            "--no-progress"]
    if s.get("scene"):
        argv += ["--scene", s["scene"]]
    if s.get("downscale"):
        argv += ["--downscale", str(s["downscale"])]
    if data_root and "{root}" not in s["data"]:
        argv += ["--data-root", data_root]
    for v in s.get("set", []):
        argv += ["--set", v]
    return argv


def make_config(scale: str, data_root: str | None, iterations: int, device: str, seed: int, strategy: dict,
                scene_scale: float | None = None):
    """The race's warpgs config for ``scale`` (the CLI's layers, then ``recipe_overrides``)."""
    from warpgs.pipelines.sparse import build_parser, make_config as cli_config

    argv = scale_argv(scale, data_root, iterations, device, seed)
    for s in recipe_overrides(strategy, scene_scale):
        argv += ["--set", s]
    cfg, _ = cli_config(build_parser().parse_args(argv))
    return cfg


def plain_problems(tr, strategy: dict) -> list[str]:
    """What in a built trainer is not the plain recipe (empty: nothing): regularisers, held geometry, a far field,
    path pruning, a second model, compact mode's stages, a random background, a loss other than simple_trainer's,
    a strategy other than ``DefaultStrategy`` with thresholds ``strategy``, a budget, a growth schedule cut short."""
    from warpgs.strategy import DefaultStrategy

    out = []
    # the dropout is built at rate 0 too (the full method may set its own rate), and then does nothing
    on = [n for n, reg in tr.regularizers.items.items() if not (n == "dropout" and reg.rate == 0)]
    if on:
        out.append(f"regularisers on: {', '.join(on)}")
    if tr.held is not None:
        out.append(f"geometry held ({tr.held['why']})")
    if tr.bg.components.items:
        out.append(f"background components: {', '.join(tr.bg.components.items)}")
    if tr.path_pruning.clearance is not None or tr.path_pruning.floaters is not None:
        out.append("path clearance / floaters")
    if tr.pair is not None:
        out.append("a co-regularised pair")
    if tr.stages or tr.reserved_steps:
        out.append("compact mode")
    if tr.cfg.train.random_background:
        out.append("a random background")
    if tr.cfg.strategy.prune_unseen_at_end:
        out.append("the final pruning")
    lc = tr.cfg.loss
    if (lc.l1_weight, lc.ssim_weight) != (1.0 - RECIPE["ssim_lambda"], RECIPE["ssim_lambda"]):
        out.append(f"loss {lc.l1_weight} L1 + {lc.ssim_weight} D-SSIM")
    if lc.depth_weight or lc.alpha_weight:
        out.append("a depth or alpha term")
    if tr.model.alpha_max != RECIPE["alpha_max"]:
        out.append(f"alpha capped at {tr.model.alpha_max} (gsplat: {RECIPE['alpha_max']})")
    if tr.method.name != "baseline":
        out.append(f"method {tr.method.name}")
    s = tr.strategy
    if type(s) is not DefaultStrategy:
        out.append(f"strategy {type(s).__name__}")
    else:
        out += [f"strategy.{k}={getattr(s, k)} (gsplat: {v})" for k, v in strategy.items() if getattr(s, k) != v]
        if s.reset_opacity != RECIPE["reset_opacity"]:
            out.append(f"strategy.reset_opacity={s.reset_opacity} (gsplat 1.5.3 never resets)")
        if s.max_gaussians:
            out.append(f"strategy.max_gaussians={s.max_gaussians}")
    return out


def data_root_default() -> str | None:
    for p in (ROOT.parent / "shared" / "data", ROOT / "shared" / "data"):
        if p.is_dir():
            return str(p)
    return None


def gpu_tag(device: str) -> str:
    if device != "cuda":
        return "cpu"
    name = torch.cuda.get_device_name().lower().replace("nvidia", "").split()
    return "".join(ch for ch in (name[0] if name else "gpu") if ch.isalnum()) or "gpu"


def commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


# ----------------------------------------------------------------------------------------------
# one scale: the scene, the initial Gaussians, the two sides


class Scale:
    """What both sides of one scale share: the config, the scene, the scene scale, the initial Gaussians.
    ``build(scene_scale)``: the race's warpgs config for the scene with that scene scale."""

    def __init__(self, name: str, scene, build, strategy: dict, seed: int):
        from warpgs.engine.init import scene_scale_of
        from warpgs.pipelines.sparse import make_trainer

        self.name, self.scene, self.strategy, self.seed = name, scene, strategy, seed
        self.scene_scale = scene_scale_of(scene.train)
        self.scene_scale_all = scene_scale_of(list(scene.train) + list(scene.test))
        self.cfg = build(self.scene_scale)
        self.train_scene = dataclasses.replace(scene, test=[])  # the trainer evaluates nothing on its own
        base = make_trainer(self.cfg, self.train_scene)  # warpgs's initial points for the dataset
        problems = plain_problems(base, strategy)
        if problems:
            raise SystemExit(f"{name}: the warpgs trainer is not the plain recipe: {'; '.join(problems)}")
        self.device = base.device
        self.init = getattr(getattr(self.train_scene, "geometry", None), "method", None) or self.cfg.model.init
        self.init_state = base.state_dict(("model",))
        n = len(base.model)
        g = torch.manual_seed(RECIPE["seed"])  # simple_trainer: set_random_seed(42), then quats = torch.rand((N, 4))
        self.init_state["params"]["quats"] = torch.rand((n, 4), generator=g)
        self.initial_gaussians = n
        self.train_cams = base.train_cams
        self.test_cams = [c.to_torch(self.device) for c in scene.test]
        self.background = base.background
        self.width, self.height = self.train_cams[0].width, self.train_cams[0].height
        del base

    @classmethod
    def load(cls, name: str, args, strategy: dict) -> "Scale":
        """The scale ``name`` (``SCALES``) as ``args`` say: its scene through warpgs's loaders (at 1/``shrink``)."""
        def build(scene_scale=None):
            return make_config(name, args.data_root, args.iterations, args.device, args.seed, strategy, scene_scale)
        return cls(name, load_scene(build(), args.shrink), build, strategy, args.seed)

    def params(self) -> dict[str, torch.Tensor]:
        return {k: v.to(self.device, copy=True) for k, v in self.init_state["params"].items()}


class WarpgsSide:
    """The trainer, from the scale's initial Gaussians."""

    name = "warpgs"

    def __init__(self, sc: Scale, iterations: int, schedule: dict | None = None):
        from warpgs.pipelines.sparse import make_trainer

        cfg = copy.deepcopy(sc.cfg)
        cfg.train.iterations = iterations
        for k, v in (schedule or {}).items():
            setattr(cfg.train if k == "sh_degree_interval" else cfg.strategy, k, v)
        self.tr = make_trainer(cfg, sc.train_scene)
        self.tr.load_state_dict(sc.init_state)  # the same initial Gaussians (and a fresh optimiser)
        self.skipped = 0
        self.tr.log = self.log

    def log(self, msg: str) -> None:
        self.skipped += " skipped" in msg
        print(msg, file=sys.stderr)

    def train(self, stop: int) -> None:
        self.tr.train(stop)

    def __len__(self) -> int:
        return len(self.tr.model)

    def render(self, cam) -> torch.Tensor:
        return self.tr.render(cam).image

    def record(self) -> dict:
        return {"skipped_steps": self.skipped, "recoveries": len(self.tr.recoveries),
                "sync_every": self.tr.sync_every,
                # whether the steps ran as CUDA graphs: a recording that fails leaves the run without them
                "cuda_graph": None if self.tr.graph is None else {
                    "recordings": self.tr.graph.captures, "replays": self.tr.graph.replays, "off": self.tr.graph.off}}


def gsplat_dssim():
    """(D-SSIM of [H, W, 3] images, its name): simple_trainer's ``fused_ssim`` with valid padding where the
    package is there, else warpgs's (kornia's SSIM, same padding): the same loss code as the trainer's."""
    try:
        from fused_ssim import fused_ssim
    except ImportError:
        from warpgs.losses import dssim

        return dssim, "warpgs.losses.dssim (fused_ssim not installed)"

    def d(img, gt):
        return 1.0 - fused_ssim(img.permute(2, 0, 1)[None], gt.permute(2, 0, 1)[None], padding="valid")
    return d, "fused_ssim (valid padding)"


class GsplatSide:
    """gsplat 1.5.3's examples/simple_trainer.py training loop, its defaults, through gsplat's library API."""

    name = "gsplat"

    def __init__(self, sc: Scale, iterations: int, schedule: dict | None = None):
        import gsplat
        from gsplat.strategy import DefaultStrategy

        self.sc, self.gsplat = sc, gsplat
        schedule = schedule or {}
        r = RECIPE
        torch.manual_seed(r["seed"])  # simple_trainer: set_random_seed(42) (the split's noise comes from it)
        p = sc.params()
        self.splats = torch.nn.ParameterDict({n: torch.nn.Parameter(p[n]) for n in
                                              ("means", "scales", "quats", "opacities", "sh0", "shN")})
        lrs = {"means": r["means_lr"] * sc.scene_scale, "scales": r["scales_lr"], "quats": r["quats_lr"],
               "opacities": r["opacities_lr"], "sh0": r["sh0_lr"], "shN": r["shN_lr"]}
        bs = r["batch_size"]
        self.optimizers = {n: torch.optim.Adam([{"params": self.splats[n], "lr": lr * math.sqrt(bs), "name": n}],
                                               eps=r["adam_eps"] / math.sqrt(bs),
                                               betas=(1 - bs * (1 - 0.9), 1 - bs * (1 - 0.999)))
                           for n, lr in lrs.items()}
        self.scheduler = torch.optim.lr_scheduler.ExponentialLR(
            self.optimizers["means"], gamma=r["means_lr_final_factor"] ** (1.0 / iterations))
        self.strategy = DefaultStrategy(**{**sc.strategy, **{k: v for k, v in schedule.items() if k in sc.strategy}},
                                        absgrad=r["absgrad"], verbose=False)
        self.strategy.check_sanity(self.splats, self.optimizers)
        self.state = self.strategy.initialize_state(scene_scale=sc.scene_scale)
        self.interval = schedule.get("sh_degree_interval", r["sh_degree_interval"])
        self.iterations = iterations
        self.step = 0
        self.dssim, self.ssim_name = gsplat_dssim()
        self.bg = sc.background[None]

    def degree(self, step: int) -> int:
        return min(step // self.interval, RECIPE["sh_degree"])

    def rasterize(self, cam, degree: int):
        s = self.splats
        colors = torch.cat([s["sh0"], s["shN"]], 1)
        img, _, info = self.gsplat.rasterization(
            s["means"], s["quats"], torch.exp(s["scales"]), torch.sigmoid(s["opacities"]), colors, cam.viewmat[None],
            cam.K[None], cam.width, cam.height, near_plane=RECIPE["near_plane"], far_plane=RECIPE["far_plane"],
            sh_degree=degree, packed=RECIPE["packed"], absgrad=RECIPE["absgrad"], backgrounds=self.bg,
            rasterize_mode=RECIPE["rasterize_mode"])
        return img[0], info

    def train(self, stop: int) -> None:
        order = view_order(len(self.sc.train_cams), stop, self.sc.seed)
        lam = RECIPE["ssim_lambda"]
        for step in range(self.step, stop):
            cam = self.sc.train_cams[order[step]]
            img, info = self.rasterize(cam, self.degree(step))
            self.strategy.step_pre_backward(self.splats, self.optimizers, self.state, step, info)
            loss = (img - cam.image).abs().mean() * (1.0 - lam) + self.dssim(img, cam.image) * lam
            loss.backward()
            for opt in self.optimizers.values():
                opt.step()
                opt.zero_grad(set_to_none=True)
            self.scheduler.step()
            self.strategy.step_post_backward(self.splats, self.optimizers, self.state, step, info,
                                             packed=RECIPE["packed"])
        self.step = stop

    def __len__(self) -> int:
        return len(self.splats["means"])

    def render(self, cam) -> torch.Tensor:
        return self.rasterize(cam, self.degree(max(self.iterations - 1, 0)))[0]

    def record(self) -> dict:
        return {"ssim": self.ssim_name}


SIDES = {"gsplat": GsplatSide, "warpgs": WarpgsSide}


def profile(side, stop: int, device: str, top: int = 15) -> dict:
    """``side`` trained on to step ``stop`` under torch.profiler: wall time, the device's total kernel time, and
    the top CUDA kernels (by device time) and CPU ops (by own CPU time)."""
    from torch.profiler import ProfilerActivity
    from torch.profiler import profile as torch_profile

    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device == "cuda" else [])
    start = side.step if isinstance(side, GsplatSide) else side.tr.step
    sync(device)
    t0 = time.perf_counter()
    with torch_profile(activities=acts) as prof:
        side.train(stop)
        sync(device)
    wall = time.perf_counter() - t0
    events = prof.key_averages()

    def dev(e):
        return getattr(e, "self_device_time_total", None) or getattr(e, "self_cuda_time_total", 0) or 0

    def rows(key):
        best = sorted(events, key=key, reverse=True)[:top]
        return [{"name": e.key[:120], "calls": e.count, "ms": round(key(e) / 1e3, 3)} for e in best if key(e) > 0]
    out = {"steps": stop - start, "wall_s": round(wall, 3),
           "top_cpu_ops": rows(lambda e: e.self_cpu_time_total)}
    if device == "cuda":
        out["device_time_s"] = round(sum(dev(e) for e in events) / 1e6, 3)
        out["top_cuda_kernels"] = rows(dev)
    return out


def run_side(kind: str, sc: Scale, args) -> tuple[dict, object]:
    """Warm-up, the timed run and the evaluation of one side of one scale: (its row, the trained side)."""
    cls = SIDES[kind]
    if args.warmup > 0:
        w = cls(sc, args.warmup, WARMUP_SCHEDULE)
        w.train(args.warmup)
        sync(args.device)
        del w
    gc.collect()
    cuda = args.device == "cuda"
    if cuda:
        torch.cuda.empty_cache()
        torch.cuda.reset_peak_memory_stats()
        before = torch.cuda.memory_allocated()
    side = cls(sc, args.iterations)
    sync(args.device)
    t0 = time.perf_counter()
    side.train(args.iterations)
    sync(args.device)
    seconds = time.perf_counter() - t0
    row = {"seconds": round(seconds, 3), "it_per_s": round(args.iterations / seconds, 2), "gaussians": len(side)}
    if cuda:  # what this side allocated at most, over what was there before it started
        row["peak_allocated_mb"] = round((torch.cuda.max_memory_allocated() - before) / 2**20, 1)
    row.update(test_psnr=mean_psnr(side.render, sc.test_cams), train_psnr=mean_psnr(side.render, sc.train_cams),
               **side.record())
    return row, side


def median_row(rows: list[dict]) -> dict:
    """One run's row, or of several the medians of their time, Gaussians and PSNRs (the rest from the first)."""
    if len(rows) == 1:
        return rows[0]
    out = dict(rows[0])
    for key in ("seconds", "gaussians", "test_psnr", "train_psnr", "peak_allocated_mb"):
        if key in out:
            v = float(statistics.median([r[key] for r in rows]))
            out[key] = int(round(v)) if key == "gaussians" else round(v, 4 if "psnr" in key else 3)
    out["it_per_s"] = round(rows[0]["it_per_s"] * rows[0]["seconds"] / out["seconds"], 2)
    out["runs"] = len(rows)
    return out


def spread(rows: list[dict]) -> dict:
    """How far a side's runs lie apart: its test PSNRs (dB), Gaussians (relative to their median) and times."""
    p = [r["test_psnr"] for r in rows]
    g = [r["gaussians"] for r in rows]
    t = [r["seconds"] for r in rows]
    return {"test_psnr_db": round(max(p) - min(p), 3),
            "gaussians_rel": round((max(g) - min(g)) / max(float(statistics.median(g)), 1.0), 4),
            "seconds_rel": round((max(t) - min(t)) / float(statistics.median(t)), 4)}


def race_scale(name: str, args, strategy: dict) -> dict:
    sc = Scale.load(name, args, strategy)
    kinds = (["gsplat"] if args.device == "cuda" else []) + ["warpgs"]
    print(f"{name}: {sc.scene.name}, {len(sc.train_cams)} train / {len(sc.test_cams)} test views at "
          f"{sc.width}x{sc.height}, {sc.initial_gaussians} initial Gaussians ({sc.init}), scene scale "
          f"{sc.scene_scale:.4g}, {args.iterations} iterations on {args.device}; sides: {', '.join(kinds)}", flush=True)
    out = {"scene": sc.scene.name, "views": len(sc.train_cams), "test_views": len(sc.test_cams), "width": sc.width,
           "height": sc.height, "shrink": args.shrink, "iterations": args.iterations, "warmup": args.warmup,
           "init": sc.init, "initial_gaussians": sc.initial_gaussians, "scene_scale": sc.scene_scale,
           "scene_scale_train_and_test": sc.scene_scale_all, "background": sc.background.tolist(),
           "commit": args.commit, "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
    sides = {}  # kept for the profile
    runs = {kind: [] for kind in kinds}
    for r in range(args.repeats):  # the sides alternate, so a drift of the machine falls on both
        for kind in kinds:
            row, side = run_side(kind, sc, args)
            runs[kind].append(row)
            if args.profile and r == 0:
                sides[kind] = side
            del side
            gc.collect()
            if args.device == "cuda":
                torch.cuda.empty_cache()
    for kind in kinds:
        out[kind] = median_row(runs[kind])
        if args.repeats > 1:
            out[kind + "_runs"] = runs[kind]
            out[kind + "_spread"] = spread(runs[kind])
    g, w = out.get("gsplat"), out["warpgs"]
    if g is not None:
        out["time_ratio"] = round(w["seconds"] / g["seconds"], 3)
        out["gaussians_rel_diff"] = round(abs(w["gaussians"] - g["gaussians"]) / max(g["gaussians"], 1), 4)
        out["psnr_diff_db"] = round(w["test_psnr"] - g["test_psnr"], 3)
        out["counts_within_5pct"] = out["gaussians_rel_diff"] <= 0.05
        out["psnr_within_0p2db"] = abs(out["psnr_diff_db"]) <= 0.2
        out["goal_0p75"] = out["time_ratio"] <= GOAL
    else:  # no gsplat (the CPU): nothing to judge; a profile, when asked for, is of the warpgs side
        out.update(time_ratio=None, gaussians_rel_diff=None, psnr_diff_db=None, counts_within_5pct=None,
                   psnr_within_0p2db=None, goal_0p75=None)
    if args.profile and not out["goal_0p75"]:
        for kind, side in sides.items():  # each trained model trains on past its end, profiled
            out[kind]["profile"] = profile(side, args.iterations + args.profile_steps, args.device)
    sides.clear()
    line = f"{name}: warpgs {w['seconds']:.2f} s, {w['gaussians']} Gaussians, test PSNR {w['test_psnr']:.2f}"
    if g is not None:
        line += (f" | gsplat {g['seconds']:.2f} s, {g['gaussians']} Gaussians, test PSNR {g['test_psnr']:.2f} | ratio "
                 f"{out['time_ratio']:.3f} (goal {GOAL}: {out['goal_0p75']}), counts {out['gaussians_rel_diff']:.1%} "
                 f"apart ({out['counts_within_5pct']}), PSNR {out['psnr_diff_db']:+.2f} dB ({out['psnr_within_0p2db']})")
    for kind in kinds:
        if kind + "_spread" in out:
            sp = out[kind + "_spread"]
            line += (f" | {kind} over {args.repeats} runs: {sp['test_psnr_db']:.2f} dB, {sp['gaussians_rel']:.1%} "
                     f"Gaussians apart")
    print(line, flush=True)
    return out


@dataclasses.dataclass
class Args:
    scales: list
    iterations: int
    device: str
    shrink: int
    warmup: int
    seed: int
    data_root: str | None
    profile: bool
    profile_steps: int
    strategy_set: list
    repeats: int
    out: Path
    commit: str | None = None


def parse_args(argv=None) -> Args:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", action="append", choices=sorted(SCALES), default=[], help="a scale (repeatable)")
    ap.add_argument("--all", action="store_true", help="every scale: " + ", ".join(SCALES))
    ap.add_argument("--iterations", type=int, default=7000)
    ap.add_argument("--device", choices=["cuda", "cpu"], default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--shrink", type=int, default=1, help="train and test at 1/N of the scale's size (box filter)")
    ap.add_argument("--warmup", type=int, default=None, help="untimed steps per side first (default 40 CUDA, 0 CPU)")
    ap.add_argument("--seed", type=int, default=0, help="warpgs's train.seed: the view order, the init's randomness")
    ap.add_argument("--data-root", default=None, help="folder of the real scenes (default ../shared/data)")
    ap.add_argument("--profile", action="store_true",
                    help="profile both sides of each scale whose ratio is over 0.75 (the warpgs side on the CPU)")
    ap.add_argument("--profile-steps", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=1,
                    help="runs of each side per scale, alternating; the checks use their medians and the JSON "
                         "gives each run and each side's spread (gsplat's own run-to-run spread judges the checks)")
    ap.add_argument("--strategy-set", action="append", default=[], metavar="KEY=VALUE",
                    help="a DefaultStrategy threshold for both sides instead of gsplat's default (smoke runs: "
                         "refine_start_iter=10)")
    ap.add_argument("--out", type=Path, default=None, help="default bench/results/perf/race_gsplat_<gpu>.json")
    ap.add_argument("--commit", default=None,
                    help="the commit measured, where the tree has no git (default: git rev-parse --short HEAD)")
    a = ap.parse_args(argv)
    scales = list(SCALES) if a.all else a.scale
    if not scales:
        ap.error("give --scale NAME (repeatable) or --all")
    if a.repeats < 1:
        ap.error(f"--repeats {a.repeats}: at least 1")
    if a.device == "cuda" and not gsplat_available():
        ap.error("the race needs gsplat on CUDA (pip install gsplat==1.5.3); --device cpu runs the warpgs side alone")
    for s in a.strategy_set:
        if s.split("=", 1)[0] not in GSPLAT_STRATEGY or "=" not in s:
            ap.error(f"--strategy-set {s!r}: KEY=VALUE with KEY one of {', '.join(GSPLAT_STRATEGY)}")
    out = a.out or ROOT / "bench" / "results" / "perf" / f"race_gsplat_{gpu_tag(a.device)}.json"
    return Args(scales=scales, iterations=a.iterations, device=a.device, shrink=a.shrink,
                warmup=a.warmup if a.warmup is not None else (40 if a.device == "cuda" else 0), seed=a.seed,
                data_root=a.data_root or data_root_default(), profile=a.profile, profile_steps=a.profile_steps,
                strategy_set=a.strategy_set, repeats=a.repeats, out=out, commit=a.commit or commit())


def main(argv=None) -> dict:
    import yaml

    args = parse_args(argv)
    strategy = gsplat_strategy_defaults()
    strategy.update({k: yaml.safe_load(v) for k, v in (s.split("=", 1) for s in args.strategy_set)})
    result = json.loads(args.out.read_text()) if args.out.is_file() else {}
    info = machine(args.device)
    info.update(commit=args.commit, date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    result.update(machine=info, goal=GOAL, seeds={"warpgs_train_seed": args.seed, "gsplat_seed": RECIPE["seed"]},
                  recipe={"simple_trainer": RECIPE, "strategy": strategy,
                          "warpgs_overrides": recipe_overrides(strategy)})
    result.setdefault("scales", {})
    for name in args.scales:
        result["scales"][name] = race_scale(name, args, strategy)
        write_result(args.out, result)  # after every scale: a run cut short keeps what it measured
    return result


if __name__ == "__main__":
    main()
