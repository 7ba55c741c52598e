"""bench/quality/pseudo_quality.py: the held-out frames it compares with, its per-frame figures on analytic images, and one
tiny end-to-end probe on the CPU (a capture written as nerfstudio frames on a ring)."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from tiny_scene import write_nerfstudio

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "quality"))


def _seq(renders, frames, warped, U):
    from types import SimpleNamespace

    return SimpleNamespace(renders=renders, frames=frames, warped=warped, guidance=warped, uncertainty=U)


def test_frame_record_and_summary_on_analytic_images():
    import pseudo_quality as pq

    gt = torch.full((1, 8, 8, 3), 0.5)
    render = gt + 0.1                      # MSE 0.01 -> 20 dB
    pseudo = gt + 0.05                     # MSE 0.0025 -> about 26.02 dB
    U = torch.ones(1, 8, 8)
    U[0, :4] = 0.2                         # half the pixels seen (U < 1), and reliable (U < 0.5)
    rec = pq.frame_record(_seq(render, pseudo, gt.clone(), U), 0, gt[0], 0.5)
    assert rec["render_psnr"] == pytest.approx(20.0, abs=1e-3)
    assert rec["pseudo_psnr"] == pytest.approx(-10 * math.log10(0.0025), abs=1e-3)
    assert rec["seen"] == 0.5 and rec["reliable"] == 0.5
    assert rec["warp_mse_seen"] == 0.0 and rec["render_mse_seen"] == pytest.approx(0.01, abs=1e-6)
    s = pq.summarise([dict(rec, frame="a")])
    assert s["frames_improved"] == 1
    assert s["mse_gain_seen"] == pytest.approx((0.01 - 0.0025) * 0.5, abs=1e-6)  # > 0: the pseudo view helps
    worse = pq.frame_record(_seq(pseudo, render, gt.clone(), U), 0, gt[0], 0.5)
    assert pq.summarise([dict(worse, frame="a")])["mse_gain_seen"] < 0
    none_seen = pq.frame_record(_seq(render, pseudo, gt.clone(), torch.ones(1, 8, 8)), 0, gt[0], 0.5)
    assert none_seen["render_mse_seen"] is None and none_seen["seen"] == 0.0


def test_trajectories_run_through_the_frames_between_neighbouring_inputs():
    import pseudo_quality as pq
    from types import SimpleNamespace

    V = np.stack([np.eye(4) * (i + 1) for i in range(3)])
    frames = [SimpleNamespace(name=n, viewmat=np.eye(4, dtype=np.float32) * 7) for n in ("00", "02", "03", "06", "09")]
    # inputs named 05, 01, 08 (not in capture order): pairs (01, 05) and (05, 08); 00 and 09 lie outside
    trajs, owners = pq.trajectories_through(["05", "01", "08"], V, frames)
    assert [(t.start, t.end) for t in trajs] == [(1, 0), (0, 2)]
    assert [[f.name for f in o] for o in owners] == [["02", "03"], ["06"]]
    assert len(trajs[0]) == 4 and np.allclose(trajs[0].viewmats[0], V[1]) and np.allclose(trajs[0].viewmats[-1], V[0])


def test_probe_end_to_end_leaves_the_test_and_training_frames_out(tmp_path):
    import pseudo_quality as pq

    data = write_nerfstudio(tmp_path / "ring", n_frames=17)  # test split: frames 0, 8, 16
    out = tmp_path / "q.json"
    pq.main(["--data", str(data), "--downscale", "0", "--views", "3", "--iterations", "10", "--device", "cpu",
             "--variant", "default", "--variant", "unguided", "--set", "model.init=box",
             "--set", "model.init_num=200", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]", "--out", str(out)])
    (case,) = json.loads(out.read_text()).values()
    held = case["held_out"]
    assert held and not {"f000", "f008", "f016"} & set(held)
    for v in case["variants"].values():
        assert [f["frame"] for f in v["frames"]] == held and v["summary"]["frames"] == len(held)
        assert all(f["render_psnr"] is not None and f["pseudo_psnr"] is not None for f in v["frames"])
    # the same trained model for every variant: the renders agree
    a, b = case["variants"]["default"]["frames"], case["variants"]["unguided"]["frames"]
    assert [f["render_psnr"] for f in a] == [f["render_psnr"] for f in b]
