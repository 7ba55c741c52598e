"""The ``Stage`` protocol: a part of a run above its training (compact mode's search,
``warpgs.strategy.compact.CompactStage``), added by whoever builds the trainer (``Trainer.add_stage``;
``warpgs.pipelines.sparse.make_trainer``), so the engine imports none of them. A stage gets the trainer's narrow
view (``warpgs.engine.context.Context``), never the trainer."""

from __future__ import annotations


class Stage:
    """A stage of a run; this base does nothing. Hooks, each called by the trainer:

    - ``reserve_steps(iterations)``: how many of the run's last steps the stage trains itself (the loop stops that
      many early, and ``finish`` counts them once the stage has run);
    - ``wrap_strategy(strategy, ctx)``: the strategy the loop densifies with (the stage's pruning around it);
    - ``before_evaluation(ctx)``: runs the stage after training, before the test metrics; returns its record
      (metrics.json's ``name``) or None. ``size_before``: the Gaussians before it removed any, once it ran
      (metrics.json's ``num_gaussians_before_compaction`` when nothing set it earlier)."""

    name = "stage"
    size_before: int | None = None

    def reserve_steps(self, iterations: int) -> int:
        return 0

    def wrap_strategy(self, strategy, ctx):
        return strategy

    def before_evaluation(self, ctx) -> dict | None:
        return None
