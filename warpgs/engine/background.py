"""What the training and evaluation renders see behind the Gaussians: a colour (``train.background``, else the
scene's white or black), or what a background component draws (``warpgs.backgrounds``: the far field, fitted on
the training views), and for a training step with ``train.random_background`` a random colour behind a view with
an alpha channel."""

from __future__ import annotations

import dataclasses

import torch

from warpgs.backgrounds import Backgrounds


class Background:
    """``colour`` [3]; ``components``: the background components on for the run (``build``; none until then)."""

    def __init__(self, colour: torch.Tensor, train_cfg):
        self.colour, self.tc = colour, train_cfg
        self.components = Backgrounds({})

    def build(self, cfg, ctx) -> None:
        """The components ``cfg`` turns on (``Backgrounds.build``), fitted once on the training views."""
        self.components = Backgrounds.build(cfg, ctx)

    def for_cam(self, cam, keep: bool = True) -> torch.Tensor:
        """What ``cam`` (anything with viewmat, K, width, height) sees behind the Gaussians: a component's
        [H, W, 3] image (the far field's) when one is on, else the [3] colour. The image is kept for the next
        render of the same camera unless ``keep`` is False (a one-off pose)."""
        img = self.components.image(cam, keep)
        return self.colour if img is None else img

    def for_training(self, cam, generator: torch.Generator):
        """(camera, background) for one training step: with ``train.random_background`` and an alpha channel, a
        random colour from ``generator`` and the target composited over it; else as they are."""
        if not (self.tc.random_background and cam.alpha is not None):
            return cam, self.for_cam(cam)
        # target over a random colour: image = rgb a + bg (1 - a)  ->  image + (1 - a) (new_bg - bg)
        bg = torch.rand(3, device=self.colour.device, generator=generator)
        return dataclasses.replace(cam, image=cam.image + (1 - cam.alpha)[..., None] * (bg - self.colour)), bg
