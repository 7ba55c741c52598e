"""CoR-GS (Zhang et al., ECCV 2024): a co-regularised pair of 3D-GS models (``corgs.pair``,
``--method corgs``; its settings: the section ``corgs``).

Two models are trained side by side, and where they disagree is taken as where neither is right:

- **The pair.** The second model starts from the first one's initial Gaussians and trains on the same
  input view at every step, with the same inputs' loss (``Trainer.input_loss``), its own Adam and
  ``DefaultStrategy`` (the config's ``strategy``), and its own random streams (split noise, dropout), so
  densification makes the two differ. The first model is the one evaluated, exported and compacted;
  the method's own terms and phases (the full method's pseudo views, depth priors and densification from
  them) act on it alone, so with ``--method full`` its partner is a model of the input views.
- **Co-pruning** (CoR-GS Sec. 4.2): every ``corgs.prune_every`` steps after ``strategy.refine_start_iter``
  (right after a densification), a Gaussian of either model with no centre of the other within
  ``corgs.prune_dist`` x the scene scale is removed (``co_prune_masks``: Warp hash-grid radius queries,
  ``warpgs.densify.within_radius``). A model is never emptied.
- **Co-regularisation on pseudo views** (Sec. 4.3): from step ``corgs.start`` on, each step also
  renders both models at a pose between two neighbouring training views (``corgs.frames`` poses
  per pair along the path of ``warpgs.pseudo.trajectory.virtual_cameras``, drawn in a shuffled order; never a test
  view) and adds ``corgs.weight`` x (l1_weight L1 + ssim_weight D-SSIM) of each render against the
  other's detached render to that model's loss (``co_reg_loss``). These renders use no dropout: they
  compare the models as they render at test time.

The trainer adds both models' losses into one backward (the detached targets keep the gradients apart),
steps both optimisers on the divergence guard's one verdict, and checkpoints both (``state_dict``), so a
resumed run continues exactly. The cost: about twice the training before ``co_reg_start``, four renders
a step after it.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from warpgs import losses
from warpgs.config import check_limits
from warpgs.densify import within_radius
from warpgs.model import PARAM_NAMES, GaussianModel
from warpgs.optim import STATE_PARTS, load_model_state, make_optimizer, model_state
from warpgs.pseudo.trajectory import virtual_cameras
from warpgs.strategy.ops import remove

SEED_OFFSETS = {"split": 11, "drop": 12, "views": 13}  # the partner's random streams: train.seed + these


def co_prune_masks(means_a: torch.Tensor, means_b: torch.Tensor, radius: float) -> tuple[torch.Tensor, torch.Tensor]:
    """CoR-GS's co-pruning decision: ([Na], [Nb]) bool, the centres of ``means_a`` [Na, 3] with no centre of
    ``means_b`` [Nb, 3] within ``radius`` (their nearest one is farther), and the other way round. Warp hash-grid
    radius queries on the tensors' device (cpu or cuda); "within" is a squared distance <= radius^2 in float32."""
    if not radius > 0:
        raise ValueError(f"co-pruning radius must be > 0, got {radius}")
    return ~within_radius(means_b, means_a, radius), ~within_radius(means_a, means_b, radius)


def disagreement(image: torch.Tensor, other: torch.Tensor, l1_weight: float = 0.8, ssim_weight: float = 0.2
                 ) -> torch.Tensor:
    """l1_weight L1 + ssim_weight D-SSIM of ``image`` [H, W, 3] against ``other`` detached: the gradient
    reaches ``image``'s model only (CoR-GS's co-regularisation term of one model)."""
    other = other.detach()
    loss = l1_weight * losses.l1(image, other)
    if ssim_weight > 0:
        loss = loss + ssim_weight * losses.dssim(image, other)
    return loss


def co_reg_loss(image_a: torch.Tensor, image_b: torch.Tensor, l1_weight: float = 0.8, ssim_weight: float = 0.2
                ) -> torch.Tensor:
    """Both models' co-regularisation terms of one pseudo view, summed: each render against the other's
    detached render (``disagreement``). Zero when the renders agree; one backward trains both models."""
    return (disagreement(image_a, image_b, l1_weight, ssim_weight)
            + disagreement(image_b, image_a, l1_weight, ssim_weight))


class CoRegPair:
    """The second model of the co-regularised pair, its optimiser, strategy and random streams; the trainer
    calls ``loss`` in each step before the backward and ``after_update`` after the optimisers' step. ``ctx``:
    the trainer's narrow view (``warpgs.engine.context.Context``), its model as initialised."""

    def __init__(self, ctx):
        tc = ctx.cfg.corgs
        check_limits(tc, "CoR-GS's options", "corgs.")
        self.ctx = ctx
        m = ctx.model  # the first model as initialised: the partner starts from the same Gaussians
        self.model = GaussianModel(*(m.params[n].detach() for n in PARAM_NAMES), max_sh_degree=m.max_sh_degree)
        self.strategy = copy.deepcopy(ctx.cfg.strategy)
        self.optimizer = make_optimizer(self.model, ctx.cfg, ctx.scene_scale)
        self.state = self.strategy.initialize_state(len(self.model), ctx.device)
        seed = ctx.cfg.train.seed
        self.split_gen = torch.Generator(device=ctx.device).manual_seed(seed + SEED_OFFSETS["split"])
        self.drop_gen = torch.Generator(device=ctx.device).manual_seed(seed + SEED_OFFSETS["drop"])
        self.views = virtual_cameras(ctx.cameras.train, tc.frames)  # poses between the training views
        self.view_rng = np.random.default_rng(seed + SEED_OFFSETS["views"])
        self.order: list[int] = []
        self.co_pruned: list[dict] = []  # each co-pruning: step, Gaussians removed from each model, counts after
        self._out = None  # the partner's render of this step's view, for its densification statistics
        if not self.views and tc.weight > 0:
            ctx.log("warpgs: corgs.pair: one training view, so no poses between views to co-regularise on; "
                        "the pair is only co-pruned")

    @property
    def settings(self):
        return self.ctx.cfg.corgs

    def next_view(self) -> int:
        if not self.order:
            self.order = self.view_rng.permutation(len(self.views)).tolist()
        return self.order.pop()

    # ------------------------------------------------------------------------------------------
    # a training step

    def loss(self, step: int, cam, background, parts: dict) -> torch.Tensor:
        """What the pair adds to step ``step``'s loss of the first model on the input view ``cam`` (rendered over
        ``background``): the partner's inputs' loss on that view and, from ``start`` on, both models'
        co-regularisation terms on one pseudo view x ``weight``. Their values go into ``parts``
        (``partner``, ``co_reg``)."""
        ctx, s = self.ctx, self.settings
        self.model.active_sh_degree = ctx.model.active_sh_degree
        out = self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=background,
                                opacity_scale=ctx.opacity_scale(step, self.model, self.drop_gen), check_finite=False)
        self._out = out
        loss, own = ctx.input_loss(out, cam)
        parts["partner"] = own["inputs"]
        loss = ctx.parameter_priors(self.model, loss, {})
        if s.weight > 0 and step >= s.start and self.views:
            pc = self.views[self.next_view()]
            bg = ctx.background.for_cam(pc)
            a, b = (model.render(pc.viewmat, pc.K, pc.width, pc.height, background=bg, check_finite=False).image
                    for model in (ctx.model, self.model))
            co = co_reg_loss(a, b, ctx.cfg.loss.l1_weight, ctx.cfg.loss.ssim_weight)
            loss = loss + s.weight * co
            parts["co_reg"] = co
        return loss

    def after_update(self, step: int, cam, apply: torch.Tensor | None = None) -> int:
        """After step ``step``'s update of both models: the partner's densification (``Trainer.densify``; with a
        deferred step's verdict ``apply``, a skipped step counts as one that saw nothing), then the co-pruning
        when it is due. Returns how many Gaussians the co-pruning removed from both models."""
        s = self.settings
        out, self._out = self._out, None
        if apply is not None:
            out = out._replace(radii=out.radii * apply)
        self.ctx.densify(self.strategy, self.model, self.optimizer, self.state, step, out, cam, self.split_gen)
        if s.prune_every and step > self.strategy.refine_start_iter and step % s.prune_every == 0:
            return self.co_prune(step)
        return 0

    def co_prune(self, step: int) -> int:
        """Removes from each model the Gaussians with no centre of the other within ``prune_dist`` x the scene
        scale (``co_prune_masks``, both decided before either is pruned); a model that would lose every Gaussian
        keeps them. Returns how many went, in all."""
        ctx = self.ctx
        radius = self.settings.prune_dist * ctx.scene_scale
        with torch.no_grad():
            drop = co_prune_masks(ctx.model.means.detach(), self.model.means.detach(), radius)
        removed = []
        for (model, optimizer, state), mask in zip(((ctx.model, ctx.optimizer, ctx.state),
                                                     (self.model, self.optimizer, self.state)), drop):
            n = int(mask.sum())
            if n == len(model):  # nothing of it is near the other: keep it rather than empty it
                n = 0
            elif n:
                remove(model, optimizer, state, mask)
            removed.append(n)
        self.co_pruned.append({"step": step, "removed": removed[0], "partner_removed": removed[1],
                               "num_gaussians": len(ctx.model), "partner_gaussians": len(self.model)})
        if any(removed):
            ctx.log(f"warpgs: step {step}: co-pruning removed {removed[0]} Gaussians of the model and {removed[1]} of "
                   f"its partner (no counterpart within {radius:.3g}); {len(ctx.model)} and {len(self.model)} left")
        return sum(removed)

    # ------------------------------------------------------------------------------------------
    # the partner's share of the training state, and its record

    def state_dict(self, parts=STATE_PARTS, device="cpu") -> dict:
        """``model``: the partner's parameters, Adam's moments and densification statistics (on ``device``);
        ``progress``: its random streams and pseudo-view order; ``history``: the co-pruning record."""
        st: dict = {}
        if "model" in parts:
            st.update(model_state(self.model, self.optimizer, self.state, device))
        if "progress" in parts:
            st.update(split_gen=self.split_gen.get_state(), drop_gen=self.drop_gen.get_state(),
                      view_rng=copy.deepcopy(self.view_rng.bit_generator.state), order=list(self.order))
        if "history" in parts:
            st["co_pruned"] = copy.deepcopy(self.co_pruned)
        return st

    def load_state_dict(self, st: dict | None, parts=STATE_PARTS) -> None:
        """Puts back the ``parts`` of the partner's state ``st`` (copies: ``st`` stays usable); ``ValueError``
        when ``st`` is None (a state written without the pair)."""
        if st is None:
            raise ValueError("it holds no second model of the co-regularised pair (it was written with "
                             "corgs.pair off; resume it with --set corgs.pair=false)")
        ctx = self.ctx
        if "model" in parts:
            self.optimizer, self.state = load_model_state(st, self.model, ctx.cfg, ctx.scene_scale, ctx.device)
        if "progress" in parts:
            self.split_gen.set_state(st["split_gen"])
            self.drop_gen.set_state(st["drop_gen"])
            self.view_rng.bit_generator.state = copy.deepcopy(st["view_rng"])
            self.order = list(st["order"])
        if "history" in parts:
            self.co_pruned = copy.deepcopy(st["co_pruned"])

    def report(self) -> dict:
        """metrics.json's ``co_reg``: the settings, the co-pruning record, the partner's size and its PSNR and
        SSIM on the test views (for comparison only: the first model is the run's result)."""
        ctx, s = self.ctx, self.settings
        rec = {"co_prune_every": s.prune_every, "co_prune_dist": s.prune_dist,
               "co_prune_radius": s.prune_dist * ctx.scene_scale, "co_reg_weight": s.weight,
               "co_reg_start": s.start, "pseudo_views": len(self.views),
               "partner_gaussians": len(self.model), "co_pruned": copy.deepcopy(self.co_pruned)}
        if ctx.cameras.test:
            def render(cam):
                bg = ctx.background.for_cam(cam)
                return self.model.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg)

            ev = ctx.evaluate(lpips=False, render=render)["mean"]
            rec.update(partner_psnr=ev["psnr"], partner_ssim=ev["ssim"])
        return rec


__all__ = ["CoRegPair", "co_prune_masks", "co_reg_loss", "disagreement"]
