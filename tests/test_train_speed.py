"""bench/perf/train_speed.py on the CPU at a tiny size: it writes its JSON, and the trainer (reading its verdicts
every 5 steps and every step) and the plain warpgs loop, started from the same Gaussians with the same views,
rates, loss and densification, end with the same model."""

import json
import sys
from pathlib import Path

from tiny_scene import make_scene, tiny_config, write_nerfstudio
from warpgs.train import Trainer

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "perf"))


def test_train_speed_writes_its_json_and_the_loops_train_alike(tmp_path):
    import train_speed

    data = write_nerfstudio(tmp_path / "scene")
    out = tmp_path / "speed.json"
    train_speed.main(["--data", str(data), "--device", "cpu", "--iterations", "24", "--warmup", "1",
                      "--set", "model.init=box", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]",
                      "--set", "model.init_num=200", "--set", "strategy.refine_start_iter=5",
                      "--set", "strategy.refine_every=10", "--set", "train.sync_every=5",
                      "--loops", "warpgs_trainer,plain_warpgs,warpgs_trainer_sync1,warpgs_trainer_torch_guard",
                      "--out", str(out)])
    r = json.loads(out.read_text())
    assert set(r["loops"]) == {"warpgs_trainer", "plain_warpgs", "warpgs_trainer_sync1", "warpgs_trainer_torch_guard"}
    assert r["same_model_every_sync"] is True and r["settings"]["sync_every"] == 5
    assert r["same_model_torch_guard"] is True
    assert r["settings"]["initial_gaussians"] == 200 and r["settings"]["views"] == 3
    assert r["machine"]["torch"] and r["machine"]["warp"] and r["machine"]["cpu"]
    a, b = r["loops"]["warpgs_trainer"], r["loops"]["plain_warpgs"]
    assert a["gaussians"] == b["gaussians"] != 200  # densified, alike
    assert a["train_psnr"] == b["train_psnr"] and a["test_psnr"] == b["test_psnr"]
    assert r["ratios"]["warpgs_trainer/plain_warpgs"] == round(a["seconds"] / b["seconds"], 3)


def test_the_plain_loops_take_the_trainers_view_order():
    import train_speed

    tr = Trainer(tiny_config(1, seed=3), make_scene())
    assert train_speed.view_order(3, 10, 3) == [tr.next_view() for _ in range(10)]
