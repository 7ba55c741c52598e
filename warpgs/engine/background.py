"""What the training and evaluation renders see behind the Gaussians: a colour (``train.background``, else the
scene's white or black), or with ``train.far_field`` a far field fitted on the training views
(``warpgs.farfield``), and for a training step with ``train.random_background`` a random colour behind a view
with an alpha channel."""

from __future__ import annotations

import dataclasses
import time

import torch

from warpgs.farfield import FarFieldImages, make_far_field


class Background:
    """``colour`` [3]; ``far_field`` (None: off) and the seconds its fits took (``far_field_time``, None: none)."""

    def __init__(self, colour: torch.Tensor, train_cams, train_cfg, log):
        self.colour = colour
        self.train_cams, self.tc, self.log = train_cams, train_cfg, log
        self.far_field = None
        self.far_field_time: float | None = None
        self._images = FarFieldImages()

    def fit(self, kind: str, geo=None):
        """``make_far_field`` of ``kind`` on the training views, with the initial points for
        ``train.far_field_proxy``; its choice in one line when something was chosen. Returns it (None: none)."""
        tc = self.tc
        points = None if geo is None or not len(geo.xyz) else geo.xyz
        t0 = time.perf_counter()
        ff = make_far_field(kind, self.train_cams, tc.far_field_bins, self.colour, tc.far_field_blur,
                            tc.far_field_proxy, points)
        took = time.perf_counter() - t0
        if ff is not None:  # the run's per-stage timings (metrics.json stage_times_s far_field_s)
            self.far_field_time = (self.far_field_time or 0.0) + took
        if ff is not None and (tc.far_field_blur == "auto" or ff.proxy):
            self.log(f"warpgs: {ff.describe()} ({took:.1f} s)")
        return ff

    def for_cam(self, cam, keep: bool = True) -> torch.Tensor:
        """What ``cam`` (anything with viewmat, K, width, height) sees behind the Gaussians: the far field's
        [H, W, 3] image when it is on, else the [3] colour. The image is kept for the next render of the same
        camera (``FarFieldImages``) unless ``keep`` is False (a one-off pose)."""
        if self.far_field is None:
            return self.colour
        return self._images.image(self.far_field, cam, keep)

    def for_training(self, cam, generator: torch.Generator):
        """(camera, background) for one training step: with ``train.random_background`` and an alpha channel, a
        random colour from ``generator`` and the target composited over it; else as they are."""
        if not (self.tc.random_background and cam.alpha is not None):
            return cam, self.for_cam(cam)
        # target over a random colour: image = rgb a + bg (1 - a)  ->  image + (1 - a) (new_bg - bg)
        bg = torch.rand(3, device=self.colour.device, generator=generator)
        return dataclasses.replace(cam, image=cam.image + (1 - cam.alpha)[..., None] * (bg - self.colour)), bg
