"""Graceful stops (``warpgs.engine.signals``): SIGTERM takes Ctrl-C's path (finish the step, write the
checkpoint, say how to resume) and the run exits with 143; Ctrl-C keeps 130."""

import signal

import pytest
import torch

from tiny_scene import make_scene, param_copy, same_params, tiny_config
from warpgs.engine import CHECKPOINT, Trainer, TrainingInterrupted
from warpgs.engine.signals import StopRequest, exit_code


@pytest.fixture(scope="module")
def scene():
    return make_scene()


def _signal_at(tr, step, signum):
    real = tr.train_step

    def stepped():
        if tr.step == step:
            signal.raise_signal(signum)  # as if the process got it during this step
        return real()

    return stepped


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_finishes_the_step_saves_and_the_resume_is_exact(scene, tmp_path, monkeypatch, signum):
    tr = Trainer(tiny_config(40), scene, tmp_path)
    monkeypatch.setattr(tr, "train_step", _signal_at(tr, 15, signum))
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    logs = []
    tr.log = logs.append
    with pytest.raises(TrainingInterrupted) as e:
        tr.train()
    assert e.value.step == 16 and e.value.signum == signum and e.value.checkpoint == tmp_path / CHECKPOINT
    assert torch.load(tmp_path / CHECKPOINT, weights_only=False)["step"] == 16
    assert {s: signal.getsignal(s) for s in before} == before  # the previous handlers are back
    assert any(("SIGTERM" if signum == signal.SIGTERM else "Ctrl-C") in m for m in logs)
    resumed = Trainer(tiny_config(40), scene, tmp_path)
    resumed.load_checkpoint()
    resumed.train()
    straight = Trainer(tiny_config(40), scene)
    straight.train()
    assert same_params(param_copy(straight), param_copy(resumed)) and straight.losses == resumed.losses


def test_exit_codes_and_a_stop_requested_in_code():
    assert exit_code(signal.SIGTERM) == 143 and exit_code(signal.SIGINT) == 130 and exit_code(None) == 130
    stop = StopRequest(lambda msg: None)
    assert not stop.requested
    stop.request()
    assert stop.requested and stop.signum == signal.SIGINT


def test_the_command_exits_143_on_sigterm_and_130_on_ctrl_c(tmp_path, monkeypatch):
    from warpgs.pipelines import sparse

    cfg = tiny_config(30)
    for signum, code in ((signal.SIGTERM, 143), (signal.SIGINT, 130)):
        real = Trainer.train_step

        def stepped(self, signum=signum, real=real):
            if self.step == 5:
                signal.raise_signal(signum)
            return real(self)

        monkeypatch.setattr(Trainer, "train_step", stepped)
        with pytest.raises(sparse.RunStopped) as e:
            sparse.run_method("baseline", cfg, make_scene(), tmp_path / str(code), resume=False)
        assert e.value.code == code and (tmp_path / str(code) / CHECKPOINT).is_file()
        monkeypatch.setattr(Trainer, "train_step", real)
