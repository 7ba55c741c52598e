"""Does the rasterizer of one code tree give the same floats as another's? (a bisect of figures that moved between
two commits: dump or record with each tree's warpgs, then compare)

    PYTHONPATH=TREE python bench/diagnostics/rasterizer_commits.py dump OUT.pt [--device cuda]      # with TREE's warpgs
    PYTHONPATH=TREE python bench/diagnostics/rasterizer_commits.py dump-ply OUT.pt --ply MODEL.ply --data dtu --scene scan65
    PYTHONPATH=TREE python bench/diagnostics/rasterizer_commits.py record --calls 0:400 REC.pt -- SPARSE_ARGS...
    PYTHONPATH=TREE python bench/diagnostics/rasterizer_commits.py replay OUT.pt REC.pt
    python bench/diagnostics/rasterizer_commits.py compare A.pt B.pt                                 # per output: equal? max diff

``dump`` renders fixed random scenes (seeded; SH degrees 0-3, per-pixel and plain backgrounds, Gaussians over
three decades of depth, a cluster at nearly equal depths, and ones behind the camera, before the near plane, huge
or off screen), with and without a fixed intersection capacity, forward and backward (deterministic backward) under
a loss with random weights. ``dump-ply`` does the same for a trained model's Gaussians from every view of a scene,
with and without a DropGaussian mask. ``record`` runs ``python -m warpgs.pipelines.sparse`` with
``warpgs.render.rasterize`` wrapped and saves the inputs of the calls numbered FIRST to LAST (training steps and
evaluations alike; ``--calls`` goes before OUT); ``replay`` renders each saved call again with the code it runs on.
"""

from __future__ import annotations

import argparse
import sys

import torch


def scenes(device: str):
    g = torch.Generator().manual_seed(0)
    for name, n, w, h in (("spread", 20000, 160, 120), ("cluster", 4000, 96, 64), ("wild", 20000, 160, 120)):
        if name == "spread":
            depth = torch.exp(torch.rand(n, generator=g) * 6.9) * 0.1
        elif name == "cluster":
            depth = 5 + 1e-4 * torch.rand(n, generator=g)
        else:  # behind the camera, before the near plane, far away, and off screen
            depth = torch.cat([torch.rand(n // 4, generator=g) * -5, torch.rand(n // 4, generator=g) * 0.05,
                               torch.exp(torch.rand(n - n // 2, generator=g) * 9) * 0.05])
        xy = (torch.rand(n, 2, generator=g) - 0.5) * depth[:, None].abs() * (1.2 if name != "wild" else 3.0)
        means = torch.cat([xy, depth[:, None]], 1)
        quats = torch.randn(n, 4, generator=g)
        scales = torch.rand(n, 3, generator=g) * 0.03 * depth[:, None].abs() ** 0.5
        if name == "wild":  # a few very large ones
            scales[::97] *= 50
        opac = torch.rand(n, generator=g) * 0.9 + 0.05
        sh = torch.randn(n, 16, 3, generator=g) * 0.3
        bg = torch.rand(h, w, 3, generator=g)
        K = torch.tensor([[w * 0.8, 0, w / 2], [0, w * 0.8, h / 2], [0, 0, 1.0]])
        wts = [torch.randn(h, w, 3, generator=g), torch.randn(h, w, generator=g), torch.randn(h, w, generator=g)]
        yield name, [t.to(device) for t in (means, quats, scales, opac, sh, bg, K, *wts)], w, h


def _cpu(v):
    """A tensor detached and copied to the CPU; anything else as it is."""
    return v.detach().cpu().clone() if isinstance(v, torch.Tensor) else v


def _random_loss(o, g: torch.Generator, alpha: bool):
    """sum(image x W) + 0.01 sum(depth x W') (+ sum(alpha x W'')), the weights standard normal from ``g``."""
    h, w = o.image.shape[:2]
    dev = o.image.device
    loss = (o.image * torch.randn(h, w, 3, generator=g).to(dev)).sum()
    loss = loss + (o.depth.reshape(h, w) * torch.randn(h, w, generator=g).to(dev)).sum() * 0.01
    if alpha:
        loss = loss + (o.alpha.reshape(h, w) * torch.randn(h, w, generator=g).to(dev)).sum()
    return loss


def _entry(o, grads: dict, **extra) -> dict:
    """One render's record: its image, intersection count, the outputs in ``extra`` and the gradients ``grads``
    (name -> tensor or None; None left out)."""
    return {"image": _cpu(o.image), **{k: _cpu(v) for k, v in extra.items()}, "n_intersections": o.n_intersections,
            **{f"grad_{k}": _cpu(t) for k, t in grads.items() if t is not None}}


def _save(res, out: str, what: str) -> None:
    import warpgs

    torch.save(res, out)
    print(f"wrote {out} ({what}; warpgs from {warpgs.__file__})")


# (name, SH degree, outputs in the loss, fixed intersection capacity (a CUDA graph's render), background)
CASES = (("all3", 3, "all", False, "image"), ("image0", 0, "image", False, "colour"),
         ("image3_capacity", 3, "image", True, "colour"), ("all1_capacity", 1, "all", True, "image"))


def dump(out: str, device: str) -> None:
    from warpgs.render import count_intersections, rasterize

    res = {}
    for (name, (means, quats, scales, opac, sh, bg, K, w_img, w_dep, w_alp), w, h), (case, degree, use, capacity, bgk) \
            in ((sc, c) for sc in scenes(device) for c in CASES):
        params = [p.clone().requires_grad_(True) for p in (means, quats, scales, opac, sh, bg)]
        background = params[5] if bgk == "image" else torch.full((3,), 0.25, device=device)
        cap = None
        if capacity:
            cap = 2 * int(count_intersections(means, quats, scales, opac, torch.eye(4, device=device), K, w, h)) + 64
        o = rasterize(*params[:4], params[4], torch.eye(4, device=device), K, w, h, sh_degree=degree,
                      background=background, isect_capacity=cap)
        d = o.depth.reshape(h, w)
        loss = (o.image * w_img).sum()
        if use == "all":
            loss = loss + (d * w_dep).sum() * 0.01 + (o.alpha.reshape(h, w) * w_alp).sum()
        loss.backward()
        names = ("means", "quats", "scales", "opacities", "sh", "background")
        res[f"{name}/{case}"] = _entry(o, {k: p.grad for k, p in zip(names, params)}, depth=d, alpha=o.alpha)
    _save(res, out, f"{len(res)} renders")


def dump_ply(out: str, ply: str, data: str, scene: str, views: int, root: str, device: str) -> None:
    """A trained model's Gaussians (``ply``) rendered from every view of a scene (SH degrees 0 and 3, and degree
    0 with a DropGaussian mask of rate 0.1; black background), forward and backward under a loss with random
    weights on the image and the depth."""
    from warpgs.data.registry import load_scene
    from warpgs.model import GaussianModel

    model = GaussianModel.load_ply(ply, device=device)
    sc = load_scene(data, scene=scene, views=views, root=root)
    g = torch.Generator().manual_seed(1)
    res = {}
    for cam in list(sc.train) + list(sc.test):
        for degree, drop in ((0, 0.0), (3, 0.0), (0, 0.1)):
            for p in model.params.values():
                p.grad = None
                p.requires_grad_(True)
            vm = torch.as_tensor(cam.viewmat, device=device)
            K = torch.as_tensor(cam.K, device=device)
            scale = None
            if drop > 0:  # DropGaussian's mask: survivors' opacity x 1 / (1 - p), so some exceed 1
                scale = ((torch.rand(len(model), generator=g) >= drop).float() / (1 - drop)).to(device)
            o = model.render(vm, K, cam.width, cam.height, sh_degree=degree, opacity_scale=scale)
            _random_loss(o, g, alpha=False).backward()
            key = f"{cam.name}/sh{degree}" + (f"_drop{drop}" if drop else "")
            res[key] = _entry(o, {k: p.grad for k, p in model.params.items()})
    _save(res, out, f"{len(res)} renders")


def record(out: str, first: int, last: int, argv: list[str]) -> None:
    """Runs ``python -m warpgs.pipelines.sparse ARGV`` with ``warpgs.render.rasterize`` wrapped: the inputs of its
    calls number ``first`` to ``last`` (counted from 0, every call: training steps and evaluations) are saved to
    ``out``, to be replayed by ``replay`` on other code."""
    import runpy

    import warpgs.render as render

    inner, calls, saved = render.rasterize, [0], []

    def wrapped(*args, **kwargs):
        if first <= calls[0] <= last:
            saved.append({"call": calls[0], "args": [_cpu(a) for a in args],
                          "kwargs": {k: _cpu(v) for k, v in kwargs.items()}})
        calls[0] += 1
        return inner(*args, **kwargs)

    render.rasterize = wrapped
    sys.argv = ["warpgs.pipelines.sparse"] + argv
    try:
        runpy.run_module("warpgs.pipelines.sparse", run_name="__main__")
    except SystemExit:
        pass
    _save(saved, out, f"{len(saved)} calls of {calls[0]}")


def replay(out: str, recorded: str, device: str) -> None:
    """Each call saved by ``record``, rendered again with this code (forward and backward under a loss with random
    weights on the image, depth and alpha)."""
    from warpgs.render import rasterize

    g = torch.Generator().manual_seed(2)
    res = {}
    for rec in torch.load(recorded):
        args = [a.to(device).requires_grad_(a.is_floating_point()) if isinstance(a, torch.Tensor) else a
                for a in rec["args"]]
        kwargs = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in rec["kwargs"].items()}
        o = rasterize(*args, **kwargs)
        _random_loss(o, g, alpha=True).backward()
        res[f"call{rec['call']}"] = _entry(o, {f"arg{i}": a.grad for i, a in enumerate(args)
                                              if isinstance(a, torch.Tensor)})
    _save(res, out, f"{len(res)} calls")


def compare(a: str, b: str) -> int:
    A, B = torch.load(a), torch.load(b)
    same = True
    for scene in A:
        for k, va in A[scene].items():
            if k not in B[scene]:
                continue
            vb = B[scene][k]
            if not isinstance(va, torch.Tensor):
                eq = va == vb
                print(f"{scene:8s} {k:18s} {'equal' if eq else f'{va} vs {vb}'}")
            else:
                eq = torch.equal(va, vb)
                diff = (va - vb).abs().max().item()
                rel = diff / max(va.abs().max().item(), 1e-30)
                print(f"{scene:8s} {k:18s} {'equal' if eq else f'DIFFER max {diff:.3e} (rel {rel:.2e}), '}"
                      f"{'' if eq else f'{(va != vb).sum().item()} of {va.numel()} differ'}")
            same &= bool(eq)
    print("bit-identical" if same else "not bit-identical")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out")
    d.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p = sub.add_parser("dump-ply")
    p.add_argument("out")
    p.add_argument("--ply", required=True)
    p.add_argument("--data", default="dtu")
    p.add_argument("--scene", default="scan65")
    p.add_argument("--views", type=int, default=3)
    p.add_argument("--data-root", default=None)
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    r = sub.add_parser("record")
    r.add_argument("out")
    r.add_argument("--calls", default="0:100", help="FIRST:LAST calls of rasterize to save")
    r.add_argument("argv", nargs=argparse.REMAINDER, help="-- then python -m warpgs.pipelines.sparse's arguments")
    q = sub.add_parser("replay")
    q.add_argument("out")
    q.add_argument("recorded")
    q.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args(argv)
    if args.cmd == "dump":
        dump(args.out, args.device)
        return 0
    if args.cmd == "record":
        first, last = (int(x) for x in args.calls.split(":"))
        record(args.out, first, last, [a for a in args.argv if a != "--"])
        return 0
    if args.cmd == "replay":
        replay(args.out, args.recorded, args.device)
        return 0
    if args.cmd == "dump-ply":
        dump_ply(args.out, args.ply, args.data, args.scene, args.views, args.data_root, args.device)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
