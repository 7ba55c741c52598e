"""Training speed end to end: warpgs's trainer against a plain gsplat training loop (issue 15).

    python bench/perf/train_speed.py --set model.init=frustum   # fern, 3 views, 3000 it, 50,000 random initial
                                                           # Gaussians; CUDA (+ gsplat 1.5.3) if available
    python bench/perf/train_speed.py --device cpu --shrink 8 --iterations 60 --repeats 3 --set model.init=frustum \\
        --set model.init_num=1000 --set strategy.refine_start_iter=10 --set strategy.refine_every=20
                                                           # bench/results/perf/train_speed_cpu.json (about a minute)

The loops, one after the other in this process, each from the same initial Gaussians (the trainer's
initialisation, made once and copied), over the same training views in the same order (the trainer's
shuffled order for the seed), with the same learning rates (``make_optimizer``'s; the means' decaying as the
trainer's), SH degree schedule and loss (``loss.l1_weight`` L1 + ``loss.ssim_weight`` D-SSIM through
``warpgs.losses``: 0.8 / 0.2), background and densification thresholds:

- ``warpgs_trainer``: ``Trainer.train`` as ``python -m warpgs.pipelines.sparse`` builds it (the divergence
  guard, snapshots, ``train.sync_every``; no output folder, no progress bar);
- ``plain_warpgs``: the shortest loop around warpgs's rasterizer (``GaussianModel.render``), Adam as the
  trainer makes it and ``warpgs.strategy.DefaultStrategy``: what the trainer's machinery costs over it;
- ``plain_gsplat`` (CUDA, gsplat importable): ``gsplat.rasterization`` (packed=False, classic, as gsplat's
  examples/simple_trainer.py), gsplat's ``DefaultStrategy`` and one Adam per parameter (gsplat's
  convention; fused where the trainer's is, so the optimiser is no difference between the loops);
- ``warpgs_trainer_torch_guard`` (only when asked for): the trainer with ``train.guard_kernels=false`` (a deferred
  step's verdict from two dozen torch ops instead of the default's two Warp launches); it must end with the same
  model as ``warpgs_trainer``;
- ``warpgs_trainer_sync1`` (only when asked for): the trainer reading its verdicts every step
  (``train.sync_every=1``): what the host reads cost; it must end with the same model as ``warpgs_trainer``;
- ``warpgs_trainer_eager`` (only when asked for): the trainer without CUDA graphs (``train.cuda_graph=false``:
  every step launches its kernels one by one); it must end with the same model as ``warpgs_trainer``.

Each loop runs ``--warmup`` steps first (kernel loading, cuDNN, allocator), then ``--iterations`` steps timed
with ``time.perf_counter`` between two ``torch.cuda.synchronize()``; with ``--repeats`` the loops take turns
and each one's median run is reported. Reported per loop: seconds, it/s, the
final Gaussian count, the mean PSNR over the training views and over the test views (each loop's model
rendered by its own rasterizer), and the ratios warpgs_trainer / plain_gsplat and warpgs_trainer /
plain_warpgs (time over time: below 1 is faster). The JSON records the machine (CPU model, GPU, torch,
Warp, gsplat) and the settings. The loops share warpgs's config, not gsplat's own recipe: the like-for-like race
against gsplat 1.5.3's simple_trainer recipe is bench/perf/race_gsplat.py.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs import losses  # noqa: E402
from bench.perf.rasterizer import write_result  # noqa: E402
from warpgs.model import PARAM_NAMES, GaussianModel  # noqa: E402

LOOPS = ("warpgs_trainer", "plain_warpgs", "plain_gsplat", "warpgs_trainer_sync1", "warpgs_trainer_torch_guard",
         "warpgs_trainer_eager")
DEFAULT_LOOPS = LOOPS[:3]


def gsplat_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("gsplat") is not None


def machine(device: str) -> dict:
    import warp as wp

    cpu = platform.processor() or "cpu"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info = {"cpu": cpu, "cpu_count": os.cpu_count(), "python": platform.python_version(),
            "torch": torch.__version__, "warp": wp.__version__, "platform": platform.platform()}
    if device == "cuda":
        info["gpu"] = torch.cuda.get_device_name()
    if gsplat_available():
        import gsplat

        info["gsplat"] = gsplat.__version__
    return info


def make_config(args):
    """The run's config as the main CLI builds it (``warpgs.pipelines.sparse.make_config``)."""
    from warpgs.pipelines.sparse import build_parser, make_config as cli_config

    argv = ["--data", args.data, "--views", str(args.views), "--method", "baseline", "--iterations",
            str(args.iterations), "--device", args.device, "--no-progress"]
    if args.scene:
        argv += ["--scene", args.scene]
    if args.data_root:
        argv += ["--data-root", args.data_root]
    # the plain loops train plain 3D-GS: the trainer gets none of the regularisers a dataset config may turn on
    # (DropGaussian is the captures' and LLFF's default since issue 14); --set can still ask for them
    argv += ["--set", "regularizers.dropout.rate=0", "--set", "regularizers.opacity_noise.sigma=0",
             "--set", "regularizers.scale_reg.weight=0", "--set", "corgs.pair=false", "--set", "backgrounds.far_field.kind=none", "--set", "clearance.path=0",
             "--set", "clearance.view=0", "--set", "regularizers.alpha_binary.weight=0",  # the captures' defaults
             "--set", "strategy.refine_stop_fraction=0",  # 3D-GS's schedule in steps (LLFF's, DTU's and the captures'
             #   baseline stop growing at half the run; the plain loops read refine_stop_iter alone)
             "--set", "regularizers.opacity_decay.rate=0", "--set", "regularizers.binocular.weight=0"]  # Binocular3DGS's terms
    for s in args.set:
        argv += ["--set", s]
    cfg, _ = cli_config(build_parser().parse_args(argv))
    return cfg


def load_scene(cfg, shrink: int):
    """The scene (train and test views); ``shrink`` > 1: every view at 1/shrink of its size (box filter)."""
    from warpgs.data.stress import shrink as shrink_camera
    from warpgs.pipelines.sparse import load_scene_for

    scene = load_scene_for(cfg)
    if shrink > 1:
        scene = dataclasses.replace(scene, train=[shrink_camera(c, shrink) for c in scene.train],
                                    test=[shrink_camera(c, shrink) for c in scene.test])
    return scene


def view_order(n_views: int, iterations: int, seed: int) -> list[int]:
    """The trainer's view order (``Trainer.next_view``): a permutation of the views for ``seed``, drawn
    again whenever one is used up, taken from its end."""
    rng = np.random.default_rng(seed + 2)
    order, out = [], []
    for _ in range(iterations):
        if not order:
            order = rng.permutation(n_views).tolist()
        out.append(order.pop())
    return out


def sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


def mean_psnr(render, cams) -> float | None:
    from warpgs.metrics import psnr

    if not cams:
        return None
    with torch.no_grad():
        return float(np.mean([psnr(render(c), c.image) for c in cams]))


# ----------------------------------------------------------------------------------------------
# the loops: each returns (model size, render function for evaluation)


class Setup:
    """What every loop shares: the config, the views, the initial state, the order, the schedules."""

    def __init__(self, cfg, scene):
        from warpgs.pipelines.sparse import make_trainer

        self.cfg, self.scene = cfg, scene
        self.train_scene = dataclasses.replace(scene, test=[])  # the trainer evaluates nothing on its own
        base = make_trainer(cfg, self.train_scene)
        self.device = base.device
        self.init_state = base.state_dict(("model",))  # on the CPU; every loop starts from it
        self.initial_gaussians = len(base.model)
        self.scene_scale = base.scene_scale
        self.background = base.background
        self.train_cams = base.train_cams
        self.test_cams = [c.to_torch(self.device) for c in scene.test]
        self.means_lr = base.means_lr  # the trainer's schedule (its iterations, no phases)
        self.width, self.height = self.train_cams[0].width, self.train_cams[0].height

    def order(self, iterations: int) -> list[int]:
        return view_order(len(self.train_cams), iterations, self.cfg.train.seed)

    def sh_degree(self, step: int) -> int:
        return min(step // max(self.cfg.train.sh_degree_interval, 1), self.cfg.model.sh_degree)

    def loss(self, image, target):
        lc = self.cfg.loss
        return lc.l1_weight * losses.l1(image, target) + lc.ssim_weight * losses.dssim(image, target)

    def initial_params(self) -> dict[str, torch.Tensor]:
        return {k: v.to(self.device, copy=True) for k, v in self.init_state["params"].items()}


def run_warpgs_trainer(setup: Setup, iterations: int, sync_every: int | None = None, guard_kernels: bool | None = None,
                       cuda_graph: bool | None = None):
    from warpgs.pipelines.sparse import make_trainer

    cfg = copy.deepcopy(setup.cfg)
    cfg.train.iterations = iterations
    if sync_every is not None:
        cfg.train.sync_every = sync_every
    if guard_kernels is not None:
        cfg.train.guard_kernels = guard_kernels
    if cuda_graph is not None:
        cfg.train.cuda_graph = cuda_graph
    tr = make_trainer(cfg, setup.train_scene)
    tr.load_state_dict(setup.init_state)  # the same initial Gaussians (and a fresh optimiser)
    tr.log = lambda msg: print(msg, file=sys.stderr)

    def finish():
        return len(tr.model), lambda c: tr.render(c).image
    return tr.train, finish, tr


def run_plain_warpgs(setup: Setup, iterations: int):
    from warpgs.train import make_optimizer

    cfg = setup.cfg
    p = setup.initial_params()
    model = GaussianModel(*(p[n] for n in PARAM_NAMES), max_sh_degree=cfg.model.sh_degree)
    opt = make_optimizer(model, cfg, setup.scene_scale)
    means = next(g for g in opt.param_groups if g["name"] == "means")
    strategy = copy.deepcopy(cfg.strategy)
    state = strategy.initialize_state(len(model), setup.device)
    gen = torch.Generator(device=setup.device).manual_seed(cfg.train.seed + 1)
    order = setup.order(iterations)
    bg = setup.background

    def go():
        for step in range(iterations):
            model.active_sh_degree = setup.sh_degree(step)
            means["lr"] = setup.means_lr(step)
            cam = setup.train_cams[order[step]]
            out = model.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg, check_finite=False)
            setup.loss(out.image, cam.image).backward()
            opt.step()
            opt.zero_grad(set_to_none=True)
            strategy.step_post_backward(model, opt, state, step, out, cam.width, cam.height, setup.scene_scale,
                                        generator=gen)

    def finish():
        return len(model), lambda c: model.render(c.viewmat, c.K, c.width, c.height, background=bg).image
    return go, finish, model


def run_plain_gsplat(setup: Setup, iterations: int):
    """gsplat 1.5.3's conventions (examples/simple_trainer.py): a ParameterDict, one Adam per parameter,
    ``DefaultStrategy`` with step_pre_backward / step_post_backward (after the optimisers)."""
    import gsplat
    from gsplat.strategy import DefaultStrategy as GsplatDefaultStrategy

    from warpgs.train import adam_options, base_learning_rates

    cfg = setup.cfg
    p = setup.initial_params()
    splats = torch.nn.ParameterDict({n: torch.nn.Parameter(p[n]) for n in PARAM_NAMES})
    lrs = base_learning_rates(cfg, setup.scene_scale)
    optimizers = {n: torch.optim.Adam([{"params": splats[n], "lr": lrs[n], "name": n}], eps=cfg.optim.eps,
                                      **adam_options(setup.device)) for n in PARAM_NAMES}
    s = cfg.strategy
    strategy = GsplatDefaultStrategy(
        prune_opa=s.prune_opa, grow_grad2d=s.grow_grad2d, grow_scale3d=s.grow_scale3d, grow_scale2d=s.grow_scale2d,
        prune_scale3d=s.prune_scale3d, prune_scale2d=s.prune_scale2d, refine_scale2d_stop_iter=s.refine_scale2d_stop_iter,
        refine_start_iter=s.refine_start_iter, refine_stop_iter=s.refine_stop_iter, reset_every=s.reset_every,
        refine_every=s.refine_every, pause_refine_after_reset=s.pause_refine_after_reset, absgrad=False, verbose=False)
    strategy.check_sanity(splats, optimizers)
    state = strategy.initialize_state(scene_scale=setup.scene_scale)
    order = setup.order(iterations)
    bg = setup.background[None]

    def render(cam, degree):
        colors = torch.cat([splats["sh0"], splats["shN"]], 1)
        img, _, info = gsplat.rasterization(
            splats["means"], splats["quats"], torch.exp(splats["scales"]), torch.sigmoid(splats["opacities"]),
            colors, cam.viewmat[None], cam.K[None], cam.width, cam.height, sh_degree=degree, packed=False,
            backgrounds=bg, rasterize_mode="classic")
        return img[0], info

    def go():
        for step in range(iterations):
            optimizers["means"].param_groups[0]["lr"] = setup.means_lr(step)
            cam = setup.train_cams[order[step]]
            img, info = render(cam, setup.sh_degree(step))
            strategy.step_pre_backward(splats, optimizers, state, step, info)
            setup.loss(img, cam.image).backward()
            for o in optimizers.values():
                o.step()
                o.zero_grad(set_to_none=True)
            strategy.step_post_backward(splats, optimizers, state, step, info, packed=False)

    final = setup.sh_degree(max(iterations - 1, 0))

    def finish():
        return len(splats["means"]), lambda c: render(c, final)[0]
    return go, finish, splats


RUNNERS = {"warpgs_trainer": run_warpgs_trainer, "plain_warpgs": run_plain_warpgs, "plain_gsplat": run_plain_gsplat,
           "warpgs_trainer_sync1": lambda setup, iterations: run_warpgs_trainer(setup, iterations, sync_every=1),
           "warpgs_trainer_torch_guard": lambda setup, iterations: run_warpgs_trainer(setup, iterations,
                                                                                       guard_kernels=False),
           "warpgs_trainer_eager": lambda setup, iterations: run_warpgs_trainer(setup, iterations, cuda_graph=False)}


def measure(name: str, setup: Setup, iterations: int, warmup: int) -> dict:
    device = setup.device.type
    if warmup > 0:
        go, _, _ = RUNNERS[name](setup, warmup)
        go()
        sync(device)
    if device == "cuda":
        torch.cuda.empty_cache()
    go, finish, _ = RUNNERS[name](setup, iterations)
    sync(device)
    t0 = time.perf_counter()
    go()
    sync(device)
    seconds = time.perf_counter() - t0
    n, render = finish()
    row = {"seconds": round(seconds, 3), "it_per_s": round(iterations / seconds, 2), "gaussians": n,
           "train_psnr": mean_psnr(render, setup.train_cams), "test_psnr": mean_psnr(render, setup.test_cams)}
    print(f"  {name:<15} {row['seconds']:8.2f} s  {row['it_per_s']:8.2f} it/s  {n:>8} Gaussians  train PSNR "
          f"{row['train_psnr']:.2f}  test PSNR {row['test_psnr'] if row['test_psnr'] is None else round(row['test_psnr'], 2)}",
          flush=True)
    return row


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default="llff", help="dataset name or folder (default llff: fern)")
    ap.add_argument("--scene", default=None)
    ap.add_argument("--views", type=int, default=3)
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--device", choices=["cuda", "cpu"], default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--loops", default=None,
                    help=f"comma-separated, of {', '.join(LOOPS)} (default: the first three where gsplat runs, "
                         "else the warpgs ones)")
    ap.add_argument("--shrink", type=int, default=1, help="train and test at 1/N of the loaded size (box filter)")
    ap.add_argument("--warmup", type=int, default=None, help="untimed steps before each loop (default 20 CUDA, 2 CPU)")
    ap.add_argument("--repeats", type=int, default=1, help="runs of each loop (interleaved); the median is reported")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override (repeatable)")
    ap.add_argument("--out", type=Path, default=None, help="default bench/results/perf/train_speed_<device>.json")
    args = ap.parse_args(argv)
    device = args.device
    has_gsplat = device == "cuda" and gsplat_available()
    loops = args.loops.split(",") if args.loops else [n for n in DEFAULT_LOOPS if n != "plain_gsplat" or has_gsplat]
    for n in loops:
        if n not in LOOPS:
            ap.error(f"--loops: unknown loop {n!r}; the loops are {', '.join(LOOPS)}")
    if "plain_gsplat" in loops and not has_gsplat:
        ap.error("plain_gsplat needs CUDA and gsplat (pip install gsplat==1.5.3)")
    warmup = args.warmup if args.warmup is not None else (20 if device == "cuda" else 2)
    out_path = args.out or ROOT / "bench" / "results" / "perf" / f"train_speed_{device}.json"

    cfg = make_config(args)
    scene = load_scene(cfg, args.shrink)
    setup = Setup(cfg, scene)
    print(f"{scene.name}: {len(setup.train_cams)} train / {len(setup.test_cams)} test views at "
          f"{setup.width}x{setup.height}, {setup.initial_gaussians} initial Gaussians, {args.iterations} iterations "
          f"on {device}", flush=True)
    result = {
        "machine": machine(device),
        "settings": {"data": args.data, "scene": scene.name, "views": len(setup.train_cams),
                     "test_views": len(setup.test_cams), "width": setup.width, "height": setup.height,
                     "shrink": args.shrink, "iterations": args.iterations, "warmup": warmup, "repeats": args.repeats,
                     "device": device,
                     "initial_gaussians": setup.initial_gaussians, "set": args.set,
                     "sync_every": cfg.train.sync_every, "init": cfg.model.init,
                     "loss": {"l1_weight": cfg.loss.l1_weight, "ssim_weight": cfg.loss.ssim_weight},
                     "strategy": dataclasses.asdict(cfg.strategy)},
        "loops": {},
    }
    runs: dict[str, list[dict]] = {name: [] for name in loops}
    for r in range(args.repeats):  # interleaved, so that a busy spell of the machine hits every loop alike
        for name in loops:
            runs[name].append(measure(name, setup, args.iterations, warmup if r == 0 else 0))
    for name, rows in runs.items():
        row = dict(sorted(rows, key=lambda x: x["seconds"])[len(rows) // 2])  # the median run
        if len(rows) > 1:
            row["all_seconds"] = [x["seconds"] for x in rows]
        result["loops"][name] = row
    secs = {k: v["seconds"] for k, v in result["loops"].items()}
    ratios = {}
    for other in ("plain_gsplat", "plain_warpgs", "warpgs_trainer_sync1", "warpgs_trainer_torch_guard",
                  "warpgs_trainer_eager"):
        if "warpgs_trainer" in secs and other in secs:
            ratios[f"warpgs_trainer/{other}"] = round(secs["warpgs_trainer"] / secs[other], 3)
    result["ratios"] = ratios
    for other, key, what in (("warpgs_trainer_sync1", "same_model_every_sync", "whatever train.sync_every"),
                             ("warpgs_trainer_torch_guard", "same_model_torch_guard", "with the torch-op guard"),
                             ("warpgs_trainer_eager", "same_model_eager", "without CUDA graphs")):
        if {"warpgs_trainer", other} <= set(result["loops"]):
            a, b = result["loops"]["warpgs_trainer"], result["loops"][other]
            result[key] = all(a[k] == b[k] for k in ("gaussians", "train_psnr", "test_psnr"))
            print(f"  the same model {what}: {result[key]}")
    for k, v in ratios.items():
        print(f"  time ratio {k}: {v:.3f}")
    write_result(out_path, result)
    return result


if __name__ == "__main__":
    main()
