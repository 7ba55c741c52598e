"""The far field: what a view shows where no Gaussian covers it.

A few inputs of a walk-around capture leave much of a novel view unseen by any of them (bench/covisibility.py:
on castle_p30 with 3 views a test view's training views see 32% of it on average). Over a black background
those regions render black, and during training Gaussians grow to cover the inputs' sky and distant walls
with whatever depth they happen to have, then float in front of the novel views.

``ElevationFarField`` is a background that depends on the viewing direction only through its elevation
above the capture's horizon: a colour per elevation band, the mean of the training pixels whose rays fall in
that band (linearly interpolated between band centres; bands no input sees take the nearest seen band's
colour). Sky, distant facades and the ground repeat around a capture far more than they change with the
azimuth, so this is the least-squares guess for an unseen direction that the inputs support, and it needs no
weights. It is fitted once on the training views only (never the test views) and stays fixed, so a run and
its resume compute the same one. "Up" is the mean of the training cameras' up axes (OpenCV: -y).

    ff = ElevationFarField.fit(train_cams, bins=16)
    out = model.render(cam.viewmat, cam.K, W, H, background=ff.image(cam.viewmat, cam.K, W, H))

The PLY holds only the Gaussians; ``far_field.json`` in the run folder holds the bands.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch

FAR_FIELDS = ("none", "elevation", "sky")


def ray_directions(viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """[H, W, 3] unit world-space directions of the pixel centres of a pinhole camera (OpenCV axes)."""
    dev = viewmat.device
    v, u = torch.meshgrid(torch.arange(height, device=dev, dtype=torch.float32) + 0.5,
                          torch.arange(width, device=dev, dtype=torch.float32) + 0.5, indexing="ij")
    K = K.float()
    x = (u - K[0, 2]) / K[0, 0]
    y = (v - K[1, 2]) / K[1, 1]
    d = torch.stack([x, y, torch.ones_like(x)], -1) @ viewmat[:3, :3].float()  # R^T d, as row vectors
    return d / d.norm(dim=-1, keepdim=True)


BLUR_CHOICES = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0)  # ``blur="auto"`` picks among these widths (in bands)


def _band_stats(cam, viewmat: torch.Tensor, up: torch.Tensor, bins: int):
    """A view's per-band pixel sums [bins, 3], pixel counts [bins] and sums of squares [bins] (float64)."""
    dev = viewmat.device
    img = torch.as_tensor(cam.image, dtype=torch.float32, device=dev).reshape(-1, 3).double()
    e = ray_directions(viewmat, torch.as_tensor(cam.K, device=dev), cam.width, cam.height) @ up
    b = ((e.reshape(-1) + 1) * 0.5 * bins).long().clamp(0, bins - 1)
    sums = torch.zeros(bins, 3, dtype=torch.float64, device=dev).index_add_(0, b, img)
    counts = torch.zeros(bins, dtype=torch.float64, device=dev).index_add_(0, b, torch.ones_like(b, dtype=torch.float64))
    squares = torch.zeros(bins, dtype=torch.float64, device=dev).index_add_(0, b, (img * img).sum(1))
    return sums, counts, squares


def band_colours(sums: torch.Tensor, counts: torch.Tensor, blur: float) -> torch.Tensor:
    """[bins, 3] colours from per-band pixel sums and counts: with ``blur`` > 0 each band averages the pixels
    of all bands weighted by a Gaussian of their distance (in bands); bands with no pixel take the nearest
    seen band's colour."""
    bins = counts.shape[0]
    idx = torch.arange(bins, device=counts.device, dtype=torch.float64)
    if blur > 0:
        k = torch.exp(-0.5 * ((idx[:, None] - idx[None]) / blur) ** 2)
        sums, counts = k @ sums, k @ counts
    seen = torch.nonzero(counts > 1e-9).flatten()
    colors = sums / counts.clamp(min=1e-9)[:, None]
    if len(seen) < bins:  # unseen bands: the nearest seen band's colour
        near = seen[(idx[:, None] - idx[seen][None]).abs().argmin(1)]
        colors = colors[near]
    return colors


def choose_blur(stats: list, choices=BLUR_CHOICES) -> float:
    """The blur of ``choices`` whose far field, fitted on all views but one, predicts the left-out view's pixels
    with the least squared error, summed over the views (``stats``: ``_band_stats`` of each). What no input
    sees is a guess from the others: how sharply the colours of the inputs' elevation bands carry over to a
    view they did not see is measured on the inputs themselves. 0 with a single view."""
    if len(stats) < 2:
        return 0.0
    sums = sum(s for s, _, _ in stats)
    counts = sum(n for _, n, _ in stats)
    errors = []
    for blur in choices:
        err = 0.0
        for s, n, q in stats:
            c = band_colours(sums - s, counts - n, blur)
            err += float((q - 2 * (c * s).sum(1) + n * (c * c).sum(1)).sum())
        errors.append(err)
    return float(choices[min(range(len(choices)), key=errors.__getitem__)])


class ElevationFarField:
    """A colour per elevation band (module docstring). ``up`` [3] unit vector, ``colors`` [bins, 3]."""

    def __init__(self, up: torch.Tensor, colors: torch.Tensor, blur: float = 0.0):
        self.up = up.float()
        self.colors = colors.float()
        self.blur = blur

    @property
    def bins(self) -> int:
        return int(self.colors.shape[0])

    @classmethod
    def fit(cls, cameras, bins: int = 16, blur: float | str = 0.0) -> "ElevationFarField":
        """From ``cameras`` (``CameraTensors`` or ``Camera``s: viewmat, K, width, height, image). ``blur``: the
        width (in bands) of a Gaussian kernel over the elevation that each band's colour averages the training
        pixels with; ``"auto"``: the one of ``BLUR_CHOICES`` that predicts each training view best from the
        others (leave-one-out; 0 with one view). The chosen width is ``self.blur``."""
        if bins < 1:
            raise ValueError(f"far field: bins must be >= 1, got {bins}")
        if not cameras:
            raise ValueError("far field: no views to fit it on")
        mats = [torch.as_tensor(c.viewmat, dtype=torch.float32) for c in cameras]
        up = -torch.stack([m[1, :3] for m in mats]).mean(0)
        if float(up.norm()) < 1e-6:  # up axes that cancel out (cameras rolled all around): the first one's
            up = -mats[0][1, :3]
        up = up / up.norm()
        stats = [_band_stats(c, m, up, bins) for c, m in zip(cameras, mats)]
        if blur == "auto":
            blur = choose_blur(stats)
        blur = float(blur)
        if blur < 0:
            raise ValueError(f"far field: blur must be >= 0 or 'auto', got {blur}")
        sums = sum(s for s, _, _ in stats)
        counts = sum(n for _, n, _ in stats)
        return cls(up, band_colours(sums, counts, blur).float(), blur)

    def elevation_coordinate(self, dirs: torch.Tensor) -> torch.Tensor:
        """Continuous band coordinate of unit directions: band i's centre is at i."""
        return (dirs @ self.up.to(dirs.device) + 1) * 0.5 * self.bins - 0.5

    def image(self, viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int) -> torch.Tensor:
        """[H, W, 3] far-field colour seen by a camera, on the viewmat's device."""
        x = self.elevation_coordinate(ray_directions(viewmat, K, width, height)).clamp(0, self.bins - 1)
        i0 = x.floor().long().clamp(max=self.bins - 1)
        i1 = (i0 + 1).clamp(max=self.bins - 1)
        w = (x - i0.float())[..., None]
        colors = self.colors.to(viewmat.device)
        return colors[i0] * (1 - w) + colors[i1] * w

    def to_dict(self) -> dict:
        return {"kind": "elevation", "blur": self.blur, "up": [float(v) for v in self.up.cpu()],
                "colors": [[round(float(v), 6) for v in row] for row in self.colors.cpu()]}

    @classmethod
    def from_dict(cls, d: dict) -> "ElevationFarField":
        return cls(torch.tensor(d["up"], dtype=torch.float32), torch.tensor(d["colors"], dtype=torch.float32),
                   float(d.get("blur", 0.0)))

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ElevationFarField":
        """What ``save`` wrote (a run folder's ``far_field.json``)."""
        return cls.from_dict(json.loads(Path(path).read_text()))


def make_far_field(kind: str, cameras, bins: int, background=None, blur: float | str = 0.0) -> ElevationFarField | None:
    """The far field ``train.far_field`` asks for, fitted on ``cameras`` (the training views); None for none.
    ``sky``: the bands above the horizon only; below it, ``background`` (default black): the ground is
    geometry for the Gaussians, not a backdrop."""
    if kind == "none":
        return None
    if kind in ("elevation", "sky"):
        ff = ElevationFarField.fit(cameras, bins, blur)
        if kind == "sky":
            below = (torch.arange(ff.bins, dtype=torch.float32) + 0.5) / ff.bins * 2 - 1 < 0
            bg = torch.zeros(3) if background is None else torch.as_tensor(background, dtype=torch.float32).cpu()
            ff.colors = torch.where(below.to(ff.colors.device)[:, None], bg.to(ff.colors.device), ff.colors)
        return ff
    raise ValueError(f"train.far_field={kind!r}: expected one of {', '.join(FAR_FIELDS)}")
