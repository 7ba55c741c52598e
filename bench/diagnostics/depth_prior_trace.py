"""How much of each input the inputs' plane-sweep depth prior covers, and how right it is there (issue 13).

    python bench/diagnostics/depth_prior_trace.py --data-root ../shared/data            # castle_p30, herz_jesus_p25; 3/6/9 views
    python bench/diagnostics/depth_prior_trace.py --data-root D --scenes castle_p30 --views 9 --out trace.json

For each capture and view count (384x256, the training views of the standard split): the prior that
``full.early_depth`` gives each input (``inputs_plane_sweep``, as ``FullMethod.early_input_depths`` runs it:
plane-sweep stereo between the inputs with ``densify.stereo`` of configs/nerfstudio.yaml, within the scene's
bounds from the SfM points), its
confident pixels, and, against the SfM points (pycolmap with the poses held fixed; the run's ``model.init:
sfm`` before any fallback) that land on a confident pixel, the median relative depth error and the share off
by more than 10%. Writes JSON (``--out``) and prints a line per case. Nothing here trains.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.pipelines.full import inputs_plane_sweep  # noqa: E402
from warpgs.pipelines.sparse import build_parser, load_scene_for, make_config  # noqa: E402
from warpgs.points import GeometryConfig, initial_geometry  # noqa: E402


def check_against_points(depth: torch.Tensor, mask: torch.Tensor, cam, xyz: torch.Tensor) -> dict:
    """The points of ``xyz`` [N, 3] in front of ``cam`` whose pixel is in ``mask``: how many, the median of
    |depth - their z| / z and the share above 0.1 (an empty dict when none)."""
    pc = xyz @ cam.viewmat[:3, :3].T + cam.viewmat[:3, 3]
    pc = pc[pc[:, 2] > 0]
    uv = pc @ cam.K.T
    u = (uv[:, 0] / uv[:, 2]).floor().long()
    v = (uv[:, 1] / uv[:, 2]).floor().long()
    inside = (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    z, u, v = pc[inside, 2], u[inside], v[inside]
    on = mask[v, u]
    if not int(on.sum()):
        return {}
    rel = (depth[v, u][on] - z[on]).abs() / z[on]
    return {"points_on_confident": int(on.sum()), "median_rel_err": round(float(rel.median()), 4),
            "share_over_10pct": round(float((rel > 0.1).float().mean()), 3)}


def trace(data_root: str, scene_name: str, views: int) -> dict:
    args = build_parser().parse_args(["--data", "dl3dv", "--scene", scene_name, "--views", str(views), "--downscale", "8",
                                      "--data-root", data_root, "--method", "full", "--device", "cpu"])
    cfg, _ = make_config(args)
    scene = load_scene_for(cfg)
    cams = [c.to_torch("cpu") for c in scene.train]
    geo = initial_geometry(scene.train, "sfm", GeometryConfig())
    st = inputs_plane_sweep(cams, geo.bounds, cfg.densify.stereo)
    xyz = torch.tensor(geo.xyz, dtype=torch.float32) if geo.method == "sfm" else None
    rows = []
    for v, cam in enumerate(cams):
        row = {"view": cam.name, "confident_px": int(st.mask[v].sum()), "pixels": int(st.mask[v].numel())}
        if xyz is not None and len(xyz):
            row.update(check_against_points(st.depth[v], st.mask[v], cam, xyz))
        rows.append(row)
    cover = [r["confident_px"] / r["pixels"] for r in rows]
    return {"init": geo.method, "points": int(len(geo.xyz)), "bounds": [float(b) for b in geo.bounds],
            "coverage_min": round(min(cover), 5), "coverage_max": round(max(cover), 5), "views": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data-root", required=True)
    ap.add_argument("--scenes", nargs="+", default=["castle_p30", "herz_jesus_p25"])
    ap.add_argument("--views", nargs="+", type=int, default=[3, 6, 9])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    out = {}
    for scene in args.scenes:
        for views in args.views:
            r = out[f"{scene}_{views}v"] = trace(args.data_root, scene, views)
            checked = [x for x in r["views"] if "median_rel_err" in x]
            print(f"{scene} {views} views: init {r['init']}, confident {100 * r['coverage_min']:.2f}-"
                  f"{100 * r['coverage_max']:.2f}% of each input; checked against SfM points in {len(checked)} views, "
                  f"median relative error {', '.join(str(x['median_rel_err']) for x in checked) or '-'}", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
