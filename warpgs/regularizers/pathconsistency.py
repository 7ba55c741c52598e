"""Two-view consistency at poses of the capture path (``full.path_consistency``, ``regularizers.path_consistency``).

At a pose between two neighbouring inputs, the photos of both, warped into it with the depth the model renders there
(``warpgs.regularizers.binocular.pose_warp``), should agree wherever both see the same surface. The term is their mean absolute
difference over the pixels both land in; its gradient reaches that depth only (the photos are fixed). The full method
evaluates it at the pseudo view it trains on anyway (its render is there; ``full.path_consistency``). Any method can
have it at a pose of the pseudo views' trajectories drawn each step, at the cost of one more render
(``regularizers.path_consistency``, this module's ``PathConsistency``): the measure of whether a gain is the pseudo views'.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
import numpy as np
import torch

from warpgs.regularizers.base import Regularizer


def two_view_consistency(depth: torch.Tensor, view, a, b) -> torch.Tensor:
    """The term for one pose ``view`` (viewmat, K) and its rendered ``depth`` [H, W]: the photos of inputs ``a`` and
    ``b`` warped into it with that depth, mean absolute difference over the pixels both land in (0 where none do).
    The inputs must share the view's intrinsics and size."""
    from warpgs.regularizers.binocular import pose_warp, rigid_inverse

    inv = rigid_inverse(view.viewmat.float())
    wa, ma = pose_warp(a.image, depth, a.viewmat.float() @ inv, view.K)
    wb, mb = pose_warp(b.image, depth, b.viewmat.float() @ inv, view.K)
    both = ma * mb
    return ((wa - wb).abs().mean(-1) * both).sum() / (both.sum() + 1e-6)


def check_one_camera(cams, option: str) -> None:
    """A clear error unless every view of ``cams`` has one size and one camera matrix (the warp's assumption)."""
    Ks = torch.stack([torch.as_tensor(c.K, dtype=torch.float32).cpu() for c in cams])
    if len({(c.width, c.height) for c in cams}) > 1 or not torch.allclose(Ks, Ks[:1].expand_as(Ks)):
        raise ValueError(f"{option} needs input views of one size and one camera matrix (K); these differ: "
                         f"set {option}=0")


@dataclass
class PathConsistencyConfig:
    weight: float = 0.0  # weight of the two inputs' agreement at a pose of the pseudo views' trajectories drawn each
    #   step (one more render a step): their photos warped into it with its rendered depth, L1 where both land. The
    #   full method's own is full.path_consistency, at its pseudo views; 0: off
    start: float = 0.4  # share of the run's steps before it starts (the full method's first cycle)

    LIMITS = {"weight": ">= 0", "start": "[0, 1]"}
    LEGACY = {"path_consistency": "weight", "path_consistency_start": "start"}  # train.<key> of earlier versions


CONFIG = PathConsistencyConfig  # the section regularizers.<name> of the run's config


class PathConsistency(Regularizer):
    """``regularizers.path_consistency`` for one trainer: the interior poses of the pseudo views' trajectories between each
    pair of neighbouring inputs; from step ``start`` on, each step one of them (drawn with a generator the checkpoint
    keeps) is rendered and the term computed there."""

    name = "path_consistency"

    def __init__(self, weight: float, start: int, cams, trajectories, seed: int, device):
        check_one_camera(cams, "regularizers.path_consistency")
        self.weight, self.start = weight, start
        poses, self.pairs = [], []
        for traj in trajectories:
            for vm in traj.viewmats[1:-1]:
                poses.append(vm)
                self.pairs.append((traj.start, traj.end))
        self.poses = torch.as_tensor(np.stack(poses), dtype=torch.float32, device=device)
        self.rng = np.random.default_rng(int(seed) + 29)

    def active(self, step: int) -> bool:
        return self.weight > 0 and step >= self.start

    def loss(self, model, cams, background, opacity_scale, parts: dict) -> torch.Tensor:
        """weight x the term at one drawn pose (rendered over ``background`` with ``opacity_scale``), recorded in
        ``parts`` as ``path_consistency``."""
        from types import SimpleNamespace

        k = int(self.rng.integers(len(self.pairs)))
        a, b = (cams[i] for i in self.pairs[k])
        view = SimpleNamespace(viewmat=self.poses[k], K=a.K)
        out = model.render(view.viewmat, a.K, a.width, a.height, background=background, opacity_scale=opacity_scale,
                           check_finite=False)
        term = two_view_consistency(out.depth, view, a, b)
        parts["path_consistency"] = term.detach()
        return self.weight * term

    # the Regularizer hooks: one more render a step, of a pose drawn on the host (not held by a CUDA graph)
    def step_term(self, ctx, step: int, out, cam, bg, parts: dict) -> torch.Tensor | None:
        if not self.active(step):
            return None
        return self.loss(ctx.model, ctx.cameras.train, ctx.background.colour, ctx.opacity_scale(step), parts)

    def graph_safe(self, ctx, step: int) -> bool:
        return not self.active(step)

    def state_dict(self) -> dict:
        return {"path_consistency_rng": copy.deepcopy(self.rng.bit_generator.state)}

    def load_state_dict(self, st: dict) -> None:
        if "path_consistency_rng" in st:
            self.rng.bit_generator.state = copy.deepcopy(st["path_consistency_rng"])


def build(cfg, ctx) -> PathConsistency | None:
    """``weight`` > 0 with two inputs or more: the term at the interior poses of the pseudo views' trajectories
    (``pseudo.trajectory.n_frames`` a segment), from ``start`` x the run on."""
    c, tc = cfg.regularizers.path_consistency, cfg.train
    if not (c.weight > 0 and len(ctx.cameras.views) >= 2):
        return None
    return PathConsistency(c.weight, int(c.start * tc.iterations), ctx.cameras.views,
                           ctx.cameras.trajectories(max(cfg.pseudo.trajectory.n_frames, 3)), tc.seed, ctx.device)
