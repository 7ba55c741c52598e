"""The training methods, each a ``Method`` of the one loop (``warpgs.engine.Trainer``): ``base`` (the baseline,
which adds nothing), ``full`` (the paper's generation-guided method) and ``corgs`` (CoR-GS's co-regularised
pair over the baseline). ``METHODS`` names them for
``--method``; the modules load when asked for."""

from __future__ import annotations

import importlib

METHODS = {"baseline": ("warpgs.methods.base", "Baseline"), "full": ("warpgs.methods.full", "FullMethod"),
           "corgs": ("warpgs.methods.corgs", "CoRGS")}


def method_class(name: str):
    """The ``Method`` class of the method ``name`` (``ValueError`` naming the known ones otherwise)."""
    if name not in METHODS:
        raise ValueError(f"method={name!r}: the training methods are {', '.join(METHODS)}")
    module, cls = METHODS[name]
    return getattr(importlib.import_module(module), cls)
