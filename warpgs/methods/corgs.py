"""CoR-GS (Zhang et al., ECCV 2024) as a method, ``--method corgs``: the baseline's loop with a second model
beside the first, the two co-pruned and co-regularised on poses between the training views
(``warpgs.coreg.CoRegPair``; its settings are the section ``corgs``). ``corgs.pair: true`` adds the same pair
to another method (the full method with it: ``--method full --set corgs.pair=true``)."""

from __future__ import annotations

from warpgs.engine.method import Method


class CoRGS(Method):
    name = "corgs"
    pair = True  # the trainer builds the co-regularised pair for this method (Trainer.__init__)


__all__ = ["CoRGS"]
