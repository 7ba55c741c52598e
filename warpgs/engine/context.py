"""The narrow view of a trainer that its collaborators get (regularisers, the path pruning, the co-regularised
pair, compact mode, stages): the model and its optimiser and densification state, the strategy, the scene's
cameras and their path, the background, the step, the generators, the log, whether a stop was requested, and
the few operations of the loop they build on (the losses, densification, evaluation, the training state).
Never the trainer itself, nor anything private of it."""

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
    def isect_capacity(self) -> int | None:
        """The intersection capacity of the step being recorded as a CUDA graph (``warpgs.engine.graphstep``): every
        render of the step uses fixed buffers of this size instead of reading its count; None otherwise."""
        return self._trainer.isect_capacity

    @property
    def total_steps(self) -> int:
        return self._trainer.total_steps

    @property
    def reserved_steps(self) -> int:
        """The run's last steps that a stage (compact mode's search) trains itself (``Trainer.add_stage``)."""
        return self._trainer.reserved_steps

    @property
    def geometry(self):
        """The initial points found between the training views (``warpgs.engine.init.prepare_geometry``; None:
        the initialisation found none)."""
        return self._trainer.geometry

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

    def extra_views(self) -> list:
        """The views the method trains on besides the inputs (``Method.extra_views``)."""
        return self._trainer.method.extra_views()

    # ---- the loop's operations, for those that train a model beside it or after it
    def means_lr(self, step: int) -> float:
        return self._trainer.means_lr(step)

    def compute_loss(self, out, cam):
        """The training loss of a render of the input view ``cam`` (``Trainer.compute_loss``)."""
        return self._trainer.compute_loss(out, cam)

    def input_loss(self, out, cam):
        """The inputs' loss and the regularisers' terms on a render (``Trainer.input_loss``)."""
        return self._trainer.input_loss(out, cam)

    def step_terms(self, step: int, out, cam, bg, loss, parts: dict):
        """``loss`` plus the regularisers' terms of a training step ``step`` on the render ``out`` of ``cam`` over
        ``bg`` (``Regularizers.step_terms``: e.g. the binocular term, which renders a moved camera)."""
        return self._trainer.regularizers.step_terms(self, step, out, cam, bg, loss, parts)

    def after_regularized_update(self, step: int) -> None:
        """The regularisers' work after step ``step``'s update (``Regularizers.after_update``: the opacity decay)."""
        self._trainer.regularizers.after_update(self, step)

    def regularizer_generators(self) -> list[tuple[object, str]]:
        """The regularisers' own random streams as (holder, attribute) (the binocular partner's move)."""
        return self._trainer.regularizers.graph_generators()

    def parameter_priors(self, model, loss, parts: dict):
        """``loss`` plus the regularisers' priors on ``model``'s parameters (``Trainer.parameter_priors``)."""
        return self._trainer.parameter_priors(model, loss, parts)

    def densify(self, strategy, model, optimizer, state: dict, step: int, out, cam, generator) -> dict:
        """A strategy's densification of ``model`` after step ``step`` (``Trainer.densify``)."""
        return self._trainer.densify(strategy, model, optimizer, state, step, out, cam, generator)

    def evaluate(self, cameras=None, lpips: bool = True, render=None) -> dict:
        """Metrics over ``cameras`` (default: the test views) of ``render`` (``Trainer.evaluate``)."""
        return self._trainer.evaluate(cameras, lpips=lpips, render=render)

    def state_dict(self, parts) -> dict:
        """A copy of the ``parts`` of the training state (``warpgs.engine.state.state_dict``)."""
        return self._trainer.state_dict(parts)

    def load_state_dict(self, st: dict) -> None:
        self._trainer.load_state_dict(st)
