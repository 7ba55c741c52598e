"""The ``BackgroundComponent`` protocol: what one component draws behind the Gaussians instead of the colour, each
hook a no-op here.

A component is built once per trainer by its module's ``build(cfg, ctx)`` (None: off for this run) and called by
the trainer's background (``warpgs.engine.background.Background``) through ``Backgrounds``
(``warpgs.backgrounds``) in the registry's order: the first that gives an image for a camera wins. ``ctx`` is the
trainer's narrow view (``warpgs.engine.context.Context``): the scene's cameras, the background colour, the initial
points, the log; never the trainer itself. A component is fitted on the training views only and stays fixed, so
a run and its resume draw the same background.
"""

from __future__ import annotations

import torch


class BackgroundComponent:
    """One background component; override the hooks it uses (module docstring)."""

    name = "background"
    time: float | None = None  # seconds its fit took (metrics.json's stage_times_s ``<name>_s``; None: none)

    def image(self, cam, keep: bool = True) -> torch.Tensor | None:
        """What ``cam`` (anything with viewmat, K, width, height) sees behind the Gaussians, [H, W, 3], or None
        (the colour). ``keep``: the image may be kept for the next render of the same camera."""
        return None

    def save(self, out) -> None:
        """Writes what a viewer needs to draw it into the run folder ``out``."""
