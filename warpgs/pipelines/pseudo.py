"""Pseudo views from a trained model, on their own: ``python -m warpgs.pipelines.pseudo --model
outputs/run/checkpoint.pt --data llff --out outputs/pseudo`` renders the interpolated poses, warps the
inputs, scores the uncertainty and runs the sampler (warpgs/pseudo/views.py), writing the sequences as PNGs."""

from __future__ import annotations

import argparse
import sys

import torch

from warpgs.data import add_data_args, load_scene_from_args
from warpgs.pseudo.views import (
    add_pseudo_args,
    config_from_args,
    generate_pseudo_views,
    model_renderer,
    resolve_backend,
)
from warpgs.train import CheckpointError, load_trained


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m warpgs.pipelines.pseudo", description=__doc__.split("\n")[0])
    p.add_argument("--model", required=True, help="trained 3D-GS: a PLY or a checkpoint.pt")
    p.add_argument("--out", default="outputs/pseudo", help="folder for the PNGs")
    p.add_argument("--device", default="auto", help="cpu | cuda | auto")
    p.add_argument("--drop-invalid", action="store_true",
                   help="a PLY --model: drop Gaussians with non-finite values (one warning) instead of refusing it")
    add_data_args(p)
    add_pseudo_args(p)
    args = p.parse_args(argv)
    device = ("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device
    try:
        cfg = config_from_args(args)
        resolve_backend(cfg)  # the video model's weights (auto: found or not, said in one line), before anything loads
        scene = load_scene_from_args(args)
        model = load_trained(args.model, device=device, drop_invalid=args.drop_invalid)
    except (ValueError, OSError, CheckpointError) as e:  # ConfigError, SceneError, a refused PLY or checkpoint
        print(f"error: {e}", file=sys.stderr)
        return 2
    bg = [1.0, 1.0, 1.0] if scene.white_background else [0.0, 0.0, 0.0]
    seqs = generate_pseudo_views(model_renderer(model, bg), scene.train, cfg, device=device, out_dir=args.out)
    for s in seqs:
        print(f"inputs {s.start} -> {s.end}: {len(s)} frames, mean U {float(s.uncertainty.mean()):.3f}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
