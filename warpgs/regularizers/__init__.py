"""The training regularisers: one module each, built through ``REGISTRY`` and called in its order.

    regs = Regularizers.build(cfg, ctx)          # the ones on for this run, in the registry's order
    loss = regs.input_term(out, loss, parts)     # after the inputs' loss (alpha_binary)
    loss = regs.model_term(model, loss, parts)   # priors on a model's parameters (scale_reg)
    loss = regs.step_terms(ctx, step, out, cam, bg, loss, parts)   # after the method's terms (binocular, ...)
    scale = regs.opacity_scale(ctx, step, n, generator)            # a training render's opacity factors
    regs.after_update(ctx, step)                 # after the optimiser's update (opacity decay)

The registry's order is the order of the terms in the loss and of the draws from the generators, so it is part
of the runs' numbers: a new regulariser goes at the end of it. To add one (the binocular term is the worked
example, ``warpgs/regularizers/binocular.py``): a module with its settings' dataclass (``CONFIG``, the section
``regularizers.<name>``), a ``Regularizer`` subclass and a ``build(cfg, ctx)`` that returns it or None (off), a
line below, and a test (docs/architecture.md).
"""

from __future__ import annotations

import importlib

import torch

from warpgs.regularizers.base import Regularizer
from warpgs.registry import build_registered, registry_section

# name -> module (warpgs.regularizers.<module>), in the order their terms enter the loss
REGISTRY = {
    "alpha_binary": "alpha_binary",
    "scale_reg": "scale_reg",
    "dropout": "dropout",
    "opacity_noise": "opacity_noise",
    "opacity_decay": "opacity_decay",
    "binocular": "binocular",
    "path_consistency": "pathconsistency",
}

MODULES = {name: importlib.import_module(f"warpgs.regularizers.{m}") for name, m in REGISTRY.items()}

# the config's section ``regularizers`` (one subsection per regulariser, its module's ``CONFIG`` dataclass) and the
# keys of ``train`` before the section existed -> (regulariser, its key): warpgs.config's MOVED and TrainConfig
RegularizersConfig, LEGACY_TRAIN_KEYS = registry_section(
    "RegularizersConfig", MODULES, __name__,
    "The regularisers' settings (``regularizers.<name>``; warpgs/regularizers/<name>.py).")


class Regularizers:
    """The regularisers on for one trainer, by name in the registry's order; each hook calls theirs in turn."""

    def __init__(self, items: dict[str, Regularizer]):
        self.items = items

    @classmethod
    def build(cls, cfg, ctx, names=None) -> "Regularizers":
        return cls(build_registered(MODULES, cfg, ctx, names))

    def get(self, name: str) -> Regularizer | None:
        return self.items.get(name)

    def input_term(self, out, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        for reg in self.items.values():
            loss = reg.input_term(out, loss, parts)
        return loss

    def model_term(self, model, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        for reg in self.items.values():
            loss = reg.model_term(model, loss, parts)
        return loss

    def step_terms(self, ctx, step: int, out, cam, bg, loss: torch.Tensor, parts: dict) -> torch.Tensor:
        for reg in self.items.values():
            term = reg.step_term(ctx, step, out, cam, bg, parts)
            if term is not None:
                loss = loss + term
        return loss

    def opacity_scale(self, ctx, step: int, n: int, generator: torch.Generator) -> torch.Tensor | None:
        """The product of the regularisers' opacity factors, drawn in the registry's order; None when none gives any."""
        scale = None
        for reg in self.items.values():
            f = reg.opacity_factor(ctx, step, n, generator)
            if f is not None:
                scale = f if scale is None else scale * f
        return scale

    def opacity_scale_bound(self, ctx, step: int) -> float | None:
        """The largest factor ``opacity_scale`` can put on an opacity at ``step`` (None when it puts none): the
        projection's screen box grows with the opacity, so counting tile intersections on opacities scaled by it
        bounds what the step's render emits (a CUDA graph's fixed-capacity buffers, ``warpgs.engine.graphstep``)."""
        bound = None
        for reg in self.items.values():
            b = reg.factor_bound(ctx, step)
            if b is not None:
                bound = b if bound is None else bound * b
        return None if bound is None else bound * (1.0 + 1e-5)

    def after_update(self, ctx, step: int) -> None:
        for reg in self.items.values():
            reg.after_update(ctx, step)

    def graph_safe(self, ctx, step: int) -> bool:
        return all(reg.graph_safe(ctx, step) for reg in self.items.values())

    def graph_key(self, ctx, step: int) -> tuple:
        return tuple(reg.graph_key(ctx, step) for reg in self.items.values())

    def graph_tensors(self) -> list[torch.Tensor]:
        return [t for reg in self.items.values() for t in reg.graph_tensors()]

    def graph_generators(self) -> list[tuple[object, str]]:
        return [g for reg in self.items.values() for g in reg.graph_generators()]

    def graph_counters(self) -> list[torch.Tensor]:
        return [c for reg in self.items.values() for c in reg.graph_counters()]

    def state_dict(self) -> dict:
        st = {}
        for reg in self.items.values():
            st.update(reg.state_dict())
        return st

    def load_state_dict(self, st: dict) -> None:
        for reg in self.items.values():
            reg.load_state_dict(st)


__all__ = ["LEGACY_TRAIN_KEYS", "MODULES", "REGISTRY", "Regularizer", "Regularizers", "RegularizersConfig"]
