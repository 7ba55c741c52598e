"""The ``Method`` protocol: what a training method adds to the one loop of ``warpgs.engine.Trainer``. The engine
defines it and calls it; the methods (``warpgs.methods``) implement it."""

from __future__ import annotations

import torch

from warpgs.optim import STATE_PARTS


class Method:
    """What a training method adds to the one loop of ``Trainer``; this base is the baseline, which adds
    nothing. Hooks, each called by the trainer:

    - ``attach(trainer)``: once, at the end of ``Trainer.__init__`` (the method keeps ``self.trainer``);
    - ``loss_terms(out, cam, loss, parts)``: the training loss of a step from the inputs' ``loss``; extra
      views are rendered and added here, and each term's value goes into ``parts``;
    - ``extra_views()``: the views it trains on besides the inputs (compact mode's importance counts them);
    - ``graph_safe()``, ``graph_inputs(cam)``, ``graph_bind(tensors)``, ``graph_done()``: its terms in a step
      recorded as a CUDA graph (``warpgs.engine.graphstep``);
    - ``state_dict(parts)`` / ``load_state_dict(st)``: the method's share of ``Trainer.state_dict``;
    - ``run()``: the phases of training (``Trainer.run``);
    - ``finish(metrics, baseline)``: records and outputs after ``Trainer.finish``'s own."""

    name = "baseline"
    pair = False  # True: the trainer trains CoR-GS's co-regularised pair with it (warpgs.coreg; corgs.pair adds
    #   it to any method)

    def attach(self, trainer) -> None:
        self.trainer = trainer

    def loss_terms(self, out, cam, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        return loss

    def graph_safe(self) -> bool:
        """Whether ``loss_terms`` now adds only torch operations with no host read and no random draw, so that
        a CUDA graph can hold the step (``warpgs.engine.graphstep``)."""
        return True

    def graph_inputs(self, cam) -> tuple[tuple, dict[str, torch.Tensor], list]:
        """For the step on the input ``cam`` as a CUDA graph's replay: (what the recording depends on, the tensors
        ``loss_terms`` reads that change from step to step, copied into the recording's own before each replay,
        the extra cameras it renders, whose intersection counts bound its capacity). Host-side choices of the step
        (an extra view picked) are made here and kept for the step, replayed or not."""
        return (), {}, []

    def graph_bind(self, tensors: dict[str, torch.Tensor] | None) -> None:
        """While a step is recorded, ``loss_terms`` reads ``tensors`` (the recording's copies of ``graph_inputs``'
        tensors, by the same names); None after the recording."""

    def graph_done(self) -> None:
        """A replay made the step (the host-side choices of ``graph_inputs`` are used)."""

    def extra_views(self) -> list:
        return []

    def state_dict(self, parts=STATE_PARTS) -> dict:
        return {}

    def load_state_dict(self, st: dict) -> None:
        pass

    def run(self) -> None:
        self.trainer.train()

    def finish(self, metrics: dict, baseline: dict | None = None) -> dict:
        return metrics

