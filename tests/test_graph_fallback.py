"""CUDA graphs of training steps (``warpgs.engine.graphstep``): a run whose step cannot be recorded goes on without the
graphs, drawing its dropout masks from a generator that takes the draws (a generator registered with a failed
capture refused them: "Offset increment outside graph capture"). CUDA only: skipped where torch sees no GPU."""

import pytest
import torch

from tiny_scene import full_method_trainer, make_scene, tiny_config
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


def test_the_full_methods_cycles_replay_with_the_numbers_of_the_steps_without_graphs(tmp_path):
    """The full method after its first cycle (one input and one pseudo view a step, the depth priors of the stereo, the
    binocular term drawing its partner's move on the device, dropout): with the graphs the cycles' steps are
    replays, and every parameter and recorded loss is the one of the run without them, bit for bit."""
    runs = {}
    for graph in (False, True):
        tr = full_method_trainer(tmp_path / str(graph), "cuda", 60, "--set", f"guard.cuda_graph={str(graph).lower()}")
        tr.run()
        runs[graph] = ({k: v.detach().clone() for k, v in tr.model.params.items()}, list(tr.losses), tr.graph)
    (pe, le, _), (pg, lg, g) = runs[False], runs[True]
    assert g is not None and g.off is None and g.replays > 20, (g.off, g.replays)
    assert le == lg
    assert all(torch.equal(pe[k], pg[k]) for k in pe)
