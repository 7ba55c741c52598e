"""Binocular consistency (Han et al., "Binocular-Guided 3D Gaussian Splatting with View Consistency for Sparse
View Synthesis", NeurIPS 2024): a weight-free geometry term on the input views (``regularizers.binocular``).

At a training step on an input view, the model is also rendered from that camera moved by ``t`` along its own
x axis (a rectified stereo partner: same intrinsics and rotation). With the depth ``z`` rendered at the input,
the moved render is warped back into the input (``moved(x - fx t / z)``, ``warpgs.kernels.warping.shift_warp``)
and compared with the input photo (L1 where both taps of the warp fall inside the image). The gradient
reaches the depth through the warp's sampling position and the moved render's colours, so depth that does not
hold the photo's content at the right distance is pushed to where a second eye would see it. An edge-aware
smoothness of the disparity ``fx t / z`` (in pixels) goes with it, as in their code (weight 0.05).

``t`` is drawn each step uniformly in ``[-s, s]`` with ``s`` the shift that gives ``shift`` x
the image width of disparity at the render's median depth: the same stereo geometry at every scene scale
and resolution (their code draws in ``[-0.4, 0.4]`` scene units; Blender's 400-pixel views at 4 units give
about 0.14 of the width). The draw happens on the device (no host read). The term starts at
``start`` x the run's steps (theirs: 20,000 of 30,000 on LLFF and DTU, 4000 of 7000 on
Blender).

``axes: xy`` (ours) moves the camera in a direction of its image plane drawn each step
(uniform angle; the same distance as above), up and down as well as sideways, and warps back with the general
reprojection (``pose_warp``).

``partner: path`` (ours) replaces the sideways partner by a pose of the capture path: the
poses the pseudo views' trajectories pass through (splined centres, slerped rotations), from the input up to
``reach`` x the way to each neighbouring input, one drawn per step. The moved render is warped
back with the general reprojection (``pose_warp``: a turn and a move in any direction) and compared with the
photo as above. On a walk-around capture the test views lie along that path, between the inputs, where a
sideways move of the same size says nothing about the depth the path's views need.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs import losses
from warpgs._warp import arg, device_of, launch, stream_of
from warpgs.kernels import warping as kw
from warpgs.regularizers.base import Regularizer
import warp as wp

MIN_DEPTH = 1e-6


class _ShiftWarp(torch.autograd.Function):
    @staticmethod
    def forward(ctx, moved, depth, ft):
        moved = moved.contiguous().float()
        depth = depth.contiguous().float()
        ft = ft.reshape(1).contiguous().float()
        H, W = depth.shape
        warped = torch.empty(H, W, 3, device=depth.device, dtype=torch.float32)
        weight = torch.empty(H, W, device=depth.device, dtype=torch.float32)
        dev = device_of(depth)
        launch(kw.shift_warp, (H, W), [arg(moved, wp.vec3), arg(depth), arg(ft), MIN_DEPTH, arg(warped, wp.vec3),
                                        arg(weight)], dev, stream_of(dev))
        ctx.save_for_backward(moved, depth, ft)
        ctx.mark_non_differentiable(weight)
        return warped, weight

    @staticmethod
    def backward(ctx, v_warped, _v_weight):
        moved, depth, ft = ctx.saved_tensors
        H, W = depth.shape
        v_moved = torch.zeros_like(moved)
        v_depth = torch.empty_like(depth)
        dev = device_of(depth)
        launch(kw.shift_warp_backward, (H,), [arg(moved, wp.vec3), arg(depth), arg(ft), MIN_DEPTH,
                                                 arg(v_warped.contiguous().float(), wp.vec3), arg(v_moved, wp.vec3),
                                                 arg(v_depth)], dev, stream_of(dev))  # a thread per row
        return v_moved, v_depth, None


def shift_warp(moved: torch.Tensor, depth: torch.Tensor, ft) -> tuple[torch.Tensor, torch.Tensor]:
    """``moved`` [H, W, 3] (the render from the camera moved by t along its x axis) sampled at ``x - ft / z`` of
    each pixel of the input (``depth`` [H, W], z-depth; ``ft`` = fx t, a float or a one-element tensor), linearly
    along the row with zero padding -> (warped [H, W, 3], weight [H, W]: the share of the two taps inside the
    image, 0 where the depth is <= 0). Differentiable in ``moved`` and ``depth`` (Warp kernels,
    ``warpgs.kernels.warping.shift_warp``); ``weight`` is not."""
    if depth.dim() != 2 or moved.shape != (*depth.shape, 3):
        raise ValueError(f"shift_warp: moved [H, W, 3] and depth [H, W] of one size expected, got "
                         f"{list(moved.shape)} and {list(depth.shape)}")
    if not torch.is_tensor(ft):
        ft = torch.tensor([float(ft)], device=depth.device)
    return _ShiftWarp.apply(moved, depth, ft.to(depth.device))


class _PoseWarp(torch.autograd.Function):
    @staticmethod
    def forward(ctx, moved, depth, rel, K):
        moved = moved.contiguous().float()
        depth = depth.contiguous().float()
        rel = rel.reshape(1, 4, 4).contiguous().float()
        K = K.reshape(1, 3, 3).contiguous().float()  # (inverted in the kernel)
        H, W = depth.shape
        warped = torch.empty(H, W, 3, device=depth.device, dtype=torch.float32)
        weight = torch.empty(H, W, device=depth.device, dtype=torch.float32)
        dev = device_of(depth)
        launch(kw.pose_warp, (H, W), [arg(moved, wp.vec3), arg(depth), arg(rel, wp.mat44), arg(K, wp.mat33),
                                       MIN_DEPTH, arg(warped, wp.vec3), arg(weight)], dev, stream_of(dev))
        ctx.save_for_backward(moved, depth, rel, K)
        ctx.mark_non_differentiable(weight)
        return warped, weight

    @staticmethod
    def backward(ctx, v_warped, _v_weight):
        moved, depth, rel, K = ctx.saved_tensors
        H, W = depth.shape
        v_fixed = torch.zeros(H, W, 3, device=depth.device, dtype=torch.int64)
        v_depth = torch.empty_like(depth)
        dev = device_of(depth)
        launch(kw.pose_warp_backward, (H, W), [arg(moved, wp.vec3), arg(depth), arg(rel, wp.mat44), arg(K, wp.mat33),
                                                MIN_DEPTH, arg(v_warped.contiguous().float(), wp.vec3),
                                                arg(v_fixed, wp.int64), arg(v_depth)], dev, stream_of(dev))
        v_moved = (v_fixed.double() * 2.0**-40).float()  # the rasterizer's fixed point (FIXED_SCALE = 2^40)
        return v_moved, v_depth, None, None


def pose_warp(moved: torch.Tensor, depth: torch.Tensor, rel: torch.Tensor, K: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """``moved`` [H, W, 3] (the render from another camera of the same intrinsics ``K`` [3, 3]) sampled where each
    pixel of the input, at its ``depth`` [H, W] (z-depth), lands in that camera (``rel`` [4, 4]: input camera ->
    moved camera, ``P_moved P_input^-1``), bilinearly with zero padding -> (warped [H, W, 3], weight [H, W]: the
    share of the four taps inside the image, 0 where the depth or the reprojected depth is <= 0).
    Differentiable in ``moved`` and ``depth`` (Warp kernels, ``warpgs.kernels.warping.pose_warp``); ``weight``
    is not. ``shift_warp`` is its special case of a move along x."""
    if depth.dim() != 2 or moved.shape != (*depth.shape, 3):
        raise ValueError(f"pose_warp: moved [H, W, 3] and depth [H, W] of one size expected, got "
                         f"{list(moved.shape)} and {list(depth.shape)}")
    return _PoseWarp.apply(moved, depth, rel.to(depth.device), K.to(depth.device))


def rigid_inverse(viewmat: torch.Tensor) -> torch.Tensor:
    """The inverse of a rigid 4x4 transform, [R^T, -R^T t] (no linear solve: nothing to check, no host read)."""
    inv = torch.zeros_like(viewmat)
    rt = viewmat[:3, :3].T
    inv[:3, :3] = rt
    inv[:3, 3] = -rt @ viewmat[:3, 3]
    inv[3, 3] = 1.0
    return inv


def moved_viewmat(viewmat: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """The world-to-camera matrix of the camera moved by ``t`` (a one-element tensor) along its own x axis:
    camera coordinates x - t, the rest unchanged."""
    vm = viewmat.clone()
    vm[0, 3] = vm[0, 3] - t.reshape(())
    return vm


@dataclass
class BinocularConfig:
    weight: float = 0.0  # weight of the binocular consistency on the input views: the render from the camera moved
    #   along its x axis, warped back with the input's rendered depth, against the photo (their weight: 1); 0: off
    shift: float = 0.1  # the largest move: this x the image width of disparity at the median depth
    start: float = 0.5  # share of the run's steps before the term starts (theirs: 2/3 LLFF/DTU, 4/7 Blender)
    smooth: float = 0.05  # edge-aware smoothness of the disparity (pixels) with it (theirs: 0.05)
    partner: str = "shift"  # shift: their partner, the camera moved along its x axis | path: a pose of the capture
    #   path next to the input (the pseudo views' trajectories), up to reach of the way to a neighbour
    reach: float = 0.5  # path partner: the farthest, as a share of the way to the neighbouring input
    axes: str = "x"  # shift partner: x: along the camera's x axis (theirs) | xy: in a direction of the image plane
    #   drawn each step (up and down too: DTU's test cameras sit in the rows above and below its inputs')

    LIMITS = {"weight": ">= 0", "shift": "(0, 1]", "start": "[0, 1]", "smooth": ">= 0", "partner": "{shift, path}",
              "reach": "(0, 1]", "axes": "{x, xy}"}
    LEGACY = {"binocular": "weight", "binocular_shift": "shift", "binocular_start": "start",  # train.<key> of
              "binocular_smooth": "smooth", "binocular_partner": "partner", "binocular_reach": "reach",  # earlier
              "binocular_axes": "axes"}  # versions


CONFIG = BinocularConfig  # the section regularizers.<name> of the run's config


class Binocular(Regularizer):
    """The term of one trainer (module docstring); ``loss`` adds it for an input render."""

    name = "binocular"

    def __init__(self, weight: float, shift: float, start: int, smooth: float, device, seed: int,
                 path: dict[str, torch.Tensor] | None = None, axes: str = "x"):
        if axes not in ("x", "xy"):
            raise ValueError(f"binocular axes must be x or xy, got {axes!r}")
        self.weight, self.shift, self.start, self.smooth, self.axes = weight, shift, start, smooth, axes
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(int(seed) + 17)
        self.device = device
        # steps whose moved render needed more than a CUDA graph's fixed capacity (``loss``)
        self.overflows = torch.zeros((), dtype=torch.int64, device=device)
        # partner "path": per input view (name), the poses of the capture path next to it
        # (warpgs.strategy.clearance.path_partners); a view without any keeps the shifted partner
        self.path = {k: v.to(device=device, dtype=torch.float32) for k, v in (path or {}).items()}

    def active(self, step: int) -> bool:
        return self.weight > 0 and step >= self.start

    def loss(self, model, out, cam, bg, parts: dict, capacity: int | None = None) -> torch.Tensor:
        """weight x (masked L1 of the warped moved render against ``cam.image`` + smooth x disparity smoothness)
        for the input render ``out`` of ``cam`` (over ``bg``); recorded in ``parts`` as ``binocular``.

        ``capacity``: the moved render's fixed intersection buffers (a step recorded as a CUDA graph,
        ``warpgs.engine.graphstep``; its pose is drawn on the device, so its count cannot be read before the
        step). A render that needed more is cut short: the term sits that step out (0) and ``overflows`` counts it,
        so the next recording makes more room."""
        depth = out.depth
        fx = cam.K[0, 0]
        seen = depth.detach() > MIN_DEPTH
        partners = self.path.get(getattr(cam, "name", None))
        vm = None  # a partner pose moved in any way (warped back by reprojection); None: the sideways shift by t
        if partners is not None:  # a pose of the capture path next to the input (drawn on the device)
            k = torch.randint(len(partners), (1,), device=self.device, generator=self.gen)
            vm = partners.index_select(0, k)[0]  # (no host read of k)
        else:
            zmed = torch.where(seen, depth.detach(), torch.nan).nanmedian().nan_to_num(1.0)
            u = torch.rand(1, device=self.device, generator=self.gen)
            t = (2 * u - 1) * self.shift * cam.width * zmed / fx
            if self.axes == "xy":  # the move by t in a direction of the image plane (drawn on the device)
                a = 2 * torch.pi * torch.rand(1, device=self.device, generator=self.gen)
                vm = cam.viewmat.float().clone()
                vm[:2, 3] = vm[:2, 3] - t * torch.cat([torch.cos(a), torch.sin(a)])
        if vm is not None:
            rel = vm @ rigid_inverse(cam.viewmat.float())
            moved = model.render(vm, cam.K, cam.width, cam.height, background=bg, check_finite=False,
                                 isect_capacity=capacity)
            warped, weight = pose_warp(moved.image, depth, rel, cam.K)
            ft = (fx * rel[:3, 3].norm()).reshape(1)  # the disparity of depth 1, for the smoothness below
        else:
            moved = model.render(moved_viewmat(cam.viewmat, t), cam.K, cam.width, cam.height, background=bg,
                                 check_finite=False, isect_capacity=capacity)
            ft = (fx * t).reshape(1)
            warped, weight = shift_warp(moved.image, depth, ft)
        diff = (warped - cam.image).abs() * weight[..., None]
        term = diff.sum() / (3 * weight.sum() + 1e-6)
        if self.smooth > 0:
            disparity = torch.where(seen, ft.abs() / depth.clamp_min(MIN_DEPTH), torch.zeros_like(depth)) * weight
            term = term + self.smooth * losses.edge_aware_smoothness(disparity, cam.image, normalise=False)
        if moved.needed is not None:  # a fixed-capacity render: one cut short contributes nothing
            over = moved.needed > moved.n_intersections
            self.overflows += over
            term = torch.where(over, term.new_zeros(()), term)
        parts["binocular"] = term.detach()
        return self.weight * term

    # the Regularizer hooks: the term a step adds; in a CUDA graph, its draws come from its registered generator
    # and its render uses the step's fixed capacity
    def step_term(self, ctx, step: int, out, cam, bg, parts: dict) -> torch.Tensor | None:
        return self.loss(ctx.model, out, cam, bg, parts, ctx.isect_capacity) if self.active(step) else None

    def graph_key(self, ctx, step: int):
        return self.active(step)

    def graph_counters(self) -> list[torch.Tensor]:
        return [self.overflows]

    def graph_generators(self) -> list[tuple[object, str]]:
        return [(self, "gen")]

    def state_dict(self) -> dict:
        return {"binocular_gen": self.gen.get_state()}

    def load_state_dict(self, st: dict) -> None:
        if "binocular_gen" in st:
            self.gen.set_state(st["binocular_gen"])


def build(cfg, ctx) -> Binocular | None:
    """``weight`` > 0: the term, from ``start`` x the run on; with ``partner: path`` its partners are poses of the
    capture path next to each input."""
    c, tc = cfg.regularizers.binocular, cfg.train
    if not c.weight > 0:
        return None
    path = ctx.cameras.path_partners(c.reach) if c.partner == "path" else None
    return Binocular(c.weight, c.shift, int(c.start * tc.iterations), c.smooth, ctx.device, tc.seed, path=path,
                     axes=c.axes)
