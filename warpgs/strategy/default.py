"""Densification and pruning: gsplat's DefaultStrategy (the 3D-GS rules), with a Gaussian budget and the pruning of unseen Gaussians.

Every ``refine_every`` steps between ``refine_start_iter`` and ``refine_stop_iter``:

- grow: Gaussians whose mean 2D positional gradient (in normalised device units, gsplat's statistic:
  ``warpgs.render.means2d_grad_norm``) exceeds ``grow_grad2d`` are cloned when small
  (max scale <= ``grow_scale3d`` x scene scale) and split in two when large (new means sampled from the
  Gaussian, scales / 1.6);
- prune: opacity < ``prune_opa``, and after the first opacity reset, max scale > ``prune_scale3d`` x scene scale;
- every ``reset_every`` steps opacities are clamped to 2 x ``prune_opa`` (``reset_opacity``).

``max_gaussians`` caps the count: when growth would pass it, only the candidates with the largest
gradients grow. ``prune_unseen`` removes what the training views do not need: Gaussians whose total
blending weight over all training views is below ``unseen_min_weight`` pixels, and transparent ones.
The trainer does so whenever a refinement finds the budget spent (``prune_unseen_when_full``), so growth
goes on where the views need it, and optionally once more at the end (``prune_unseen_at_end``).
(Compact mode, ``warpgs/strategy/compact.py``, is something else: importance pruning and a size search.)
Note that in sparse-view training the Gaussians no input view sees still fill the novel views: dropping them at
the end lowered test PSNR by 0.4 dB on the synthetic scene, so the final pruning is off by default.

New Gaussians get zeroed Adam moments, as in gsplat (the operations: ``warpgs.strategy.ops``). The
strategy's running state (gradient sums and counts) is a plain dict of tensors, saved in checkpoints.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warpgs.model import GaussianModel
from warpgs.render import RenderOutput, means2d_grad_norm
from warpgs.strategy.ops import contribution, duplicate, remove, reset_opacities, split


@dataclass
class DefaultStrategy:
    prune_opa: float = 0.005  # prune below this opacity
    grow_grad2d: float = 0.0002  # grow above this mean 2D gradient (normalised device units)
    grow_scale3d: float = 0.01  # clone below / split above this max scale (x scene scale)
    grow_scale2d: float = 0.05  # split above this screen radius (fraction of the image), if refine_scale2d_stop_iter > 0
    prune_scale3d: float = 0.1  # prune above this max scale (x scene scale), after the first reset
    prune_scale2d: float = 0.15  # prune above this screen radius (fraction), if refine_scale2d_stop_iter > 0
    refine_scale2d_stop_iter: int = 0  # 0 = no screen-size rules (gsplat's default)
    refine_start_iter: int = 500
    refine_stop_iter: int = 15_000
    refine_stop_fraction: float = 0.0  # > 0: growth, pruning and the opacity resets also stop at this fraction of the
    #   run (train.iterations) when that comes first (3D-GS: 15,000 of 30,000 steps, 0.5); 0: refine_stop_iter alone.
    #   Resolved into refine_stop_iter by the trainer (warpgs.engine.init.growth_schedule)
    reset_every: int = 3000
    reset_opacity: bool = True  # clamp the opacities every reset_every steps (3D-GS); False: no reset, the pruning of
    #   the too large after reset_every kept (what gsplat 1.5.3's DefaultStrategy does: its test
    #   `step % reset_every == 0 & step > 0` parses as a chained comparison ending in `0 > 0`, never true)
    refine_every: int = 100
    pause_refine_after_reset: int = 0
    max_gaussians: int = 0  # 0 = no budget
    prune_unseen_when_full: bool = True  # prune_unseen when a refinement finds the budget spent
    unseen_min_weight: float = 0.05  # prune_unseen keeps Gaussians with at least this total weight (pixels)
    prune_unseen_at_end: bool = False  # prune_unseen before the final evaluation, with the training views (the
    #   captures' default: a Gaussian no input sees can only stand in front of a novel view; on scenes whose test
    #   views see what the inputs do not, it can cost novel-view PSNR)
    verbose: bool = False

    LIMITS = {"prune_opa": "[0, 1]", "grow_grad2d": ">= 0", "grow_scale3d": ">= 0", "grow_scale2d": ">= 0",
              "prune_scale3d": ">= 0", "prune_scale2d": ">= 0", "refine_scale2d_stop_iter": ">= 0",
              "refine_start_iter": ">= 0", "refine_stop_iter": ">= 0", "refine_stop_fraction": "[0, 1]",
              "reset_every": ">= 1", "refine_every": ">= 1",
              "pause_refine_after_reset": ">= 0", "max_gaussians": ">= 0", "unseen_min_weight": ">= 0"}
    LEGACY = {"prune_unseen_at_end": "prune_unseen_at_end"}  # train.<key> of earlier versions (warpgs.config.MOVED)

    # ------------------------------------------------------------------------------------------

    def initialize_state(self, n: int, device) -> dict[str, torch.Tensor]:
        return {
            "grad2d": torch.zeros(n, device=device),
            "count": torch.zeros(n, device=device),
            "radii": torch.zeros(n, device=device),
        }

    def step_post_backward(self, model: GaussianModel, optimizer: torch.optim.Optimizer, state: dict,
                           step: int, out: RenderOutput, width: int, height: int, scene_scale: float,
                           generator: torch.Generator | None = None) -> dict[str, int]:
        """Call after ``loss.backward()`` (gsplat calls it after the optimiser step; the means2d
        gradient is unaffected). Returns what changed: ``{"cloned", "split", "pruned", "reset"}``."""
        info = {"cloned": 0, "split": 0, "pruned": 0, "reset": 0}
        if step >= self.refine_stop_iter:
            return info
        self.update_state(state, out, width, height)
        if (step > self.refine_start_iter and step % self.refine_every == 0
                and step % self.reset_every >= self.pause_refine_after_reset):
            info["cloned"], info["split"] = self.grow(model, optimizer, state, step, scene_scale, generator)
            info["pruned"] = self.prune(model, optimizer, state, step, scene_scale)
            for v in state.values():
                v.zero_()
        if self.reset_opacity and step % self.reset_every == 0 and step > 0:
            reset_opacities(model, optimizer, self.prune_opa * 2.0)
            info["reset"] = 1
        return info

    def only_updates_state(self, step: int) -> bool:
        """Whether ``step_post_backward`` at ``step`` does no more than ``update_state`` (no growth, pruning or
        opacity reset; nothing at all past ``refine_stop_iter``): such a step can be part of a CUDA graph."""
        if step >= self.refine_stop_iter:
            return True
        refine = (step > self.refine_start_iter and step % self.refine_every == 0
                  and step % self.reset_every >= self.pause_refine_after_reset)
        return not refine and not (self.reset_opacity and step % self.reset_every == 0 and step > 0)

    def update_state(self, state: dict, out: RenderOutput, width: int, height: int) -> None:
        grads = means2d_grad_norm(out, width, height)
        sel = (out.radii > 0).all(dim=-1)  # visible in this view
        state["grad2d"] += torch.where(sel, grads, torch.zeros_like(grads))  # no index lists: no device sync
        state["count"] += sel.float()
        if self.refine_scale2d_stop_iter > 0:
            r = out.radii.max(dim=-1).values.float() / float(max(width, height))
            # in place: the statistics stay where they are (a CUDA graph of the step writes them there)
            state["radii"].copy_(torch.where(sel, torch.maximum(state["radii"], r), state["radii"]))

    def grow(self, model, optimizer, state, step, scene_scale, generator=None) -> tuple[int, int]:
        grads = state["grad2d"] / state["count"].clamp_min(1)
        is_grad_high = grads > self.grow_grad2d
        is_small = model.scales.max(dim=-1).values <= self.grow_scale3d * scene_scale
        is_dupli = is_grad_high & is_small
        is_split = is_grad_high & ~is_small
        if step < self.refine_scale2d_stop_iter:
            is_split |= state["radii"] > self.grow_scale2d
        if self.max_gaussians > 0:  # keep the candidates with the largest gradients within the budget
            room = max(0, self.max_gaussians - len(model))
            cand = torch.where(is_dupli | is_split)[0]
            if cand.numel() > room:
                keep = cand[torch.argsort(grads[cand], descending=True, stable=True)[:room]]
                allowed = torch.zeros_like(is_dupli)
                allowed[keep] = True
                is_dupli &= allowed
                is_split &= allowed
        n_dupli, n_split = int(is_dupli.sum()), int(is_split.sum())
        if n_dupli:
            duplicate(model, optimizer, state, is_dupli)
        if n_split:
            split(model, optimizer, state, torch.cat([is_split, torch.zeros(n_dupli, dtype=torch.bool,
                                                                            device=is_split.device)]), generator)
        if self.verbose:
            print(f"step {step}: {n_dupli} cloned, {n_split} split, now {len(model)}")
        return n_dupli, n_split

    def prune(self, model, optimizer, state, step, scene_scale) -> int:
        is_prune = model.opacities < self.prune_opa
        if step > self.reset_every:
            is_too_big = model.scales.max(dim=-1).values > self.prune_scale3d * scene_scale
            if step < self.refine_scale2d_stop_iter:
                is_too_big |= state["radii"] > self.prune_scale2d
            is_prune |= is_too_big
        n = int(is_prune.sum())
        if n:
            remove(model, optimizer, state, is_prune)
        return n

    def prune_unseen(self, model, optimizer, state, cameras, background=None) -> int:
        """Removes Gaussians that add less than ``unseen_min_weight`` pixels of blending weight to all
        ``cameras`` together, and those below ``prune_opa``. Returns how many went."""
        weight = contribution(model, cameras, background)
        drop = (weight < self.unseen_min_weight) | (model.opacities.detach() < self.prune_opa)
        n = int(drop.sum())
        if n == 0 or n == len(model):  # nothing to drop, or nothing would be left: keep everything
            return 0
        remove(model, optimizer, state, drop)
        return n
