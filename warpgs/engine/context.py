"""The narrow view of a trainer that its collaborators get (regularisers, the path pruning, methods, stages):
the model and its optimiser and densification state, the strategy, the scene's cameras and their path, the
background, the step, the generators, the log and whether a stop was requested. Never the trainer itself."""

from __future__ import annotations


class Context:
    """Read-through to one trainer: each name is what the trainer holds now (an optimiser is replaced when a
    state is loaded, so nothing is copied)."""

    def __init__(self, trainer):
        self._trainer = trainer
        self.device = trainer.device
        self.cameras = trainer.cameras  # warpgs.engine.cameras.SceneCameras
        self.background = trainer.bg  # warpgs.engine.background.Background
        self.log = trainer.log

    @property
    def cfg(self):
        return self._trainer.cfg

    @property
    def model(self):
        return self._trainer.model

    @property
    def optimizer(self):
        return self._trainer.optimizer

    @property
    def state(self) -> dict:
        """The densification statistics of ``model``."""
        return self._trainer.state

    @property
    def strategy(self):
        return self._trainer.strategy

    @property
    def step(self) -> int:
        return self._trainer.step

    @property
    def total_steps(self) -> int:
        return self._trainer.total_steps

    @property
    def scene_scale(self) -> float:
        return self._trainer.scene_scale

    @property
    def generators(self) -> dict:
        """The trainer's random streams by name: ``split`` (densification, random backgrounds), ``drop``
        (the training renders' opacity factors)."""
        return {"split": self._trainer.split_gen, "drop": self._trainer.drop_gen}

    def opacity_scale(self, step: int, model=None, generator=None):
        """A training render's per-Gaussian opacity factors at ``step`` (``Trainer.opacity_scale``)."""
        return self._trainer.opacity_scale(step, model, generator)

    def stop_requested(self) -> bool:
        """Whether a stop was asked for (Ctrl-C, SIGTERM; ``warpgs.engine.signals``): a long phase polls it."""
        return self._trainer.stop_requested
