"""Densification and pruning (gsplat's ``strategy`` package is the model):

- ``default``: ``DefaultStrategy``, the 3D-GS rules (grow, prune, reset opacities), a Gaussian budget and the
  pruning of unseen Gaussians; it is its own config section (``strategy``);
- ``ops``: the tensor surgery on a model and its optimiser (``duplicate``, ``split``, ``remove``,
  ``reset_opacities``, ``update_params``) and ``contribution``, each Gaussian's blending weight over views;
- ``config``: the settings of the stages below (a leaf that ``warpgs.config`` imports);
- ``clearance``: the capture path's clearance and floaters, pruned after the strategy's densification;
- ``compact``: compact mode, importance pruning during training and the size search after it.

This package imports only ``default``, ``ops`` and ``config``: ``clearance`` and ``compact`` sit higher in the
import layers (they use the pseudo views' path and the engine) and are imported by name."""

from warpgs.strategy.default import DefaultStrategy
from warpgs.strategy.ops import (contribution, duplicate, quat_to_rotmat, remove, reset_opacities, split,
                                 update_params)

__all__ = ["DefaultStrategy", "contribution", "duplicate", "quat_to_rotmat", "remove", "reset_opacities", "split",
           "update_params"]
