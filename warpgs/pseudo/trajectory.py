"""Camera trajectories between the input views (numpy, float64).

    order = nearest_neighbour_path(centers)                     # inputs ordered as a path
    trajs = path_trajectories(viewmats, n_frames=25)           # one Trajectory per pair of neighbours
    traj = perturb_trajectory(traj, score, rng, n_candidates=5)  # optional: keep the most uncertain pose
    trajs += offset_trajectories(trajs, viewmats, [-0.5, 0.5])  # optional: copies of the path above and below

Along the path, rotations are interpolated by slerp between neighbours and camera centres by a natural
cubic spline through all centres (chord-length knots), as in the released SYN3R code. A trajectory has
``n_frames`` poses and includes both ends: frame 0 is the start input's pose and frame N-1 the end
input's, so the video model is conditioned on real images at both ends.

``trajectory.offsets`` (ours) adds copies of every trajectory moved off the path: each frame's centre by
``offset`` x the distance between the pair's inputs along the inputs' mean "up" direction (made perpendicular
to the pair's chord), turned to keep looking at the point its axis looked at (the projection on that axis of
the point nearest to all the inputs' optical axes). An object-centric capture (DTU's camera rows) is tested from
above and below the row its inputs lie on, where the path never goes.

Poses are world-to-camera 4x4 matrices in OpenCV axes (``warpgs/__init__.py``); quaternions (w, x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Callable

import numpy as np
import torch

from warpgs.geometry import (  # noqa: F401  (pose helpers: re-exported for this module's readers)
    axis_angle_to_rotmat, camera_centres, pose, quat_to_rotmat, rotmat_to_quat, slerp)


@dataclass
class TrajectoryConfig:
    n_frames: int = 25  # poses per trajectory, both inputs included (SVD img2vid-xt makes 25 frames)
    perturb_candidates: int = 0  # 0: no perturbation; SYN3R draws 5 candidates per pose
    perturb_translation: float = 0.1  # candidate centre sigma, x the distance between the two inputs
    perturb_rotation_deg: float = 0.1  # candidate rotation sigma (degrees)
    # nearest: the closest input camera (paper); halves: first half from the start input (SYN3R);
    # best: per pixel, the less uncertain of the trajectory's two inputs (warps both)
    guidance_source: str = "nearest"
    # raw: the warped input's own colours | affine: per frame and source input, the gain and offset per channel that
    # bring the warp to the render's colours in the reliable pixels (exposure, white balance; guidance.match_colour)
    guidance_colour: str = "raw"
    # capture: the inputs in the order given (a walk-through's frames sorted by name: the capture path, as the
    # paper does for DL3DV); nearest: a nearest-neighbour path through the camera centres (any capture)
    order: str = "nearest"
    # copies of the path moved off it, each frame by offset x the pair's distance along the inputs' mean up direction
    # (perpendicular to the pair), turned to keep its look-at point (offset_trajectories); [] = the path only (an
    # offset of 0 is the path itself and adds nothing)
    offsets: list = field(default_factory=list)

    LIMITS = {"offsets": "[-2, 2]", "n_frames": ">= 2", "perturb_candidates": ">= 0", "perturb_translation": ">= 0",
              "perturb_rotation_deg": ">= 0", "guidance_source": "{nearest, halves, best}", "order": "{capture, nearest}",
              "guidance_colour": "{raw, affine}"}


@dataclass
class Trajectory:
    """Poses from input ``start`` to input ``end`` (indices into the caller's list of inputs)."""

    start: int
    end: int
    viewmats: np.ndarray  # (N, 4, 4) float64, world -> camera
    offset: float = 0.0  # off the path (offset_trajectories): frames 0 and N-1 are not the inputs' poses then

    def __len__(self) -> int:
        return len(self.viewmats)

    @property
    def centers(self) -> np.ndarray:
        return camera_centres(self.viewmats)


# ----------------------------------------------------------------------------------------------
# ordering and splines


def nearest_neighbour_path(centers: np.ndarray) -> list[int]:
    """Inputs ordered as an open path: a greedy nearest-neighbour tour from every start, the shortest kept.

    Ties go to the lower index, so the result is deterministic."""
    c = np.asarray(centers, np.float64)
    n = len(c)
    if n <= 2:
        return list(range(n))
    dist = np.linalg.norm(c[:, None] - c[None], axis=-1)
    best, best_len = None, np.inf
    for s in range(n):
        path, seen, length = [s], {s}, 0.0
        while len(path) < n:
            d = dist[path[-1]].copy()
            d[list(seen)] = np.inf
            k = int(np.argmin(d))
            length += d[k]
            path.append(k)
            seen.add(k)
        if length < best_len - 1e-12:
            best, best_len = path, length
    # a path and its reverse are the same tour: start from the lower-indexed end
    return best if best[0] < best[-1] else best[::-1]


def natural_cubic_spline(knots: np.ndarray, values: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """The natural cubic spline (second derivative 0 at both ends) through (knots, values (n, d))."""
    t = np.asarray(knots, np.float64)
    y = np.asarray(values, np.float64).reshape(len(t), -1)
    n = len(t)
    h = np.diff(t)
    if n < 2 or np.any(h <= 0):
        raise ValueError("spline knots must be strictly increasing and at least two")
    M = np.zeros_like(y)  # second derivatives at the knots
    if n > 2:
        A = np.zeros((n - 2, n - 2))
        rhs = 6.0 * ((y[2:] - y[1:-1]) / h[1:, None] - (y[1:-1] - y[:-2]) / h[:-1, None])
        for i in range(n - 2):
            A[i, i] = 2.0 * (h[i] + h[i + 1])
            if i > 0:
                A[i, i - 1] = h[i]
            if i < n - 3:
                A[i, i + 1] = h[i + 1]
        M[1:-1] = np.linalg.solve(A, rhs)

    def evaluate(s: np.ndarray) -> np.ndarray:
        s = np.atleast_1d(np.asarray(s, np.float64))
        k = np.clip(np.searchsorted(t, s, side="right") - 1, 0, n - 2)
        hk = h[k][:, None]
        a = (t[k + 1][:, None] - s[:, None]) / hk
        b = (s[:, None] - t[k][:, None]) / hk
        return a * y[k] + b * y[k + 1] + ((a**3 - a) * M[k] + (b**3 - b) * M[k + 1]) * hk**2 / 6.0

    return evaluate


def chord_knots(centers: np.ndarray) -> np.ndarray:
    """Cumulative distance along the centres (uniform knots where two centres coincide)."""
    d = np.linalg.norm(np.diff(np.asarray(centers, np.float64), axis=0), axis=1)
    if np.any(d <= 1e-9 * max(1.0, float(d.max(initial=0.0)))):
        return np.arange(len(centers), dtype=np.float64)
    return np.concatenate([[0.0], np.cumsum(d)])


def path_trajectories(viewmats: np.ndarray, n_frames: int, order: list[int] | str | None = None,
                      centres: str = "spline") -> list[Trajectory]:
    """One trajectory of ``n_frames`` poses between each pair of neighbours along the path.

    ``order``: a list of indices, ``"capture"`` (the order given), or ``"nearest"`` / None (the
    ``nearest_neighbour_path`` of the camera centres); Trajectory.start/end index ``viewmats``.
    ``centres``: ``"spline"`` (the natural cubic spline through all centres, chord-length knots) or ``"line"``
    (straight between the two neighbours); the rotations are slerped either way."""
    V = np.asarray(viewmats, np.float64).reshape(-1, 4, 4)
    if n_frames < 2:
        raise ValueError(f"a trajectory needs at least 2 frames, got {n_frames}")
    if len(V) < 2:
        raise ValueError("pseudo-view trajectories need at least two input views")
    if order is None or order == "nearest":
        order = nearest_neighbour_path(camera_centres(V))
    elif order == "capture":
        order = list(range(len(V)))
    elif isinstance(order, str):
        raise ValueError(f"trajectory order must be capture, nearest or a list of indices, got {order!r}")
    if centres not in ("spline", "line"):
        raise ValueError(f"trajectory centres must be spline or line, got {centres!r}")
    order = list(order)
    C = camera_centres(V[order])
    knots = chord_knots(C)
    spline = natural_cubic_spline(knots, C)
    quats = [rotmat_to_quat(V[k, :3, :3].T) for k in order]  # camera-to-world rotations
    s = np.linspace(0.0, 1.0, n_frames)
    out = []
    for seg in range(len(order) - 1):
        if centres == "line":
            cs = C[seg] + s[:, None] * (C[seg + 1] - C[seg])
        else:
            cs = spline(knots[seg] + s * (knots[seg + 1] - knots[seg]))
        mats = np.stack([pose(quat_to_rotmat(slerp(quats[seg], quats[seg + 1], si)), c) for si, c in zip(s, cs)])
        mats[0], mats[-1] = V[order[seg]], V[order[seg + 1]]  # the ends are the inputs, exactly
        out.append(Trajectory(order[seg], order[seg + 1], mats))
    return out


# ----------------------------------------------------------------------------------------------
# off the path


def focus_point(viewmats: np.ndarray, max_condition: float = 1e6) -> np.ndarray | None:
    """The point nearest (least squares) to every camera's optical axis, or None where the axes are too close
    to parallel to fix one (condition number above ``max_condition``: a forward-facing capture) or it lies
    behind a camera."""
    V = np.asarray(viewmats, np.float64).reshape(-1, 4, 4)
    if len(V) < 2:
        return None
    C = camera_centres(V)
    F = V[:, 2, :3]  # optical axes in the world (rows of world -> camera: the camera's z axis)
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for c, f in zip(C, F):
        P = np.eye(3) - np.outer(f, f)
        A += P
        b += P @ c
    if np.linalg.cond(A) > max_condition:
        return None
    p = np.linalg.solve(A, b)
    if np.any(np.einsum("ij,ij->i", p[None] - C, F) <= 0):
        return None
    return p


def _turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b`` (Rodrigues)."""
    v = np.cross(a, b)
    s, c = np.linalg.norm(v), float(np.dot(a, b))
    if s < 1e-12:
        return np.eye(3)  # (never called with opposite vectors: both axes look at the same point)
    return axis_angle_to_rotmat(v / s * np.arctan2(s, c))


def offset_trajectories(trajs: list[Trajectory], viewmats: np.ndarray, offsets) -> list[Trajectory]:
    """For each offset (a share of each pair's distance; signed: + is up) a copy of every trajectory moved off
    the path (module doc). "Up" is the inputs' mean up direction (-y of the OpenCV camera) made perpendicular
    to the pair's chord (the chord's cross product with the mean optical axis where they are parallel).
    Each moved frame turns by the smallest rotation that keeps the point it looked at (the projection of
    ``focus_point`` on its axis) on its optical axis; without a focus point (forward-facing inputs) the
    frames only move."""
    V = np.asarray(viewmats, np.float64).reshape(-1, 4, 4)
    up = -V[:, 1, :3].mean(axis=0)
    forward = V[:, 2, :3].mean(axis=0)
    focus = focus_point(V)
    out = []
    for e in offsets:
        for t in trajs:
            c = t.centers
            chord = c[-1] - c[0]
            length = float(np.linalg.norm(chord))
            if length <= 0:
                continue
            a = chord / length
            u = up - np.dot(up, a) * a
            if np.linalg.norm(u) < 1e-6 * max(np.linalg.norm(up), 1e-12):
                u = np.cross(a, forward)
            u = u / np.linalg.norm(u)
            move = float(e) * length * u
            mats = []
            for M, ci in zip(t.viewmats, c):
                R_c2w = M[:3, :3].T
                f = R_c2w[:, 2]
                turn = np.eye(3)
                if focus is not None:
                    d = float(np.dot(focus - ci, f))
                    if d > 0:  # from the moved centre to the look-at point ci + d f
                        g = d * f - move
                        turn = _turn(f, g / np.linalg.norm(g))
                mats.append(pose(turn @ R_c2w, ci + move))
            out.append(Trajectory(t.start, t.end, np.stack(mats), offset=float(e)))
    return out


# ----------------------------------------------------------------------------------------------
# perturbation


def perturb_pose(viewmat: np.ndarray, rng: np.random.Generator, translation_sigma: float,
                 rotation_sigma_deg: float) -> np.ndarray:
    """A nearby pose: centre + N(0, translation_sigma^2 I), rotation by a random small rotation vector."""
    V = np.asarray(viewmat, np.float64)
    R_c2w = V[:3, :3].T
    c = -R_c2w @ V[:3, 3]
    dR = axis_angle_to_rotmat(rng.normal(0.0, np.radians(rotation_sigma_deg), 3))
    return pose(R_c2w @ dR, c + rng.normal(0.0, translation_sigma, 3))


def perturb_trajectory(
    traj: Trajectory,
    score: Callable[[int, np.ndarray], float],
    rng: np.random.Generator,
    n_candidates: int = 5,
    translation: float = 0.1,
    rotation_deg: float = 0.1,
) -> Trajectory:
    """Replaces every interior pose by the most uncertain of ``n_candidates`` perturbed candidates.

    ``score(frame, viewmat)`` is the uncertainty of a candidate (e.g. the mean of ``uncertainty_map``);
    the translation sigma is ``translation`` x the distance between the trajectory's two inputs.
    The end poses are the inputs and stay."""
    if n_candidates <= 0 or len(traj) <= 2:
        return traj
    c = traj.centers
    sigma_t = translation * float(np.linalg.norm(c[-1] - c[0]))
    mats = traj.viewmats.copy()
    for f in range(1, len(traj) - 1):
        cands = [perturb_pose(traj.viewmats[f], rng, sigma_t, rotation_deg) for _ in range(n_candidates)]
        scores = [float(score(f, m)) for m in cands]
        mats[f] = cands[int(np.argmax(scores))]
    return Trajectory(traj.start, traj.end, mats, traj.offset)


def guidance_sources(traj: Trajectory, input_centers: np.ndarray, mode: str = "nearest") -> np.ndarray:
    """For each frame, the input (index into ``input_centers``) whose view is warped into its guidance.

    ``nearest``: the input with the closest camera centre (the paper's "nearest input view");
    ``halves``: frames i < N/2 from the start input, the rest from the end input (SYN3R).
    (``best`` chooses per pixel and is resolved by the caller, which warps both ends.)"""
    n = len(traj)
    if mode == "halves":
        return np.where(np.arange(n) < n / 2, traj.start, traj.end).astype(np.int64)
    if mode != "nearest":
        raise ValueError(f"guidance_source must be 'nearest' or 'halves', got {mode!r}")
    d = np.linalg.norm(traj.centers[:, None] - np.asarray(input_centers, np.float64)[None], axis=-1)
    return np.argmin(d, axis=1).astype(np.int64)


def virtual_cameras(cams, frames: int) -> list:
    """``frames`` poses strictly between each pair of neighbouring cameras along their nearest-neighbour
    path (``path_trajectories``), each with the intrinsics and size of the pair's first camera."""
    if len(cams) < 2 or frames <= 0:
        return []
    V = np.stack([c.viewmat.detach().cpu().double().numpy() for c in cams])
    out = []
    for traj in path_trajectories(V, frames + 2):
        ref = cams[traj.start]
        for M in traj.viewmats[1:-1]:
            out.append(SimpleNamespace(viewmat=torch.tensor(M, dtype=torch.float32, device=ref.viewmat.device),
                                       K=ref.K, width=ref.width, height=ref.height))
    return out
