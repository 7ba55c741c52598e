"""The training engine: the loop (``loop.Trainer``), its step guard (``stepguard``), the training state and
checkpoint files (``state``, ``checkpoint``), the initial model (``init``), graceful stops (``signals``), the
scene's cameras and their path (``cameras``), the background (``background``), the narrow context its
collaborators get (``context``), the stages above training (``stage``), CUDA graphs of a step (``graphstep``) and
the evaluation and outputs (``evaluation``)."""

from warpgs.engine.checkpoint import (CHECKPOINT, PREVIOUS_CHECKPOINT, CheckpointError, TrainingDiverged,
                                      TrainingInterrupted, load_trained, read_checkpoint, resumable_checkpoint)
from warpgs.engine.init import (background_colour, growth_schedule, hold_geometry, init_model, prepare_geometry,
                                resolve_device)
from warpgs.engine.loop import Trainer

__all__ = ["CHECKPOINT", "PREVIOUS_CHECKPOINT", "CheckpointError", "Trainer", "TrainingDiverged",
           "TrainingInterrupted", "background_colour", "growth_schedule", "hold_geometry", "init_model",
           "load_trained", "prepare_geometry", "read_checkpoint", "resolve_device", "resumable_checkpoint"]
