"""The capture path is empty space: Gaussians on it are floaters.

Whoever took the photos stood where the cameras are and walked between them, so nothing of the scene lies
on the camera path. The inputs of a sparse capture rarely see that space (it is beside or behind them), so
nothing in the loss removes what drifts there, and a novel view taken from the path looks through it. On
castle_p30 every sudden drop of test PSNR was one such Gaussian or a few: opaque, black, within
0.04-2 m of test frame 8 (the scene's near depth is 7.6-11 m), carrying up to 74% of that view's blending
weight with under 60 pixels of weight in all the inputs together; removing them took that view from 13.50 to
23.47 dB (`bench/diagnostics/floaters.py`).

``PathClearance`` is the path as the pseudo views' trajectories sample it (``warpgs.pseudo.trajectory``: the
inputs in capture or nearest-neighbour order, a spline between neighbours), cut into short segments, with a
clearance radius ``fraction`` x the scene's near depth. A segment that passes within that radius of a point
of the initial geometry (an object-centric capture's path crossing the object) is not free and is left
out. ``inside(means)`` marks the Gaussians whose centre lies within the radius of a free segment.

``PathFloaters`` finds such Gaussians by what they do rather than where they are: a pose on the path (between
neighbouring inputs, where novel views of a walk-through are taken) that sees a Gaussian with more than
``ratio`` x its blending weight in all the inputs together, and for which it carries a visible share of the
weight, is looking at something no input constrains. It is ``bench/diagnostics/floaters.py``'s test with poses of the path
for the test views (which it may not see); that test, with the test views, found the Gaussians behind every
collapse of castle_p30 at 9 views, and removing them restored the views.

``path_partners`` gives the binocular term its partners on the path (``train.binocular_partner: path``): the
poses of the same trajectories next to each input.
"""

from __future__ import annotations

import numpy as np
import torch

from warpgs.strategy.ops import contribution, remove


def _pairwise(points: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """[n, K] distance of each of ``points`` [n, 3] to each segment ``a[k]``-``b[k]`` ([K, 3])."""
    ab = b - a
    p = points[:, None, :]
    t = (((p - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp_min(1e-20)).clamp(0, 1)
    return (p - (a + t[..., None] * ab)).norm(dim=-1)


def segment_distance(points: torch.Tensor, a: torch.Tensor, b: torch.Tensor, chunk: int = 1 << 16) -> torch.Tensor:
    """[N] distance of each of ``points`` [N, 3] to the nearest of the segments ``a[k]``-``b[k]`` ([K, 3])."""
    if len(a) == 0:
        return torch.full((len(points),), float("inf"), device=points.device)
    out = [_pairwise(points[i:i + chunk], a, b).min(dim=1).values for i in range(0, len(points), chunk)]
    return torch.cat(out) if out else torch.zeros(0, device=points.device)


def _path(V: np.ndarray, order, trajectories=None):
    """``trajectories`` (a function of the frames per segment and the centres' kind: ``SceneCameras.
    trajectories``), or one that makes the path of the views ``V`` in ``order`` (``path_trajectories``)."""
    if trajectories is not None:
        return trajectories
    from warpgs.pseudo.trajectory import path_trajectories

    return lambda frames, centres="spline": path_trajectories(V, frames, order, centres=centres)


class PathClearance:
    """Free segments of the camera path and a clearance radius (module docstring); with ``view_depth`` > 0
    also the space each pose of the path looks into, up to that depth (``in_view``)."""

    def __init__(self, a: torch.Tensor, b: torch.Tensor, radius: float, dropped: int = 0,
                 poses: torch.Tensor | None = None, K: torch.Tensor | None = None, size=(0, 0),
                 view_depth: float = 0.0):
        self.a, self.b, self.radius, self.dropped = a, b, float(radius), int(dropped)
        self.poses, self.K, self.size, self.view_depth = poses, K, tuple(size), float(view_depth)

    @classmethod
    def build(cls, viewmats, radius: float, order="nearest", samples: int = 16,
              geometry: np.ndarray | torch.Tensor | None = None, device="cpu", K=None, size=(0, 0),
              view_depth: float = 0.0, trajectories=None) -> "PathClearance":
        """From the inputs' world-to-camera matrices [N, 4, 4], the path ``order`` (``path_trajectories``'),
        ``samples`` poses per pair of neighbours, and the points the initialisation found (``geometry``).
        ``K`` [3, 3] and ``size`` (width, height) of the inputs and ``view_depth`` > 0: the view clearance.
        ``trajectories``: the path as ``SceneCameras.trajectories`` hands it out (default: made here)."""
        from warpgs.pseudo.trajectory import camera_centres

        V = np.asarray(viewmats if not torch.is_tensor(viewmats) else viewmats.detach().cpu().numpy(), np.float64)
        segs = []
        poses = [V[i] for i in range(len(V))]
        if len(V) >= 2:
            for traj in _path(V, order, trajectories)(max(samples, 2)):
                c = camera_centres(np.asarray(traj.viewmats, np.float64))
                segs += [(c[i], c[i + 1]) for i in range(len(c) - 1)]
                poses += [np.asarray(m, np.float64) for m in traj.viewmats[1:-1]]
        if not segs:  # one input: its centre only
            c = camera_centres(V)
            segs = [(c[0], c[0])]
        a = torch.tensor(np.array([s[0] for s in segs]), dtype=torch.float32, device=device)
        b = torch.tensor(np.array([s[1] for s in segs]), dtype=torch.float32, device=device)
        dropped = 0
        if geometry is not None and len(geometry):
            g = torch.as_tensor(np.asarray(geometry, np.float32), device=device)
            # per segment: the nearest geometry point (points x segments, chunked over the points)
            near = torch.stack([_pairwise(g[i:i + 4096], a, b).min(dim=0).values for i in range(0, len(g), 4096)])
            free = near.min(dim=0).values >= radius
            dropped = int((~free).sum())
            a, b = a[free], b[free]
        P = Kt = None
        if view_depth > 0 and K is not None:
            P = torch.tensor(np.stack(poses), dtype=torch.float32, device=device)
            Kt = torch.as_tensor(np.asarray(K, np.float32), device=device)
        return cls(a, b, radius, dropped, P, Kt, size, view_depth)

    def in_view(self, means: torch.Tensor, chunk: int = 1 << 16) -> torch.Tensor:
        """[N] bool: in front of a pose of the path, nearer than ``view_depth``, inside its image."""
        hit = torch.zeros(len(means), dtype=torch.bool, device=means.device)
        if self.poses is None or self.view_depth <= 0:
            return hit
        P, K = self.poses.to(means.device), self.K.to(means.device)
        W, H = self.size
        x = means.detach().float()
        for i in range(0, len(x), chunk):
            cam = torch.einsum("kij,nj->nki", P[:, :3, :3], x[i:i + chunk]) + P[None, :, :3, 3]  # [n, k, 3]
            z = cam[..., 2]
            zc = z.clamp_min(1e-6)
            u = K[0, 0] * cam[..., 0] / zc + K[0, 2]
            v = K[1, 1] * cam[..., 1] / zc + K[1, 2]
            near = (z > 0) & (z < self.view_depth) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
            hit[i:i + chunk] = near.any(dim=1)
        return hit

    def inside(self, means: torch.Tensor) -> torch.Tensor:
        """[N] bool: centre within ``radius`` of a free segment, or (``view_depth``) nearer to a pose of the
        path than that, in its view."""
        d = segment_distance(means.detach().float(), self.a.to(means.device), self.b.to(means.device))
        return (d < self.radius) | self.in_view(means)


class PathFloaters:
    """Poses of the camera path between neighbouring inputs, and the test of ``find`` (module docstring)."""

    def __init__(self, poses: torch.Tensor, K: torch.Tensor, size, ratio: float, min_share: float = 1e-3):
        self.poses, self.K, self.size = poses, K, tuple(size)
        self.ratio, self.min_share = float(ratio), float(min_share)

    @classmethod
    def build(cls, viewmats, K, size, ratio: float, per_pair: int = 3, order="nearest", device="cpu",
              min_share: float = 1e-3, paths: str = "spline", trajectories=None) -> "PathFloaters":
        """``per_pair`` poses strictly between each pair of neighbouring inputs (world-to-camera [N, 4, 4], in
        ``order`` as the pseudo views' trajectories), seen with the inputs' ``K`` [3, 3] and ``size`` (W, H).
        ``paths``: ``"spline"``, the pseudo views' path; ``"both"``, also as many poses on the straight line
        between each pair (the walk between two far-apart inputs can lie nearer the line than the spline).
        ``trajectories``: the path as ``SceneCameras.trajectories`` hands it out (default: made here)."""
        if paths not in ("spline", "both"):
            raise ValueError(f"clearance.floaters_paths must be spline or both, got {paths!r}")
        V = np.asarray(viewmats if not torch.is_tensor(viewmats) else viewmats.detach().cpu().numpy(), np.float64)
        poses = []
        if len(V) >= 2 and per_pair > 0:
            for centres in ("spline", "line") if paths == "both" else ("spline",):
                for traj in _path(V, order, trajectories)(per_pair + 2, centres=centres):
                    poses += [np.asarray(m, np.float64) for m in traj.viewmats[1:-1]]
        P = torch.tensor(np.array(poses).reshape(-1, 4, 4), dtype=torch.float32, device=device)
        return cls(P, torch.as_tensor(np.asarray(K, np.float32), device=device), size, ratio, min_share)

    def find(self, model, inputs, background=None) -> torch.Tensor:
        """[N] bool: the Gaussians of ``model`` that some pose of the path sees with more than ``ratio`` x their
        blending weight (pixels) in ``inputs`` (cameras with viewmat, K, width, height) together, and with at
        least ``min_share`` of that pose's total weight."""
        from types import SimpleNamespace

        found = torch.zeros(len(model), dtype=torch.bool, device=model.device)
        if len(self.poses) == 0 or len(model) == 0:
            return found
        w_in = contribution(model, inputs, background).clamp_min(1e-3)
        W, H = self.size
        K = self.K.to(model.device)
        for vm in self.poses.to(model.device):
            w = contribution(model, [SimpleNamespace(viewmat=vm, K=K, width=W, height=H)], background)
            share = w / w.sum().clamp_min(1e-9)
            found |= (w > self.ratio * w_in) & (share > self.min_share)
        return found


def path_partners(viewmats, names: list[str], order, reach: float, frames: int = 21,
                  trajectories=None) -> dict[str, torch.Tensor]:
    """{name: [M, 4, 4]} the partner poses of each input for ``train.binocular_partner: path``
    (``warpgs.regularizers.binocular``): the poses of the pseudo views' trajectories (``path_trajectories``,
    ``frames`` a segment, in the path ``order``) from the input up to ``reach`` x the way to each neighbouring input."""
    V = np.asarray(viewmats, np.float64).reshape(-1, 4, 4)
    out: dict[int, list] = {}
    if len(V) < 2 or reach <= 0:
        return {}
    m = max(1, int(round(reach * (frames - 1))))
    for traj in _path(V, order, trajectories)(frames):
        out.setdefault(traj.start, []).extend(traj.viewmats[1:m + 1])
        out.setdefault(traj.end, []).extend(traj.viewmats[frames - 1 - m:frames - 1])
    return {names[k]: torch.as_tensor(np.stack(v), dtype=torch.float32) for k, v in out.items()}


class PathPruning:
    """The pruning on the camera path that follows the strategy's densification: ``clearance.path`` /
    ``clearance.view`` (``PathClearance``, every ``strategy.refine_every`` steps) and ``clearance.floaters``
    (``PathFloaters``, every ``clearance.floaters_every`` steps and before the final evaluation). ``time``: seconds the floater passes took (metrics.json's ``path_floaters_s``)."""

    def __init__(self, clearance: PathClearance | None, floaters: PathFloaters | None, floaters_every: int):
        self.clearance, self.floaters, self.floaters_every = clearance, floaters, floaters_every
        self.time = None if floaters is None else 0.0

    @classmethod
    def build(cls, c, scene, cameras, device) -> "PathPruning":
        """From the run's ``clearance`` settings ``c`` (``warpgs.strategy.config.ClearanceConfig``), the scene (its
        near depth, the initial points on ``scene.geometry``) and its cameras and path
        (``warpgs.engine.cameras.SceneCameras``)."""
        c0 = scene.train[0]
        clearance = floaters = None
        if c.path > 0 or c.view > 0:
            geo = getattr(scene, "geometry", None)
            clearance = PathClearance.build(
                cameras.viewmats, c.path * float(scene.bounds[0]), order=cameras.order,
                geometry=None if geo is None else geo.xyz, device=device, K=c0.K, size=(c0.width, c0.height),
                view_depth=c.view * float(scene.bounds[0]), trajectories=cameras.trajectories)
        if c.floaters > 0 and len(scene.train) >= 2:
            floaters = PathFloaters.build(
                cameras.viewmats, c0.K, (c0.width, c0.height), c.floaters, per_pair=c.floaters_poses,
                order=cameras.order, device=device, paths=c.floaters_paths, trajectories=cameras.trajectories)
        return cls(clearance, floaters, c.floaters_every)

    def floaters_due(self, step: int) -> bool:
        """Whether the pass after step ``step``'s densification removes the camera path's floaters."""
        return self.floaters is not None and step > 0 and step % self.floaters_every == 0

    def prunes_at(self, step: int, refine_every: int) -> bool:
        """Whether the pass after step ``step`` prunes anything (a CUDA graph cannot hold such a step)."""
        return (self.clearance is not None and step % refine_every == 0) or self.floaters_due(step)

    def after_densify(self, ctx, step: int, refine_every: int, info: dict) -> None:
        """After the strategy's densification of the trained model at ``step``: the Gaussians on the path go
        (``pruned_on_path`` in ``info``), and the floaters when due (``pruned_floaters``)."""
        model = ctx.model
        if self.clearance is not None and step % refine_every == 0:
            on_path = self.clearance.inside(model.means)
            n = int(on_path.sum())
            if 0 < n < len(model):
                remove(model, ctx.optimizer, ctx.state, on_path)
                info["pruned_on_path"] = n
        if self.floaters_due(step):
            info["pruned_floaters"] = self.remove_floaters(ctx, step)

    def remove_floaters(self, ctx, step: int) -> int:
        """Removes the Gaussians that poses of the camera path see and no input does (``PathFloaters.find``);
        returns how many."""
        import time

        if self.floaters is None:
            return 0
        model = ctx.model
        t0 = time.perf_counter()
        found = self.floaters.find(model, ctx.cameras.train, ctx.background.colour)
        n = int(found.sum())  # a read of the device: the pass's work is done when it returns
        removing = 0 < n < len(model)
        if removing:
            remove(model, ctx.optimizer, ctx.state, found)
        self.time += time.perf_counter() - t0
        if not removing:
            return 0
        ctx.log(f"warpgs: step {step}: {n} Gaussians removed that poses of the camera path see and no input does "
                f"(clearance.floaters)")
        return n
