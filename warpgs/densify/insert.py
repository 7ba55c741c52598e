"""Radius-gated insertion of new Gaussians from a densified point cloud.

    new = insert_points(existing_means, cloud_points, cloud_colors, radius=0.02)
    new.means [N, 3], new.colors [N, 3], new.scales [N, 3]  (standard deviations; log them for the model)
    new.added [C] bool: which candidates became Gaussians

A candidate becomes a Gaussian only where no existing Gaussian centre lies within ``radius`` of it
(Warp ``HashGrid`` radius query). With ``thin=True`` (default) the surviving candidates are also
thinned among themselves to at least ``radius`` apart, by a parallel greedy independent set
(``warpgs.kernels.neighbours.thin_round``), so a dense cloud does not add clumps of overlapping
Gaussians. A new Gaussian's scale is 3D-GS's initial scale, sqrt of the mean squared distance to its
``k`` nearest neighbours among the existing and the added centres (searched within
``spacing_radius``; missing neighbours count as that distance), times ``scale_factor``.

Tensors stay on their device (cpu or cuda); no open3d here (the GPU benchmark runs without it).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import NamedTuple

import torch
import warp as wp

from warpgs._warp import arg, device_of, launch, stream_of, to_wp
from warpgs.kernels import neighbours as kn


@dataclass
class InsertConfig:
    radius: float | None = None  # no new Gaussian within this distance of an existing one (world units);
    # None: densify_gaussians picks DensifyConfig.auto_radius x the cloud's extent
    thin: bool = True  # also keep the added Gaussians at least ``radius`` apart
    k: int = 3  # neighbours for the spacing-based scale (3D-GS uses 3)
    spacing_radius: float | None = None  # neighbour search radius for the scale; None: 4 x radius
    scale_factor: float = 1.0  # x the local spacing
    seed: int = 0  # thinning order

    LIMITS = {"radius": "> 0", "k": ">= 1", "spacing_radius": "> 0", "scale_factor": "> 0", "seed": ">= 0"}


class Insertion(NamedTuple):
    means: torch.Tensor  # [N, 3] centres of the new Gaussians
    colors: torch.Tensor  # [N, 3] their colours (from the cloud), or [N, 0] when no colours were given
    scales: torch.Tensor  # [N, 3] isotropic standard deviations (not logs)
    added: torch.Tensor  # [C] bool over the candidates: became a new Gaussian
    near_existing: torch.Tensor  # [C] bool: rejected because an existing Gaussian is within the radius
    rounds: int  # thinning rounds run


def _grid_dims(n: int) -> int:
    # hash table of about n cells (at least 16^3, at most 256^3 = 16M cells of two int32)
    return int(min(256, max(16, round(n ** (1.0 / 3.0)))))


def build_grid(points: torch.Tensor, cell: float, device: str) -> wp.HashGrid:
    """A ``wp.HashGrid`` over ``points`` [N, 3] float32 (contiguous) with cells ``cell`` wide."""
    dim = _grid_dims(points.shape[0])
    grid = wp.HashGrid(dim, dim, dim, device=device)
    if points.shape[0] > 0:
        grid.build(to_wp(points, wp.vec3), float(cell))
    return grid


def within_radius(points: torch.Tensor, queries: torch.Tensor, radius: float) -> torch.Tensor:
    """[Q] bool: some row of ``points`` lies within ``radius`` of each query (HashGrid query)."""
    _check(points, "points")
    _check(queries, "queries")
    dev = device_of(queries)
    hit = torch.zeros(queries.shape[0], dtype=torch.int32, device=queries.device)
    if points.shape[0] == 0 or queries.shape[0] == 0:
        return hit.bool()
    p = points.float().contiguous()
    q = queries.float().contiguous()
    stream = stream_of(dev)
    with wp.ScopedStream(stream) if stream is not None else contextlib.nullcontext():
        grid = build_grid(p, radius, dev)
        launch(kn.any_within_radius, q.shape[0], [grid.id, arg(p, wp.vec3), arg(q, wp.vec3), float(radius), arg(hit)], dev, stream)
    return hit.bool()


def thin_points(points: torch.Tensor, radius: float, seed: int = 0) -> tuple[torch.Tensor, int]:
    """[N] bool mask of a subset of ``points`` whose members are pairwise farther apart than ``radius``
    and that leaves every other point within ``radius`` of a member (a maximal independent set, the
    greedy one in a fixed pseudo-random order). Also returns the number of parallel rounds."""
    _check(points, "points")
    n = points.shape[0]
    dev = device_of(points)
    if n == 0:
        return torch.zeros(0, dtype=torch.bool, device=points.device), 0
    p = points.float().contiguous()
    stream = stream_of(dev)
    state = [torch.zeros(n, dtype=torch.int32, device=points.device) for _ in range(2)]
    counter = torch.zeros(1, dtype=torch.int32, device=points.device)
    rounds = 0
    with wp.ScopedStream(stream) if stream is not None else contextlib.nullcontext():
        grid = build_grid(p, radius, dev)
        while True:
            counter.zero_()
            launch(kn.thin_round, n, [grid.id, arg(p, wp.vec3), float(radius), int(seed) & 0x7FFFFFFF,
                                      arg(state[0]), arg(state[1]), arg(counter)], dev, stream)
            rounds += 1
            state.reverse()
            if int(counter.item()) == 0:  # one sync per round; O(log n) rounds with random priorities
                break
            if rounds > 10_000:  # pragma: no cover - cannot happen: each round accepts the top-ranked
                raise RuntimeError("thinning did not converge")
    return state[0] == int(kn.ACCEPTED), rounds


def local_spacing(points: torch.Tensor, query_index: torch.Tensor, k: int, search_radius: float) -> torch.Tensor:
    """[Q] sqrt of the mean squared distance from ``points[query_index]`` to their ``k`` nearest other
    rows of ``points`` within ``search_radius`` (missing neighbours count as ``search_radius``)."""
    _check(points, "points")
    if not 1 <= k <= kn.MAX_K:
        raise ValueError(f"k must be in 1..{kn.MAX_K}, got {k}")
    dev = device_of(points)
    idx = query_index.to(device=points.device, dtype=torch.int32).contiguous()
    out = torch.empty(idx.shape[0], dtype=torch.float32, device=points.device)
    if idx.shape[0] == 0:
        return out
    p = points.float().contiguous()
    stream = stream_of(dev)
    with wp.ScopedStream(stream) if stream is not None else contextlib.nullcontext():
        grid = build_grid(p, search_radius, dev)
        launch(kn.knn_mean_sq_distance, idx.shape[0], [grid.id, arg(p, wp.vec3), arg(idx), int(k), float(search_radius), arg(out)], dev, stream)
    return out.sqrt_()


def insert_points(
    existing_means: torch.Tensor,
    candidates: torch.Tensor,
    candidate_colors: torch.Tensor | None = None,
    radius: float | None = None,
    config: InsertConfig | None = None,
) -> Insertion:
    """New Gaussians from the ``candidates`` [C, 3] that have no existing centre within ``radius``.

    ``existing_means`` [N, 3] and ``candidates`` must be on one device; ``candidate_colors`` [C, 3]
    (any channel count) is carried over to the added rows. ``radius`` overrides ``config.radius``.
    """
    cfg = config or InsertConfig()
    if radius is None and cfg.radius is None:
        raise ValueError("insert_points needs a radius (argument or InsertConfig.radius)")
    r = float(cfg.radius if radius is None else radius)
    if not (r > 0.0 and math.isfinite(r)):
        raise ValueError(f"insertion radius must be a positive finite number, got {r}")
    _check(existing_means, "existing_means")
    _check(candidates, "candidates")
    if existing_means.device != candidates.device:
        raise ValueError(f"existing_means is on {existing_means.device}, candidates on {candidates.device}")
    if candidate_colors is not None and candidate_colors.shape[0] != candidates.shape[0]:
        raise ValueError(f"candidate_colors has {candidate_colors.shape[0]} rows, candidates {candidates.shape[0]}")
    dev = candidates.device
    cand = candidates.float().contiguous()
    finite = torch.isfinite(cand).all(dim=1)
    near = within_radius(existing_means, cand, r)
    keep = finite & ~near
    rounds = 0
    if cfg.thin and bool(keep.any()):
        idx = keep.nonzero().squeeze(1)
        sub, rounds = thin_points(cand[idx].contiguous(), r, cfg.seed)
        keep = torch.zeros_like(keep)
        keep[idx[sub]] = True
    new = cand[keep]
    spacing_r = float(cfg.spacing_radius) if cfg.spacing_radius is not None else 4.0 * r
    allp = torch.cat([existing_means.float(), new]).contiguous()
    qi = torch.arange(existing_means.shape[0], allp.shape[0], device=dev)
    spacing = local_spacing(allp, qi, cfg.k, spacing_r)
    scales = (spacing * cfg.scale_factor).unsqueeze(1).expand(-1, 3).contiguous()
    colors = candidate_colors[keep] if candidate_colors is not None else torch.zeros(new.shape[0], 0, device=dev)
    return Insertion(new, colors, scales, keep, near & finite, rounds)


def _check(t: torch.Tensor, name: str) -> None:
    if not isinstance(t, torch.Tensor) or t.dim() != 2 or t.shape[1] != 3:
        raise ValueError(f"{name} must be a [N, 3] tensor, got {getattr(t, 'shape', type(t))}")
