"""The names the training engine had in this module, kept for scripts that import them from here: the engine
lives in ``warpgs.engine`` (the loop, its step guard, state and checkpoints, initialisation) and
``warpgs.methods`` (``Method``)."""

from warpgs.engine.checkpoint import (CHECKPOINT, PREVIOUS_CHECKPOINT, CheckpointError, TrainingDiverged,  # noqa: F401
                                      TrainingInterrupted, load_trained, previous_checkpoint, read_checkpoint,
                                      resumable_checkpoint)
from warpgs.engine.init import (background_colour, growth_schedule, hold_geometry, init_model,  # noqa: F401
                                prepare_geometry, resolve_device, scene_scale_of)
from warpgs.engine.loop import Trainer  # noqa: F401
from warpgs.engine.method import Method  # noqa: F401
from warpgs.optim import (STATE_PARTS, adam_options, base_learning_rates, finite_flags,  # noqa: F401
                          make_optimizer, masked_step, with_adam_options)
