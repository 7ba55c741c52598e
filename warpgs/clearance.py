"""The capture path is empty space: Gaussians on it are floaters.

Whoever took the photos stood where the cameras are and walked between them, so nothing of the scene lies
on the camera path. The inputs of a sparse capture rarely see that space (it is beside or behind them), so
nothing in the loss removes what drifts there, and a novel view taken from the path looks through it. On
castle_p30 every sudden drop of test PSNR in session 13 was one such Gaussian or a few: opaque, black, within
0.04-2 m of test frame 8 (the scene's near depth is 7.6-11 m), carrying up to 74% of that view's blending
weight with under 60 pixels of weight in all the inputs together; removing them took that view from 13.50 to
23.47 dB (`bench/floaters.py`).

``PathClearance`` is the path as the pseudo views' trajectories sample it (``warpgs.pseudo.trajectory``: the
inputs in capture or nearest-neighbour order, a spline between neighbours), cut into short segments, with a
clearance radius ``fraction`` x the scene's near depth. A segment that passes within that radius of a point
of the initial geometry (an object-centric capture's path crossing the object) is not free and is left
out. ``inside(means)`` marks the Gaussians whose centre lies within the radius of a free segment.
"""

from __future__ import annotations

import numpy as np
import torch


def segment_distance(points: torch.Tensor, a: torch.Tensor, b: torch.Tensor, chunk: int = 1 << 16) -> torch.Tensor:
    """[N] distance of each of ``points`` [N, 3] to the nearest of the segments ``a[k]``-``b[k]`` ([K, 3])."""
    if len(a) == 0:
        return torch.full((len(points),), float("inf"), device=points.device)
    ab = b - a  # [K, 3]
    den = (ab * ab).sum(-1).clamp_min(1e-20)
    out = []
    for i in range(0, len(points), chunk):
        p = points[i:i + chunk, None, :]  # [n, 1, 3]
        t = (((p - a) * ab).sum(-1) / den).clamp(0, 1)  # [n, K]
        d = (p - (a + t[..., None] * ab)).norm(dim=-1)
        out.append(d.min(dim=1).values)
    return torch.cat(out) if out else torch.zeros(0, device=points.device)


class PathClearance:
    """Free segments of the camera path and a clearance radius (module docstring)."""

    def __init__(self, a: torch.Tensor, b: torch.Tensor, radius: float, dropped: int = 0):
        self.a, self.b, self.radius, self.dropped = a, b, float(radius), int(dropped)

    @classmethod
    def build(cls, viewmats, radius: float, order="nearest", samples: int = 16,
              geometry: np.ndarray | torch.Tensor | None = None, device="cpu") -> "PathClearance":
        """From the inputs' world-to-camera matrices [N, 4, 4], the path ``order`` (``path_trajectories``'),
        ``samples`` poses per pair of neighbours, and the points the initialisation found (``geometry``)."""
        from warpgs.pseudo.trajectory import camera_centres, path_trajectories

        V = np.asarray(viewmats if not torch.is_tensor(viewmats) else viewmats.detach().cpu().numpy(), np.float64)
        segs = []
        if len(V) >= 2:
            for traj in path_trajectories(V, max(samples, 2), order):
                c = camera_centres(np.asarray(traj.viewmats, np.float64))
                segs += [(c[i], c[i + 1]) for i in range(len(c) - 1)]
        if not segs:  # one input: its centre only
            c = camera_centres(V)
            segs = [(c[0], c[0])]
        a = torch.tensor(np.array([s[0] for s in segs]), dtype=torch.float32, device=device)
        b = torch.tensor(np.array([s[1] for s in segs]), dtype=torch.float32, device=device)
        dropped = 0
        if geometry is not None and len(geometry):
            g = torch.as_tensor(np.asarray(geometry, np.float32), device=device)
            # per segment: the nearest geometry point (segments x points, chunked over the points)
            near = torch.full((len(a),), float("inf"), device=device)
            for i in range(0, len(g), 4096):
                p = g[i:i + 4096]
                for k in range(len(a)):
                    near[k] = torch.minimum(near[k], segment_distance(p, a[k:k + 1], b[k:k + 1]).min())
            free = near >= radius
            dropped = int((~free).sum())
            a, b = a[free], b[free]
        return cls(a, b, radius, dropped)

    def to(self, device) -> "PathClearance":
        return PathClearance(self.a.to(device), self.b.to(device), self.radius, self.dropped)

    def inside(self, means: torch.Tensor) -> torch.Tensor:
        """[N] bool: centre within ``radius`` of a free segment."""
        return segment_distance(means.detach().float(), self.a.to(means.device), self.b.to(means.device)) < self.radius
