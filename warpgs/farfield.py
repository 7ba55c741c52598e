"""The far field: what a view shows where no Gaussian covers it.

A few inputs of a walk-around capture leave much of a novel view unseen by any of them (bench/diagnostics/covisibility.py:
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

**A wall around the capture** (``proxy="auto"``, ``backgrounds.far_field.proxy``). A band per elevation of the *ray*
assumes what is unseen lies infinitely far. In a courtyard or a street it does not: a camera near one wall sees
that wall's roof line high above its horizon, where a camera in the middle sees sky (castle_p30's test view 24).
With initial points, the far field can instead index its bands by the elevation, seen from a centre, of the
point where the ray leaves a vertical cylinder (axis along "up", through ``centre`` at the cameras' mean height,
radius ``radius``): the colour then depends on the height on that wall, and a nearer camera sees the roof line
higher. The centre and radius are not guessed per scene: the candidates (the cameras' mean, the points' median,
mean and box centre; radii 0.5-5 x the points' median horizontal distance from that centre; and no cylinder at
all) are scored leave-one-out, each input's pixels predicted from the bands the other inputs fit, and the best
is kept (no cylinder when nothing predicts better; with one input there is nothing to score).

The PLY holds only the Gaussians; ``far_field.json`` in the run folder holds the bands (and the cylinder).
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from pathlib import Path

import numpy as np
import torch

FAR_FIELDS = ("none", "elevation", "sky")
PROXIES = ("none", "auto")  # backgrounds.far_field.proxy: bands by the ray's elevation, or where it leaves a cylinder
PROXY_RADII = (0.5, 1.0, 1.5, 2.0, 3.0, 5.0)  # candidate radii, x the points' median horizontal distance from a centre


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


def camera_centre(viewmat: torch.Tensor) -> torch.Tensor:
    """[3] world position of a world-to-camera ``viewmat``'s camera."""
    V = torch.as_tensor(viewmat).double()
    return -V[:3, :3].T @ V[:3, 3]


def cylinder_directions(dirs: torch.Tensor, origin: torch.Tensor, up: torch.Tensor, centre: torch.Tensor,
                        radius: float) -> torch.Tensor:
    """[..., 3] unit directions from ``centre`` to where rays from ``origin`` along ``dirs`` leave the vertical
    cylinder of ``radius`` around ``centre`` (axis ``up``). From outside the cylinder, the ray's far crossing;
    a ray that misses it keeps its own direction (the wall lies infinitely far)."""
    d = dirs.double()
    up, o = up.double().to(d.device), origin.double().to(d.device) - torch.as_tensor(centre).double().to(d.device)
    oh = o - (o @ up) * up
    dh = d - (d @ up)[..., None] * up
    a = (dh * dh).sum(-1)
    b = dh @ oh
    disc = b * b - a * (float(oh @ oh) - radius * radius)
    hit = (disc >= 0) & (a > 1e-12)
    t = (-b + disc.clamp(min=0).sqrt()) / a.clamp(min=1e-12)
    p = o + t[..., None] * d
    p = p / p.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    return torch.where(hit[..., None], p, d).to(dirs.dtype)


def _band_stats(cam, e: torch.Tensor, bins: int):
    """(band sums [bins, 3], pixel counts [bins], pixels [P, 3]) of a view (float64), for its pixels' band
    coordinates ``e`` in [-1, 1] (the sine of an elevation)."""
    dev = e.device
    img = torch.as_tensor(cam.image, dtype=torch.float32, device=dev)[..., :3].reshape(-1, 3).double()
    b = ((e.reshape(-1) + 1) * 0.5 * bins).long().clamp(0, bins - 1)
    sums = torch.zeros(bins, 3, dtype=torch.float64, device=dev).index_add_(0, b, img)
    counts = torch.zeros(bins, dtype=torch.float64, device=dev).index_add_(0, b, torch.ones_like(b, dtype=torch.float64))
    return sums, counts, img


def band_coordinate(e: torch.Tensor, bins: int) -> torch.Tensor:
    """Continuous band coordinate of elevation sines ``e`` in [-1, 1]: band i's centre is at i."""
    return (e + 1) * 0.5 * bins - 0.5


def interpolate_bands(colors: torch.Tensor, e: torch.Tensor) -> torch.Tensor:
    """[..., 3] the colour at elevation sines ``e`` in [-1, 1]: linear between band centres, the end bands'
    colour beyond their centres (what ``ElevationFarField.image`` renders)."""
    bins = colors.shape[0]
    x = band_coordinate(e, bins).clamp(0, bins - 1)
    i0 = x.floor().long().clamp(max=bins - 1)
    i1 = (i0 + 1).clamp(max=bins - 1)
    w = (x - i0.to(x.dtype))[..., None].to(colors.dtype)
    return colors[i0] * (1 - w) + colors[i1] * w


def proxy_candidates(points: torch.Tensor, cameras_xyz: torch.Tensor, up: torch.Tensor) -> list[tuple[str, torch.Tensor, float]]:
    """(name, centre [3], radius) of the cylinders ``fit(proxy="auto")`` scores: centres at the cameras' mean
    height over the cameras' mean and the points' median, mean and box centre (1st-99th percentiles), radii
    ``PROXY_RADII`` x the points' median horizontal distance from that centre."""
    P, C, up = points.double(), cameras_xyz.double(), up.double()
    height = float(C.mean(0) @ up)
    lo, hi = torch.quantile(P, 0.01, dim=0), torch.quantile(P, 0.99, dim=0)
    centres = {"cameras' mean": C.mean(0), "points' median": P.median(0).values, "points' mean": P.mean(0),
               "points' box centre": 0.5 * (lo + hi)}
    out = []
    for name, c in centres.items():
        c = c - (c @ up) * up + height * up
        r = P - c
        med = float((r - (r @ up)[:, None] * up).norm(dim=1).median())
        if med > 0:
            out += [(name, c, m * med) for m in PROXY_RADII]
    return out


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


def _loo_error(views: list, blur: float) -> float:
    """Squared error of each view's pixels against what the bands the other views fit render there (linear
    between band centres, as ``image`` does), summed over the views. ``views``: (band coordinates [P],
    ``_band_stats``) of each."""
    sums = sum(st[0] for _, st in views)
    counts = sum(st[1] for _, st in views)
    err = 0.0
    for e, (s, n, img) in views:
        c = band_colours(sums - s, counts - n, blur)
        err += float(((interpolate_bands(c, e.reshape(-1).double()) - img) ** 2).sum())
    return err


class ElevationFarField:
    """A colour per elevation band (module docstring). ``up`` [3] unit vector, ``colors`` [bins, 3]; with a
    cylinder (``centre`` [3], ``radius``), the elevation is that of the ray's exit point seen from the centre."""

    def __init__(self, up: torch.Tensor, colors: torch.Tensor, blur: float = 0.0, centre: torch.Tensor | None = None,
                 radius: float | None = None, proxy: dict | None = None):
        self.up = up.float()
        self.colors = colors.float()
        self.blur = blur
        self.centre = None if centre is None else torch.as_tensor(centre, dtype=torch.float64).cpu()
        self.radius = None if radius is None else float(radius)
        self.proxy = proxy or {}  # how the cylinder was chosen: its name and the leave-one-out PSNRs

    @property
    def bins(self) -> int:
        return int(self.colors.shape[0])

    @classmethod
    def fit(cls, cameras, bins: int = 16, blur: float | str = 0.0, proxy: str = "none",
            points=None) -> "ElevationFarField":
        """From ``cameras`` (``CameraTensors`` or ``Camera``s: viewmat, K, width, height, image). ``blur``: the
        width (in bands) of a Gaussian kernel over the elevation that each band's colour averages the training
        pixels with; ``"auto"``: the one of ``BLUR_CHOICES`` that predicts each training view best from the
        others (leave-one-out; 0 with one view). The chosen width is ``self.blur``. ``proxy="auto"`` with
        ``points`` ([N, 3], the initial geometry): the cylinder of ``proxy_candidates`` (or none) that predicts
        each training view best from the others, scored together with the blur (module docstring)."""
        if bins < 1:
            raise ValueError(f"far field: bins must be >= 1, got {bins}")
        if not cameras:
            raise ValueError("far field: no views to fit it on")
        if proxy not in PROXIES:
            raise ValueError(f"backgrounds.far_field.proxy={proxy!r}: expected one of {', '.join(PROXIES)}")
        if blur != "auto" and float(blur) < 0:
            raise ValueError(f"far field: blur must be >= 0 or 'auto', got {blur}")
        mats = [torch.as_tensor(c.viewmat, dtype=torch.float32) for c in cameras]
        up = -torch.stack([m[1, :3] for m in mats]).mean(0)
        if float(up.norm()) < 1e-6:  # up axes that cancel out (cameras rolled all around): the first one's
            up = -mats[0][1, :3]
        up = up / up.norm()
        dirs = [ray_directions(m, torch.as_tensor(c.K), c.width, c.height) for c, m in zip(cameras, mats)]
        candidates: list = [("none", None, None)]
        if proxy == "auto" and points is not None and len(points) >= 10 and len(cameras) >= 2:
            origins = torch.stack([camera_centre(m).cpu() for m in mats])
            candidates += proxy_candidates(torch.as_tensor(np.asarray(points), dtype=torch.float64), origins, up.cpu())
        blurs = BLUR_CHOICES if blur == "auto" else (float(blur),)
        best, scored = None, []
        for name, centre, radius in candidates:
            es = []
            for d, m in zip(dirs, mats):
                if radius is not None:
                    d = cylinder_directions(d, camera_centre(m), up, centre, radius)
                es.append(d.to(up.dtype) @ up.to(d.device))
            views = [(e, _band_stats(c, e, bins)) for c, e in zip(cameras, es)]
            for bl in blurs:
                err = _loo_error(views, bl) if len(views) > 1 else 0.0
                scored.append((err, name, radius))
                if best is None or err < best[0]:
                    best = (err, name, centre, radius, bl, views)
        err, name, centre, radius, blur, views = best
        sums = sum(st[0] for _, st in views)
        counts = sum(st[1] for _, st in views)
        info = {}
        if len(candidates) > 1:
            pixels = 3 * sum(c.width * c.height for c in cameras)
            plain = min(e for e, n, _ in scored if n == "none")
            psnr = lambda e: round(-10 * math.log10(max(e / pixels, 1e-12)), 2)  # noqa: E731
            info = {"name": name, "loo_psnr": psnr(err), "loo_psnr_without": psnr(plain), "candidates": len(candidates)}
        return cls(up, band_colours(sums, counts, blur).float(), blur, centre, radius, info)

    def directions(self, viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int) -> torch.Tensor:
        """[H, W, 3] the unit directions the bands are indexed by: the pixels' rays, or with a cylinder the
        directions from its centre to where they leave it."""
        d = ray_directions(viewmat, K, width, height)
        if self.radius is None:
            return d
        return cylinder_directions(d, camera_centre(viewmat), self.up, self.centre, self.radius)

    def elevation_coordinate(self, dirs: torch.Tensor) -> torch.Tensor:
        """Continuous band coordinate of unit directions: band i's centre is at i."""
        return band_coordinate(dirs @ self.up.to(dirs.device), self.bins)

    def image(self, viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int) -> torch.Tensor:
        """[H, W, 3] far-field colour seen by a camera, on the viewmat's device."""
        e = self.directions(viewmat, K, width, height) @ self.up.to(viewmat.device)
        return interpolate_bands(self.colors.to(viewmat.device), e)

    def describe(self) -> str:
        """One line: the cylinder chosen (or none) and its leave-one-out score."""
        p = self.proxy
        if not p:
            return f"far field: elevation bands, blur {self.blur:g}"
        if self.radius is None:
            return (f"far field: elevation bands of the rays (no cylinder around the capture predicted the inputs "
                    f"better, leave-one-out PSNR {p['loo_psnr']:.2f}), blur {self.blur:g}")
        return (f"far field: elevation bands on a cylinder of radius {self.radius:.3g} around the {p['name']}, chosen "
                f"leave-one-out over the inputs from {p['candidates']} candidates (PSNR {p['loo_psnr']:.2f}, "
                f"{p['loo_psnr_without']:.2f} without it), blur {self.blur:g}")

    def to_dict(self) -> dict:
        d = {"kind": "elevation", "blur": self.blur, "up": [float(v) for v in self.up.cpu()],
             "colors": [[round(float(v), 6) for v in row] for row in self.colors.cpu()]}
        if self.radius is not None:
            d["cylinder"] = {"centre": [float(v) for v in self.centre], "radius": self.radius}
        if self.proxy:
            d["proxy"] = self.proxy
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ElevationFarField":
        cyl = d.get("cylinder") or {}
        return cls(torch.tensor(d["up"], dtype=torch.float32), torch.tensor(d["colors"], dtype=torch.float32),
                   float(d.get("blur", 0.0)), cyl.get("centre"), cyl.get("radius"), d.get("proxy"))

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "ElevationFarField":
        """What ``save`` wrote (a run folder's ``far_field.json``)."""
        return cls.from_dict(json.loads(Path(path).read_text()))


def _nbytes(t: torch.Tensor) -> int:
    return t.numel() * t.element_size()


class FarFieldImages:
    """The far field's image of each camera, kept: it depends only on the far field and the camera, and computing
    it (a ray and, with a cylinder, its exit point per pixel in float64) took 19 ms of a 2-core CPU's step at
    384x256, each step. ``image(far_field, cam)`` returns the one kept for the same far field and the same
    ``cam.viewmat`` / ``cam.K`` tensors and band colours (unchanged since: their version counters) at the same
    size, else computes it and keeps it (``keep=False``: computes it and keeps nothing, for one-off cameras such as a
    fly-through's). At most ``max_bytes`` of images are kept (512 MB: 109 images at 768x512, 20 at 1920x1080), the
    least recently used dropped first. Nothing is kept while a CUDA graph is being captured (its memory belongs to
    the graph)."""

    def __init__(self, max_bytes: int = 512 << 20):
        self.max_bytes = int(max_bytes)
        self.bytes = 0
        self._kept: OrderedDict = OrderedDict()

    @staticmethod
    def _version(t) -> int | None:
        return t._version if isinstance(t, torch.Tensor) else None

    def image(self, far_field, cam, keep: bool = True) -> torch.Tensor:
        vm, K, colors = cam.viewmat, cam.K, far_field.colors
        key = (id(far_field), id(vm), id(K), int(cam.width), int(cam.height))
        versions = (self._version(vm), self._version(K), id(colors), self._version(colors))
        hit = self._kept.get(key)
        if hit is not None and hit[0] is far_field and hit[1] is vm and hit[2] is K and hit[3] == versions:
            self._kept.move_to_end(key)
            return hit[4]
        img = far_field.image(vm, K, cam.width, cam.height)
        capturing = torch.cuda.is_available() and torch.cuda.is_current_stream_capturing()
        size = _nbytes(img)
        if (keep and size <= self.max_bytes and not capturing and isinstance(vm, torch.Tensor)
                and isinstance(K, torch.Tensor)):
            if hit is not None:  # a stale image of the same key
                self.bytes -= _nbytes(hit[4])
            self._kept[key] = (far_field, vm, K, versions, img)
            self._kept.move_to_end(key)
            self.bytes += size
            while self.bytes > self.max_bytes:
                self.bytes -= _nbytes(self._kept.popitem(last=False)[1][4])
        return img


def make_far_field(kind: str, cameras, bins: int, background=None, blur: float | str = 0.0, proxy: str = "none",
                   points=None) -> ElevationFarField | None:
    """The far field ``backgrounds.far_field.kind`` asks for, fitted on ``cameras`` (the training views; ``points``: the
    initial geometry, for ``proxy="auto"``); None for none. ``sky``: the bands above the horizon only; below it,
    ``background`` (default black): the ground is geometry for the Gaussians, not a backdrop."""
    if kind == "none":
        return None
    if kind in ("elevation", "sky"):
        ff = ElevationFarField.fit(cameras, bins, blur, proxy if kind == "elevation" else "none", points)
        if kind == "sky":
            below = (torch.arange(ff.bins, dtype=torch.float32) + 0.5) / ff.bins * 2 - 1 < 0
            bg = torch.zeros(3) if background is None else torch.as_tensor(background, dtype=torch.float32).cpu()
            ff.colors = torch.where(below.to(ff.colors.device)[:, None], bg.to(ff.colors.device), ff.colors)
        return ff
    raise ValueError(f"backgrounds.far_field.kind={kind!r}: expected one of {', '.join(FAR_FIELDS)}")
