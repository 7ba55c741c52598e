"""The far field as a background component (``backgrounds.far_field``): ``warpgs.farfield``'s colour per elevation
band, fitted once on the training views (with the initial points, for ``proxy: auto``) and drawn behind the
Gaussians where no Gaussian covers a view, instead of the background colour. The run folder's ``far_field.json``
holds its bands (and its cylinder) for the viewer."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from warpgs.backgrounds.base import BackgroundComponent
from warpgs.farfield import FAR_FIELDS, ElevationFarField, FarFieldImages, make_far_field

FAR_FIELD_RULE = "{" + ", ".join(FAR_FIELDS) + "}"  # backgrounds.far_field.kind, full.far_field


@dataclass
class FarFieldConfig:
    kind: str = "none"  # none | elevation: behind the Gaussians, a colour per elevation band fitted on the inputs
    #   instead of train.background (captures without alpha) | sky: the bands above the horizon only
    bins: int = 16  # elevation bands
    blur: float | str = 0.0  # width (in bands) of the Gaussian over the elevation that each band averages the
    #   inputs' pixels with; auto: the width that best predicts each input from the others (leave-one-out)
    proxy: str = "none"  # none: bands by the ray's elevation | auto: by the elevation of where the ray leaves a
    #   vertical cylinder around the capture, its centre and radius chosen leave-one-out over the inputs among
    #   candidates from the initial points (or no cylinder when none predicts better; warpgs/farfield.py)

    LIMITS = {"kind": FAR_FIELD_RULE, "bins": ">= 1", "blur": ">= 0 or {auto}", "proxy": "{none, auto}"}
    LEGACY = {"far_field": "kind", "far_field_bins": "bins", "far_field_blur": "blur",
              "far_field_proxy": "proxy"}  # train.<key> of earlier versions (warpgs.config.MOVED)


CONFIG = FarFieldConfig


class FarField(BackgroundComponent):
    """``field``: the fitted ``ElevationFarField``; its images kept per camera (``FarFieldImages``)."""

    name = "far_field"

    def __init__(self, field: ElevationFarField, took: float):
        self.field, self.time = field, took
        self.images = FarFieldImages()

    def image(self, cam, keep: bool = True):
        return self.images.image(self.field, cam, keep)

    def save(self, out) -> None:
        self.field.save(Path(out) / "far_field.json")


def build(cfg, ctx):
    """The far field of ``backgrounds.far_field.kind`` on the training views, or None for none; its choice in one
    line when something was chosen (``blur: auto``, a cylinder)."""
    c = cfg.backgrounds.far_field
    geo = ctx.geometry
    points = None if geo is None or not len(geo.xyz) else geo.xyz
    t0 = time.perf_counter()
    ff = make_far_field(c.kind, ctx.cameras.train, c.bins, ctx.background.colour, c.blur, c.proxy, points)
    if ff is None:
        return None
    took = time.perf_counter() - t0
    if c.blur == "auto" or ff.proxy:
        ctx.log(f"warpgs: {ff.describe()} ({took:.1f} s)")
    return FarField(ff, took)
