"""Rasterizer benchmark: warpgs against gsplat 1.5.3 on CUDA, against the torch oracle on the CPU.

    python bench/perf/rasterizer.py                 # CUDA if available (needs `pip install gsplat==1.5.3`), else CPU
    python bench/perf/rasterizer.py --device cpu
    python bench/perf/rasterizer.py --out bench/results/perf/rasterizer_vs_gsplat_random_h200.json

Identical inputs for both rasterizers in the same run: N random Gaussians (means uniform in a box
in front of the camera, random rotations, scales uniform up to 0.02, opacities uniform in [0, 1], RGB
colours), one pinhole camera (focal = image width). On CUDA the four rasterizers of a configuration are timed
in --rounds interleaved rounds (each round times every one for --iters calls after all were warmed up, the order
rotating from round to round, Python's garbage collector paused), and a time is the median over the rounds of
the mean per call, measured with CUDA events; the rounds' range is in the JSON. Interleaving keeps a slow start
of the process (clocks, caches, a busy host) from landing on whichever rasterizer happens to be timed first,
which single back-to-back measurements did (on an H100 the first configuration's ratio was 1.38-1.70 when measured
first, 0.71-1.07 when measured last). On the CPU: one round. "warpgs" is the default deterministic backward (fixed-point sums),
"warpgs_float_atomics" the float-atomic one (deterministic=False); forward+backward backpropagates a fixed random weighting of the image to
means, quats, scales, opacities and colours. Peak memory is torch's allocator peak above the inputs
plus Warp's memory-pool high-water mark (Warp's radix-sort scratch). The RGB agreement uses gsplat's
alpha clamp (0.999) in warpgs so that the two compute the same function.
"""

from __future__ import annotations

import argparse
import gc
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from warpgs.render import rasterize  # noqa: E402

CUDA_CONFIGS = [(138_766, 648, 420), (256_000, 1280, 720), (1_000_000, 1920, 1080)]
CPU_CONFIGS = [(64, 48, 32), (256, 96, 64)]


def make_inputs(n, width, height, device, seed=0):
    g = torch.Generator(device="cpu").manual_seed(seed)
    box_lo = torch.tensor([-1.2, -0.8, 1.5])
    box_hi = torch.tensor([1.2, 0.8, 4.0])
    means = box_lo + (box_hi - box_lo) * torch.rand(n, 3, generator=g)
    quats = torch.randn(n, 4, generator=g)
    quats = quats / quats.norm(dim=-1, keepdim=True)
    scales = 0.02 * torch.rand(n, 3, generator=g)
    opacities = torch.rand(n, generator=g)
    colors = torch.rand(n, 3, generator=g)
    viewmat = torch.eye(4)
    f = float(width)
    K = torch.tensor([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])
    w_img = torch.rand(height, width, 3, generator=g)
    t = [x.to(device) for x in (means, quats, scales, opacities, colors, viewmat, K, w_img)]
    return dict(zip(["means", "quats", "scales", "opacities", "colors", "viewmat", "K", "w_img"], t))


def trained_model_and_view(path, data, data_root, device):
    """A trained model (``GaussianModel.load_ply``: SH degree 3 colours) and the first test camera of the
    scene it was trained on (``data``: a dataset name or folder as ``--data`` takes it)."""
    from warpgs.data import load_scene
    from warpgs.model import GaussianModel

    scene = load_scene(data, root=data_root, device="cpu")
    return GaussianModel.load_ply(path, device=device), (scene.test or scene.train)[0]


def inputs_from_model(model, cam, scale, device, seed=0):
    """``model``'s Gaussians seen from ``cam``, its image ``scale`` x the camera's size (intrinsics scaled
    with it)."""
    width, height = int(cam.width * scale), int(cam.height * scale)
    K = torch.as_tensor(cam.K, dtype=torch.float32).clone()
    K[:2] *= scale
    g = torch.Generator(device="cpu").manual_seed(seed)
    with torch.no_grad():
        t = {"means": model.means, "quats": model.quats, "scales": model.scales, "opacities": model.opacities,
             "colors": model.sh, "viewmat": torch.as_tensor(cam.viewmat, dtype=torch.float32), "K": K,
             "w_img": torch.rand(height, width, 3, generator=g)}
    inp = {k: v.detach().float().contiguous().to(device) for k, v in t.items()}
    inp["sh_degree"] = model.max_sh_degree
    return inp, width, height


def grad_inputs(inp):
    return {k: inp[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")}


def warpgs_fn(inp, width, height, alpha_max, deterministic=True):
    def fwd(p):
        out = rasterize(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"], inp["viewmat"], inp["K"],
                        width, height, sh_degree=inp.get("sh_degree"), alpha_max=alpha_max,
                        deterministic=deterministic, check_finite=False)
        return out.image
    return fwd


def gsplat_fn(inp, width, height, mode="RGB"):
    import gsplat

    def fwd(p):
        img, alpha, _ = gsplat.rasterization(
            p["means"], p["quats"], p["scales"], p["opacities"], p["colors"], inp["viewmat"][None], inp["K"][None],
            width, height, packed=False, render_mode=mode, sh_degree=inp.get("sh_degree"))
        return img[0, ..., :3]
    return fwd


def reference_fn(inp, width, height, alpha_max):
    import reference as ref

    def fwd(p):
        img, _, _, _ = ref.render(p["means"], p["quats"], p["scales"], p["opacities"], p["colors"], inp["viewmat"],
                                  inp["K"], width, height, alpha_max=alpha_max)
        return img
    return fwd


def time_it(fn, iters, warmup, device):
    for _ in range(warmup):
        fn()
    if device == "cuda":
        torch.cuda.synchronize()
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
        for _ in range(iters):
            fn()
        end.record()
        torch.cuda.synchronize()
        return start.elapsed_time(end) / iters
    t0 = time.perf_counter()
    for _ in range(iters):
        fn()
    return (time.perf_counter() - t0) * 1000 / iters


def peak_mem_mb(fn, device):
    if device != "cuda":
        return None
    import warp as wp

    torch.cuda.synchronize()
    base = torch.cuda.memory_allocated()
    torch.cuda.reset_peak_memory_stats()
    try:
        wp.set_mempool_used_mem_high("cuda:0", 0) if hasattr(wp, "set_mempool_used_mem_high") else None
    except Exception:  # noqa: BLE001 - optional Warp API
        pass
    fn()
    torch.cuda.synchronize()
    peak = torch.cuda.max_memory_allocated() - base
    warp_peak = 0
    for name in ("get_mempool_used_mem_high",):
        if hasattr(wp, name):
            try:
                warp_peak = getattr(wp, name)("cuda:0")
            except Exception:  # noqa: BLE001
                warp_peak = 0
    return (peak + warp_peak) / 2**20


def calls(make_fwd, inp):
    """(forward only, forward + backward) of one rasterizer on its own copy of the inputs."""
    p = grad_inputs(inp)
    w = inp["w_img"]

    def f_only():
        with torch.no_grad():
            make_fwd(p)

    def f_b():
        img = make_fwd(p)
        (img * w).sum().backward()

    return p, f_only, f_b


def measure(fns: dict, inp, iters, warmup, device, rounds: int = 1) -> dict:
    """Times every rasterizer of ``fns`` (name: make_fwd) in ``rounds`` interleaved rounds (module docstring);
    returns name: ({forward_ms, forward_backward_ms (medians over rounds), rounds_ms, peak_mem_mb}, image)."""
    made = {name: calls(fn, inp) for name, fn in fns.items()}
    for _, f_only, f_b in made.values():
        for _ in range(warmup):
            f_only()
            f_b()
    times = {name: {"forward_ms": [], "forward_backward_ms": []} for name in fns}
    names = list(fns)
    gc.collect()
    gc.disable()
    try:
        for r in range(rounds):
            for name in names[r % len(names):] + names[:r % len(names)]:
                _, f_only, f_b = made[name]
                times[name]["forward_ms"].append(time_it(f_only, iters, 0, device))
                times[name]["forward_backward_ms"].append(time_it(f_b, iters, 0, device))
    finally:
        gc.enable()
    out = {}
    for name, (p, _, f_b) in made.items():
        t = times[name]
        res = {k: statistics.median(v) for k, v in t.items()}
        res["rounds_ms"] = {k: [round(x, 4) for x in v] for k, v in t.items()}
        res["peak_mem_mb"] = peak_mem_mb(f_b, device)
        with torch.no_grad():
            img = fns[name](p).float()
        fw, fb = t["forward_ms"], t["forward_backward_ms"]
        print(f"  {name:<14} fwd {res['forward_ms']:9.3f} ms [{min(fw):.3f}, {max(fw):.3f}]   fwd+bwd "
              f"{res['forward_backward_ms']:9.3f} ms [{min(fb):.3f}, {max(fb):.3f}]"
              + (f"   peak {res['peak_mem_mb']:.1f} MB" if res["peak_mem_mb"] is not None else ""), flush=True)
        out[name] = (res, img)
    return out


def profile(make_fwd, inp, label="warpgs"):
    """Kernel-level breakdown of one forward+backward (CUDA): prints torch.profiler's table and returns the
    CUDA time of each kernel per call (ms, summed over its launches in one forward+backward), largest first."""
    from torch.profiler import ProfilerActivity
    from torch.profiler import profile as torch_profile

    p = grad_inputs(inp)
    for _ in range(3):
        (make_fwd(p) * inp["w_img"]).sum().backward()
    torch.cuda.synchronize()
    reps = 5
    with torch_profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        for _ in range(reps):
            (make_fwd(p) * inp["w_img"]).sum().backward()
        torch.cuda.synchronize()
    print(f"  profile: {label}")
    print(prof.key_averages().table(sort_by="cuda_time_total", row_limit=25, max_name_column_width=60))
    kernels = {}
    for e in prof.key_averages():
        t = getattr(e, "self_device_time_total", None)
        if t is None:
            t = getattr(e, "self_cuda_time_total", 0.0)
        if t > 0 and not e.key.startswith(("aten::", "autograd::", "_", "cuda", "Memcpy", "Memset")):
            key = e.key[:90]  # (several cub kernels share a long prefix: summed)
            kernels[key] = kernels.get(key, 0.0) + t / reps / 1000.0
    return {k: round(v, 4) for k, v in sorted(kernels.items(), key=lambda kv: -kv[1])}


def diagnose(inp, width, height, img_w, img_g):
    """Where warpgs and gsplat differ: projected quantities bit for bit, and the pixels that differ."""
    import gsplat

    from warpgs.render import _Project

    m2, con, dep, _, radii, _ = _Project.apply(inp["means"], inp["quats"], inp["scales"], inp["opacities"],
                                               inp["viewmat"], inp["K"], width, height, 0.3, 0.01, 1e10, False)
    _, _, meta = gsplat.rasterization(inp["means"], inp["quats"], inp["scales"], inp["opacities"], inp["colors"],
                                      inp["viewmat"][None], inp["K"][None], width, height, packed=False,
                                      sh_degree=inp.get("sh_degree"))
    g_r = meta["radii"][0].reshape(-1, 2)
    both = (radii > 0).all(-1) & (g_r > 0).all(-1)
    out = {"visible_warpgs": int((radii > 0).all(-1).sum()), "visible_gsplat": int((g_r > 0).all(-1).sum()),
           "radii_equal": float((radii[both] == g_r[both]).all(-1).float().mean())}
    for name, a, b in (("means2d", m2, meta["means2d"][0]), ("conics", con, meta["conics"][0]),
                       ("depths", dep, meta["depths"][0])):
        a, b = a[both], b.reshape(a.shape)[both]
        out[f"{name}_bit_equal"] = float((a == b).reshape(a.shape[0], -1).all(-1).float().mean())
        out[f"{name}_max_rel"] = float(((a - b).abs() / b.abs().clamp_min(1e-12)).max())
    d = (img_w - img_g).abs().max(-1).values
    out.update(pixels=d.numel(), px_over_1e3=int((d > 1e-3).sum()), px_over_1e4=int((d > 1e-4).sum()),
               px_over_1e5=int((d > 1e-5).sum()), p9999=float(torch.quantile(d.flatten()[:16_000_000].float(), 0.9999)))
    print("  diagnosis:", json.dumps(out))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", choices=["cuda", "cpu"], default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--iters", type=int, default=None)
    ap.add_argument("--warmup", type=int, default=None)
    ap.add_argument("--rounds", type=int, default=None, help="interleaved timing rounds (CUDA default 7)")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--configs", type=str, default=None, help="e.g. '138766x648x420,256000x1280x720'")
    ap.add_argument("--profile", action="store_true", help="print per-kernel CUDA time tables of warpgs and gsplat (and record them)")
    ap.add_argument("--ply", type=Path, default=None,
                    help="a trained model's point_cloud.ply instead of random Gaussians (SH degree 3 colours), seen "
                         "from the first test view of --data")
    ap.add_argument("--data", default="llff", help="with --ply: the scene it was trained on (name or folder)")
    ap.add_argument("--data-root", default=None, help="with --ply: the datasets' folder")
    ap.add_argument("--scales", default="1,2", help="with --ply: image sizes as factors of the scene's")
    args = ap.parse_args(argv)
    device = args.device
    configs = CUDA_CONFIGS if device == "cuda" else CPU_CONFIGS
    if args.configs:
        configs = [tuple(int(v) for v in c.split("x")) for c in args.configs.split(",")]
    iters = args.iters or (20 if device == "cuda" else 3)
    warmup = args.warmup or (5 if device == "cuda" else 1)
    rounds = args.rounds or (7 if device == "cuda" else 1)
    out_path = args.out or ROOT / "bench" / "results" / "perf" / f"rasterizer_{device}.json"

    result = {"device": torch.cuda.get_device_name() if device == "cuda" else platform.processor() or "cpu",
              "torch": torch.__version__, "iters": iters, "rounds": rounds, "warmup": warmup, "configs": []}
    if device == "cuda":
        import gsplat

        result["gsplat"] = gsplat.__version__
    import warp as wp

    result["warp"] = wp.__version__
    if args.ply is not None:
        if device != "cuda":
            ap.error("--ply compares with gsplat on CUDA")
        configs = [float(x) for x in args.scales.split(",")]
        result["ply"] = str(args.ply)
        trained, view = trained_model_and_view(args.ply, args.data, args.data_root, device)
    for config in configs:
        if args.ply is not None:
            inp, width, height = inputs_from_model(trained, view, config, device)
            n = int(inp["means"].shape[0])
        else:
            n, width, height = config
            inp = make_inputs(n, width, height, device)
        print(f"{n} Gaussians, {width}x{height}" + (f" (trained, SH degree {inp['sh_degree']})" if args.ply else ""),
              flush=True)
        row = {"gaussians": n, "width": width, "height": height, "sh_degree": inp.get("sh_degree")}
        if device == "cuda":
            got = measure({"warpgs": warpgs_fn(inp, width, height, 0.999),
                           "warpgs_float_atomics": warpgs_fn(inp, width, height, 0.999, False),
                           "gsplat": gsplat_fn(inp, width, height),
                           "gsplat_rgb_ed": gsplat_fn(inp, width, height, "RGB+ED")}, inp, iters, warmup, device, rounds)
            for name, (res, _) in got.items():
                row[name] = res
            img_w, img_g = got["warpgs"][1], got["gsplat"][1]
            row["max_abs_rgb_diff"] = float((img_w - img_g).abs().max())
            row["diagnosis"] = diagnose(inp, width, height, img_w, img_g)
            if args.profile:
                row["kernels_ms"] = {"warpgs": profile(warpgs_fn(inp, width, height, 0.999), inp),
                                     "gsplat": profile(gsplat_fn(inp, width, height), inp, "gsplat")}
            row["ratio_fwd"] = row["warpgs"]["forward_ms"] / row["gsplat"]["forward_ms"]
            row["ratio_fwd_bwd"] = row["warpgs"]["forward_backward_ms"] / row["gsplat"]["forward_backward_ms"]
            row["ratio_fwd_bwd_vs_rgb_ed"] = (row["warpgs"]["forward_backward_ms"]
                                              / row["gsplat_rgb_ed"]["forward_backward_ms"])
            # the ratio within each round (the two timed a few ms apart), median and range over the rounds: a slow
            # stretch of the machine lands on both sides of it
            paired = [a / b for a, b in zip(row["warpgs"]["rounds_ms"]["forward_backward_ms"],
                                            row["gsplat"]["rounds_ms"]["forward_backward_ms"])]
            row["ratio_fwd_bwd_paired"] = {"median": statistics.median(paired), "min": min(paired), "max": max(paired)}
            print(f"  paired per round: fwd+bwd {row['ratio_fwd_bwd_paired']['median']:.2f} "
                  f"[{min(paired):.2f}, {max(paired):.2f}]")
            print(f"  ratio warpgs/gsplat: fwd {row['ratio_fwd']:.2f}  fwd+bwd {row['ratio_fwd_bwd']:.2f} "
                  f"(vs RGB+ED {row['ratio_fwd_bwd_vs_rgb_ed']:.2f})  max|RGB diff| {row['max_abs_rgb_diff']:.2e}")
        else:
            got = measure({"warpgs": warpgs_fn(inp, width, height, 0.99)}, inp, iters, warmup, device)
            got.update(measure({"reference": reference_fn(inp, width, height, 0.99)}, inp, 1, 0, device))
            (row["warpgs"], img_w), (row["reference"], img_r) = got["warpgs"], got["reference"]
            row["max_abs_rgb_diff"] = float((img_w - img_r).abs().max())
            row["speedup_fwd_bwd"] = row["reference"]["forward_backward_ms"] / row["warpgs"]["forward_backward_ms"]
            print(f"  speed-up over the oracle (fwd+bwd) {row['speedup_fwd_bwd']:.1f}x  "
                  f"max|RGB diff| {row['max_abs_rgb_diff']:.2e}")
        result["configs"].append(row)
    write_result(out_path, result)
    return result


def write_result(path: Path, result: dict) -> None:
    """A benchmark's JSON (indented, its folder made), and a line saying where."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
