"""For a run folder: where the worst test view's top Gaussians (bench/floaters.py's floaters.json) lie against
the camera path of warpgs/clearance.py, in metres and as a fraction of the scene's near depth.

    python bench/path_distance.py RUN_DIR [--data-root ../shared/data] [--device cuda]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> int:
    from warpgs.clearance import PathClearance, segment_distance
    from warpgs.config import build_config
    from warpgs.configio import read_yaml
    from warpgs.pipelines.sparse import load_scene_for
    from warpgs.train import load_trained

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("run")
    p.add_argument("--data-root", default=None)
    p.add_argument("--device", default="cpu")
    a = p.parse_args(argv)
    run = Path(a.run)
    cfg = build_config([(str(run / "config.yaml"), read_yaml(run / "config.yaml"))])
    if a.data_root:
        cfg.data.root = a.data_root
    cfg.train.device = a.device
    scene = load_scene_for(cfg)
    near = json.loads((run / "metrics.json").read_text())["init"]["bounds"][0]
    clear = PathClearance.build(np.stack([c.viewmat for c in scene.train]), 1.0, order=cfg.pseudo.trajectory.order)
    model = load_trained(run / "point_cloud.ply", device=a.device)
    fl = json.loads((run / "floaters.json").read_text())
    idx = torch.tensor([r["index"] for r in fl["worst_top"]], device=model.device)
    d = segment_distance(model.means.detach()[idx], clear.a.to(model.device), clear.b.to(model.device))
    cams = torch.tensor(np.stack([c.center for c in scene.test]), dtype=torch.float32)
    dc = segment_distance(cams, clear.a, clear.b)
    print(f"{run.name}: near {near:.2f}; test cameras from the path: "
          + ", ".join(f"{c.name} {x:.2f} m" for c, x in zip(scene.test, dc.tolist())))
    for r, x in zip(fl["worst_top"], d.tolist()):
        print(f"  {fl['worst']} #{r['index']}: weight {r['test_weight_px']:.0f} px (inputs {r['input_weight_px']:.1f}), "
              f"depth {r['depth_in_view']:.2f}, path {x:.2f} m = {x / near:.3f} near, max scale {r['max_scale']:.2f}, "
              f"opacity {r['opacity']:.2f}, rgb {r['rgb']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
