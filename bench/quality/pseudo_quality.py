"""How close the full method's pseudo views come to real photos taken at their poses (issue 13).

    python bench/quality/pseudo_quality.py --data-root ../shared/data                       # castle_p30, herz_jesus_p25; 3/6/9 views
    python bench/quality/pseudo_quality.py --data-root D --scenes castle_p30 --views 3 --device cuda --out q.json

A walk-around capture has frames between its training views that are neither trained on nor test views
(castle_p30 at 3 views: 23 of them, 4 of which are the test split's). For each case this trains the full
method's baseline phase (``full.baseline_fraction`` x ``--iterations`` steps, the capture config as
``python -m warpgs.pipelines.sparse --method full`` reads it, seed ``--seed``), then makes pseudo views at the
poses of those **held-out** frames (the test split's frames left out: nothing here looks at them), with
the trajectory from the input before each frame to the input after it, as the method's trajectories
run along the capture path, and compares with the real photo taken there:

- ``render``: the 3D-GS render's PSNR (the model the pseudo views are meant to improve);
- ``pseudo``: the pseudo view's PSNR (what the pseudo-view loss pulls the render towards);
- ``seen`` / ``reliable``: the share of pixels with U < 1 (the training mask, ``full.pseudo_mask: seen``)
  and U < delta, and in each the render's and the pseudo view's MSE: where the pseudo view's MSE is below
  the render's, its loss adds information; where it is above, it pulls the model away from the truth.

Each ``--variant NAME`` (from ``VARIANTS``) makes the pseudo views again with a change to ``pseudo.*`` from the
same trained model; ``default`` is the config as it is. Writes JSON (``--out``) and prints a line per case
and variant. On the CPU keep it small (``--iterations 300``); the figures in the README come from the GPU.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.configio import apply_values  # noqa: E402
from warpgs.model import PARAM_NAMES, GaussianModel  # noqa: E402
from warpgs.pipelines.full import phase_boundaries  # noqa: E402
from warpgs.pipelines.sparse import build_parser, load_scene_for, make_config, make_trainer  # noqa: E402
from warpgs.pseudo.trajectory import Trajectory  # noqa: E402
from warpgs.pseudo.views import generate_pseudo_views, model_renderer  # noqa: E402

# name: a layer over cfg.pseudo (the trained model is the same for all)
VARIANTS = {
    "default": {},
    "best_source": {"trajectory": {"guidance_source": "best"}},
    "delta_0.25": {"sampler": {"delta": 0.25}},
    "delta_0.9": {"sampler": {"delta": 0.9}},
    "unguided": {"sampler": {"guided": False}},
    "photometric_off": {"uncertainty": {"photometric": False}},
    "guide_all": {"sampler": {"k": 0.0, "b": 0.0}},  # guidance on every step (tau = 0)
    "guide_all_best": {"sampler": {"k": 0.0, "b": 0.0}, "trajectory": {"guidance_source": "best"}},
    "guide_all_d0.9": {"sampler": {"k": 0.0, "b": 0.0, "delta": 0.9}},
    "colour_affine": {"trajectory": {"guidance_colour": "affine"}},  # the warps' colours fitted to the render's
    "colour_affine_all": {"trajectory": {"guidance_colour": "affine"}, "sampler": {"k": 0.0, "b": 0.0}},
}


def held_out_frames(cfg, scene) -> list:
    """The frames neither trained on nor in the test split, as ``Camera``s (the scene loaded with
    ``test_rest``, the test split's names removed), sorted by name (the capture order)."""
    from warpgs.data import load_scene

    d = cfg.data
    rest = load_scene(d.name, scene=d.scene, views=d.views, downscale=d.downscale, root=d.root,
                      device="cpu", **{**d.options, "test_rest": True})
    test = {c.name for c in scene.test}
    train = {c.name for c in scene.train}
    return sorted((c for c in rest.test if c.name not in test and c.name not in train), key=lambda c: c.name)


def trajectories_through(train_names: list[str], train_V: np.ndarray, frames: list) -> tuple[list, list]:
    """One trajectory per pair of neighbouring inputs (in name order) through the held-out frames between
    them: (trajectories, for each the held-out frames at its interior poses). Frames before the first input
    or after the last have no pair and are left out."""
    order = sorted(range(len(train_names)), key=lambda i: train_names[i])
    trajs, owners = [], []
    for a, b in zip(order[:-1], order[1:]):
        inside = [f for f in frames if train_names[a] < f.name < train_names[b]]
        if not inside:
            continue
        V = np.stack([train_V[a]] + [np.asarray(f.viewmat, np.float64) for f in inside] + [train_V[b]])
        trajs.append(Trajectory(a, b, V))
        owners.append(inside)
    return trajs, owners


def _mse(a: torch.Tensor, b: torch.Tensor, mask: torch.Tensor | None = None) -> float | None:
    err = ((a.float() - b.float()) ** 2).mean(-1)
    if mask is not None:
        if not bool(mask.any()):
            return None
        err = err[mask]
    return float(err.mean())


def _psnr(mse: float | None) -> float | None:
    return None if mse is None else round(-10 * math.log10(max(mse, 1e-10)), 3)


def frame_record(seq, i: int, gt: torch.Tensor, delta: float) -> dict:
    """The comparison of interior frame ``i`` of ``seq`` with the real photo ``gt`` [H, W, 3]."""
    U = seq.uncertainty[i]
    seen, reliable = U < 1.0, U < delta
    rec = {"render_psnr": _psnr(_mse(seq.renders[i], gt)), "pseudo_psnr": _psnr(_mse(seq.frames[i], gt)),
           "seen": round(float(seen.float().mean()), 4), "reliable": round(float(reliable.float().mean()), 4)}
    for name, m in (("seen", seen), ("reliable", reliable)):
        for what, img in (("render", seq.renders[i]), ("pseudo", seq.frames[i]), ("warp", seq.warped[i]),
                          ("guide", seq.guidance[i])):
            e = _mse(img, gt, m)
            rec[f"{what}_mse_{name}"] = None if e is None else round(e, 6)
    return rec


def summarise(frames: list[dict]) -> dict:
    """Medians over the frames, and the pixel-weighted gain of the pseudo views over the render in the
    training mask (render MSE - pseudo MSE, x the mask's share: > 0 where the pseudo-view loss helps)."""
    def med(k):
        v = [f[k] for f in frames if f.get(k) is not None]
        return None if not v else round(float(np.median(v)), 4)

    gain = [(f["render_mse_seen"] - f["pseudo_mse_seen"]) * f["seen"] for f in frames
            if f.get("render_mse_seen") is not None]
    return {"frames": len(frames), "render_psnr": med("render_psnr"), "pseudo_psnr": med("pseudo_psnr"),
            "seen": med("seen"), "reliable": med("reliable"),
            "render_psnr_seen": _psnr(med("render_mse_seen")), "pseudo_psnr_seen": _psnr(med("pseudo_mse_seen")),
            "render_psnr_reliable": _psnr(med("render_mse_reliable")),
            "pseudo_psnr_reliable": _psnr(med("pseudo_mse_reliable")),
            "warp_psnr_seen": _psnr(med("warp_mse_seen")), "warp_psnr_reliable": _psnr(med("warp_mse_reliable")),
            "guide_psnr_reliable": _psnr(med("guide_mse_reliable")),
            "mse_gain_seen": None if not gain else round(float(np.mean(gain)), 6),
            "frames_improved": sum(1 for f in frames if f["pseudo_psnr"] is not None and f["render_psnr"] is not None
                                   and f["pseudo_psnr"] > f["render_psnr"])}


def probe(data_root: str | None, scene_name: str | None, views: int, iterations: int, seed: int, device: str,
          variants: list[str], sets: list[str], downscale: int | None = 8, cache: Path | None = None,
          data: str = "dl3dv") -> dict:
    """One case: the baseline phase trained (or read from ``cache``), then each variant's pseudo views at the
    held-out frames' poses against the photos (``frame_record``), with their medians (``summarise``)."""
    argv = ["--data", data, "--views", str(views), "--method", "full", "--device", device,
            "--iterations", str(iterations), "--seed", str(seed), "--no-progress"]
    for flag, value in (("--scene", scene_name), ("--data-root", data_root), ("--downscale", downscale)):
        if value is not None:
            argv += [flag, str(value)]
    for s in sets:
        argv += ["--set", s]
    cfg, _ = make_config(build_parser().parse_args(argv))
    scene = load_scene_for(cfg)
    frames = held_out_frames(cfg, scene)
    t0 = time.perf_counter()
    tr = make_trainer(cfg, scene, None, log=lambda *a, **k: None)
    first = phase_boundaries(tr.total_steps, cfg.full)[0]
    tr.phase_start, tr.phase_len = 0, tr.total_steps  # as FullMethod.run without restart_lr
    saved = None if cache is None else cache / f"{scene.name}_{views}v_{iterations}_s{seed}_d{downscale}.pt"
    if saved is not None and saved.is_file():  # the trained baseline phase of an earlier call (same settings)
        st = torch.load(saved, map_location=tr.device)
        tr.model = GaussianModel(*(st["params"][k] for k in PARAM_NAMES), max_sh_degree=tr.model.max_sh_degree)
        tr.model.active_sh_degree = st["active_sh_degree"]
    else:
        tr.train(first)
        if saved is not None:
            saved.parent.mkdir(parents=True, exist_ok=True)
            torch.save({"params": {k: v.detach() for k, v in tr.model.params.items()},
                        "active_sh_degree": tr.model.active_sh_degree}, saved)
    train_s = time.perf_counter() - t0
    names = [c.name for c in tr.train_cams]
    train_V = torch.stack([c.viewmat for c in tr.train_cams]).double().cpu().numpy()
    trajs, owners = trajectories_through(names, train_V, frames)
    out = {"scene": scene.name, "views": views, "steps": first, "seed": seed, "train_s": round(train_s, 1),
           "gaussians": len(tr.model), "held_out": [f.name for o in owners for f in o], "variants": {}}
    for name in variants:
        pcfg = copy.deepcopy(cfg.pseudo)
        apply_values(pcfg, copy.deepcopy(VARIANTS[name]), f"variant {name}")
        seqs = generate_pseudo_views(model_renderer(tr.model, tr.background_for), tr.train_cams, pcfg,
                                     device=tr.device, trajectories=trajs)
        recs = []
        for seq, inside in zip(seqs, owners):
            for i, f in enumerate(inside, start=1):
                gt = torch.as_tensor(f.image, dtype=torch.float32, device=seq.frames.device)
                recs.append({"frame": f.name, **frame_record(seq, i, gt, pcfg.sampler.delta)})
        out["variants"][name] = {"summary": summarise(recs), "frames": recs}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="dl3dv", help="a dataset name (with --scenes) or a capture's folder")
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--scenes", nargs="+", default=["castle_p30", "herz_jesus_p25"], help="with a dataset name")
    ap.add_argument("--views", nargs="+", type=int, default=[3, 6, 9])
    ap.add_argument("--iterations", type=int, default=3000, help="the whole run's steps (the baseline phase is a share)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--downscale", type=int, default=8, help="images_N of a DL3DV-layout capture (0: as named)")
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--variant", action="append", default=None, choices=sorted(VARIANTS),
                    help="pseudo-view settings to compare (repeatable; default: all)")
    ap.add_argument("--set", action="append", default=[], help="a config override for training and pseudo views")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--cache", type=Path, default=None,
                    help="folder keeping each case's trained baseline phase, reused by a later call with the same settings")
    args = ap.parse_args(argv)
    variants = args.variant or list(VARIANTS)
    results = {}
    scenes = args.scenes if not Path(args.data).exists() else [None]
    for scene in scenes:
        for views in args.views:
            r = probe(args.data_root, scene, views, args.iterations, args.seed, args.device, variants, args.set,
                      args.downscale or None, args.cache, args.data)
            name_ = r["scene"]
            results[f"{name_}_{views}v"] = r
            for name, v in r["variants"].items():
                s = v["summary"]
                print(f"{name_} {views}v {name:16s} {s['frames']:2d} frames  render {s['render_psnr']}  "
                      f"pseudo {s['pseudo_psnr']}  seen {s['seen']} (render {s['render_psnr_seen']} / pseudo "
                      f"{s['pseudo_psnr_seen']})  reliable {s['reliable']} (render {s['render_psnr_reliable']} / "
                      f"pseudo {s['pseudo_psnr_reliable']} / warp {s['warp_psnr_reliable']})  gain {s['mse_gain_seen']}  improved "
                      f"{s['frames_improved']}/{s['frames']}", flush=True)
            if args.out is not None:
                args.out.parent.mkdir(parents=True, exist_ok=True)
                args.out.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
