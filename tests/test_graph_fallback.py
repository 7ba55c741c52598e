"""CUDA graphs of training steps (``warpgs.engine.graphstep``): a run whose step cannot be recorded goes on without the
graphs, drawing its dropout masks from a generator that takes the draws (a generator registered with a failed
capture refused them: "Offset increment outside graph capture"). CUDA only: skipped where torch sees no GPU."""

import pytest
import torch

from tiny_scene import make_scene, tiny_config
from warpgs.engine.graphstep import StepGraph
from warpgs.train import Trainer

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")


def test_a_step_that_cannot_be_recorded_leaves_the_run_without_graphs_and_its_dropout_drawing(monkeypatch):
    def unrecordable(self, cam, capacity):  # a host sync while the stream is captured invalidates the capture
        torch.cuda.synchronize()
        raise AssertionError("not reached: the capture refuses the sync")

    monkeypatch.setattr(StepGraph, "_body", unrecordable)
    cfg = tiny_config(60, drop_rate=0.2, cuda_graph=True)
    cfg.train.device = "cuda"
    tr = Trainer(cfg, make_scene(device="cuda"))
    tr.train()
    assert tr.step == 60
    assert tr.graph is not None and tr.graph.off is not None and tr.graph.captures == 0
    assert all(bool(torch.isfinite(p).all()) for p in tr.model.params.values())
