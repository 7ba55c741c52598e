"""The ``Regularizer`` protocol: what one training regulariser may add to a step, each hook a no-op here.

A regulariser is built once per trainer by its module's ``build(cfg, ctx)`` (None: off for this run) and
called by the trainer through ``Regularizers`` (``warpgs.regularizers``) in the registry's order, which is
the order in which the terms enter the loss. ``ctx`` is the trainer's narrow view
(``warpgs.engine.context.Context``): the model, the optimisers, the scene's cameras and their path, the
background, the step and the generators, never the trainer itself.
"""

from __future__ import annotations

import torch


class Regularizer:
    """One regulariser; override the hooks it uses (module docstring)."""

    name = "regularizer"

    # ---- terms of the loss, in the order the trainer adds them
    def input_term(self, out, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        """``loss`` plus a term on an input view's render ``out`` (any model's: the co-regularised partner's too);
        added after the inputs' loss (``parts["inputs"]``, which the divergence guard judges)."""
        return loss

    def model_term(self, model, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        """``loss`` plus a prior on ``model``'s parameters (any model's)."""
        return loss

    def step_term(self, ctx, step: int, out, cam, bg, parts: dict) -> torch.Tensor | None:
        """A term of step ``step`` after the method's (it may render more; None: nothing this step)."""
        return None

    # ---- the training renders' opacities and the update
    def opacity_factor(self, ctx, step: int, n: int, generator: torch.Generator) -> torch.Tensor | None:
        """Per-Gaussian opacity factors [n] of one training render (drawn from ``generator``), or None."""
        return None

    def factor_bound(self, ctx, step: int) -> float | None:
        """The largest factor ``opacity_factor`` can give at ``step`` (None: it gives none)."""
        return None

    def after_update(self, ctx, step: int) -> None:
        """Acts on the model after the optimiser's update of ``step`` (device ops only: a CUDA graph holds it)."""

    # ---- what a CUDA graph of the step needs to know (warpgs.engine.graphstep)
    def graph_safe(self, ctx, step: int) -> bool:
        """Whether the step's hooks add only device work with no host read and no draw of their own."""
        return True

    def graph_key(self, ctx, step: int):
        """What a recorded step depends on that may change between steps (compared by value)."""
        return None

    def graph_tensors(self) -> list[torch.Tensor]:
        """The tensors a recorded step reads or writes that live outside it (filled between replays, or counters)."""
        return []

    def graph_counters(self) -> list[torch.Tensor]:
        """Device counters (int64 scalars) of the renders a recorded step's fixed capacity cut short: a recording
        whose counters grew is made again with more room."""
        return []

    def graph_generators(self) -> list[tuple[object, str]]:
        """The generators its step terms draw from on the device, as (holder, attribute): a recorded step
        registers them, so each replay draws anew what the step without the graph would draw."""
        return []

    # ---- its share of the training state (the ``progress`` part)
    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, st: dict) -> None:
        pass
