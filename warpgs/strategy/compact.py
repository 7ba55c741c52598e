"""Compact mode (``compact.enabled``, ``--compact``): the fewest Gaussians and the lowest SH degree a scene needs.

Three parts, in the spirit of LightGaussian (global significance pruning, SH distillation) and
Mini-Splatting (pruning by blending weight):

1. **Importance.** A Gaussian's importance is its total blending weight ``sum_pixels alpha_i T_i`` over
   the importance views (``warpgs.strategy.ops.contribution``: the training views, optionally poses
   interpolated between them and, for the full method, its pseudo views), optionally multiplied by its
   volume ``prod(scales) ** volume_power`` (LightGaussian's global significance; ``importance:
   weight_volume``). A Gaussian that covers no pixel of any of those views has importance 0.
2. **Pruning during training.** At the fractions ``prune_at`` of ``train.iterations`` the share
   ``prune_ratio`` of Gaussians with the lowest importance goes, and training goes on so that the rest
   compensate. ``cap_after_prune`` keeps densification from growing the count back above what each
   pruning left (it can still move Gaussians: the budget's compaction frees room), and
   ``stop_densify_at`` stops densification altogether. This runs inside the trainer's densification step (``ScheduledPruning`` wraps the strategy),
   so it works for the baseline and the full method alike and survives checkpoints.
3. **The search, in the run's last ``finetune_steps`` steps** (``Trainer.finish``; the trainer stops
   that many steps early, so the kept model has had ``train.iterations`` steps like a default run).
   Every point of the search starts from the trained model, removes the share ``ratio`` of the least important Gaussians, keeps the SH
   coefficients up to a degree, and is fine-tuned for ``finetune_steps`` steps of the run's own training
   (its loss and regularisers, no densification); the unpruned model at its full degree gets the same fine-tune and is the
   reference. Ratios are searched by bisection over ``ratios`` (quality is assumed to fall as the
   ratio rises) and the smallest model whose training-view PSNR is within ``tolerance_db`` of the best
   evaluated point is kept. Then the SH degree at that count: from 0 upwards, the first degree whose
   point is still within ``tolerance_db`` of the same best is kept (a degree at or above the one the
   model was rendered at during training costs nothing and needs no fine-tune). So the final model as a
   whole stays within the tolerance of the best point, every point having had the same extra steps.
   The kept model stores only the coefficients of its degree, so the PLY and the byte counts shrink.

**Only the training views judge.** The choice never looks at the test views; with ``report_test`` the
test PSNR of each point of the search is recorded for the report (metrics.json, bench/quality/compact.py's
chart), after the fact, and is not used. On sparse views the training-view PSNR is an imperfect
proxy for novel views: pruning what the inputs barely see can lose (or gain) test PSNR that the
training views cannot show; ``importance_views: [train, virtual]`` also counts what poses between the
inputs see (on the synthetic room it did not help). Where the training views are fitted very closely
(lego: 40.8 dB) little further pruning stays within 0.1 dB there and a lower SH degree costs more, so
most of the reduction comes from the pruning during training (lego, 15k-Gaussian hull start: 82.7K ->
41.0K by pruning, 36.9K after the search's 10%, test PSNR +0.35 dB; README).

Sizes (``size_report``): ``param_bytes`` = float32 parameters at the kept SH degree, per Gaussian
``(3 + 4 + 3 + 1 + 3 (d + 1)^2) x 4`` bytes (236 at degree 3, 56 at degree 0); ``ply_bytes`` = the
size of the 3D-GS PLY that ``GaussianModel.save_ply`` writes (it also stores three unused normals).
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from warpgs.engine.stage import Stage
from warpgs.model import GaussianModel, num_sh_coeffs, param_bytes, ply_bytes, size_report  # sizes: re-exported
from warpgs.pseudo.trajectory import virtual_cameras  # noqa: F401  (re-exported: compact mode's "virtual" views)
from warpgs.strategy.config import CompactConfig, check_compact_config as check_config
from warpgs.strategy.ops import contribution, remove, update_params

# ----------------------------------------------------------------------------------------------
# importance and pruning


def importance_cameras(ctx, cfg: CompactConfig) -> list:
    """The views of ``cfg.importance_views`` (``ctx``: the trainer's narrow view, ``warpgs.engine.context``)."""
    cams = []
    if "train" in cfg.importance_views:
        cams += list(ctx.cameras.train)
    if "virtual" in cfg.importance_views:
        cams += virtual_cameras(ctx.cameras.train, cfg.virtual_frames)
    if "pseudo" in cfg.importance_views:
        cams += list(ctx.extra_views())
    return cams


def importance(model: GaussianModel, cameras, background=None, kind: str = "weight",
               volume_power: float = 0.1) -> torch.Tensor:
    """Per-Gaussian importance [N]: total blending weight over ``cameras`` (x volume^volume_power for
    ``weight_volume``)."""
    w = contribution(model, cameras, background)
    if kind == "weight_volume":
        with torch.no_grad():
            vol = model.scales.detach().prod(dim=-1)
            w = w * (vol / vol.max().clamp_min(1e-30)).clamp_min(0) ** volume_power
    elif kind != "weight":
        raise ValueError(f"importance kind {kind!r}: expected weight or weight_volume")
    return w


def lowest_mask(scores: torch.Tensor, ratio: float) -> torch.Tensor:
    """Mask of the ``round(ratio N)`` lowest scores (ties: the lower index goes first); at least one stays."""
    n = scores.shape[0]
    k = min(int(round(ratio * n)), max(n - 1, 0))
    mask = torch.zeros(n, dtype=torch.bool, device=scores.device)
    if k > 0:
        mask[torch.argsort(scores, stable=True)[:k]] = True
    return mask


def prune_lowest(model, optimizer, state, scores: torch.Tensor, ratio: float) -> int:
    """Removes the ``ratio`` share of Gaussians with the lowest ``scores`` (with their Adam moments and
    strategy statistics); returns how many went."""
    mask = lowest_mask(scores, ratio)
    k = int(mask.sum())
    if k:
        remove(model, optimizer, state if state is not None else {}, mask)
    return k


def truncate_sh(model: GaussianModel, degree: int, optimizer=None) -> GaussianModel:
    """Keeps only the SH coefficients of ``degree`` (in place, with the Adam moments): the model then
    renders, and saves, exactly as the full model rendered at ``sh_degree=degree``."""
    if not 0 <= degree <= model.max_sh_degree:
        raise ValueError(f"truncate_sh: degree {degree} outside 0..{model.max_sh_degree}")
    k = num_sh_coeffs(degree) - 1
    update_params(model, optimizer, lambda n, p: p[:, :k].contiguous(), lambda key, v: v[:, :k].contiguous(), names=["shN"])
    model.max_sh_degree = degree
    model.active_sh_degree = min(model.active_sh_degree, degree)
    return model


# ----------------------------------------------------------------------------------------------
# pruning during training


class ScheduledPruning:
    """The trainer's strategy plus importance pruning at scheduled steps. Every other attribute is the
    wrapped strategy's (``Trainer.train_step`` reads ``prune_unseen_when_full`` etc. through it). It wraps a
    copy, so the run's config is untouched. With ``cap_after_prune`` the count after each pruning becomes
    the copy's ``max_gaussians``: densification can still move Gaussians to where the views need them
    (the budget's compaction frees room), but cannot grow back what was pruned."""

    def __init__(self, base, ctx, cfg: CompactConfig):
        self.base, self.ctx, self.compact_cfg = copy.copy(base), ctx, cfg
        self.budget = base.max_gaussians  # the configured one (0: none)
        self.cap: int | None = None
        total = ctx.total_steps
        self.prune_steps = sorted({int(round(f * total)) for f in cfg.prune_at} - {0}) if cfg.prune_ratio > 0 else []
        self.stop_step = int(round(cfg.stop_densify_at * total)) if cfg.stop_densify_at is not None else None
        self.log: list[dict] = []

    def __getattr__(self, name):
        return getattr(self.__dict__["base"], name)

    def step_post_backward(self, model, optimizer, state, step, out, width, height, scene_scale, generator=None):
        c = self.compact_cfg
        if c.cap_after_prune and self.cap is None and self.prune_steps and step >= self.prune_steps[0]:
            self.set_cap(len(model))  # resumed after a pruning: the count now is within the lost cap
        if self.stop_step is not None and step >= self.stop_step:  # densification (and opacity resets) over
            info = {"cloned": 0, "split": 0, "pruned": 0, "reset": 0}
        else:
            info = self.base.step_post_backward(model, optimizer, state, step, out, width, height, scene_scale,
                                                generator=generator)
        if step + 1 in self.prune_steps:  # after step + 1 steps
            ctx = self.ctx
            scores = importance(model, importance_cameras(ctx, c), ctx.background.colour, c.importance, c.volume_power)
            n0 = len(model)
            k = prune_lowest(model, optimizer, state, scores, c.prune_ratio)
            info["pruned"] = info.get("pruned", 0) + k
            self.log.append({"step": step + 1, "before": n0, "after": len(model)})
            if c.cap_after_prune:
                self.set_cap(len(model))
            ctx.log(f"warpgs: compact: step {step + 1}: pruned {k} of {n0} Gaussians by importance"
                   + (f"; at most {self.base.max_gaussians} from now on" if c.cap_after_prune else ""))
        return info

    def set_cap(self, n: int) -> None:
        """At most ``n`` Gaussians from now on (and at most the configured budget)."""
        self.cap = n
        self.base.max_gaussians = n if self.budget <= 0 else min(self.budget, n)


class CompactStage(Stage):
    """Compact mode as a stage of the run (``warpgs.engine.stage.Stage``, ``Trainer.add_stage``): the steps
    reserved for the search's fine-tunes, the pruning schedule around the strategy, and the search before the
    test metrics (its record: metrics.json's ``compact``)."""

    name = "compact"

    def __init__(self, cfg: CompactConfig):
        self.cfg = check_config(cfg)

    def reserve_steps(self, iterations: int) -> int:
        c = self.cfg
        if (c.ratios or c.sh_search) and c.finetune_steps > 0:
            # the search's fine-tunes are the run's last steps, so the kept model has had train.iterations
            # steps, as the default run has (fairer than extra steps: on sparse views more steps overfit)
            return min(c.finetune_steps, iterations // 2)
        return 0

    def wrap_strategy(self, strategy, ctx):
        c = self.cfg
        if ((c.prune_at and c.prune_ratio > 0) or c.stop_densify_at is not None) \
                and not isinstance(strategy, ScheduledPruning):
            return ScheduledPruning(strategy, ctx, c)
        return strategy

    def before_evaluation(self, ctx) -> dict:
        c = self.cfg
        if not c.ratios and not c.sh_search:
            return {"before": size_report(ctx.model), "points": []}
        report = search(ctx, c)
        report["trained_steps_before_search"] = ctx.step  # the trainer counts the reserved steps next
        self.size_before = report["before"]["num_gaussians"]
        return report


def attach(trainer) -> None:
    """Compact mode on a freshly built trainer (before training or resuming: ``Trainer.add_stage``). Nothing
    when ``compact.enabled`` is off."""
    if trainer.cfg.compact.enabled:
        trainer.add_stage(CompactStage(trainer.cfg.compact))


# ----------------------------------------------------------------------------------------------
# the search


def finetune(ctx, steps: int, seed: int = 0) -> int:
    """``steps`` steps of the run's own training on the training views, without densification: the trainer's
    loss (``compute_loss``, so the full method's pseudo views too), the regularisers as they act at the steps the
    fine-tune stands in for (``ctx.step`` on: DropGaussian's mask, the binocular term, the opacity decay; without
    them a 3-view capture's fine-tune overfits its inputs and loses 0.1-0.25 dB of test PSNR), learning rates as at
    the end of training. The view order, random backgrounds and every random draw come from ``seed``, so every
    candidate sees the same sequence. Returns the number of steps skipped for a non-finite loss or gradient."""
    from warpgs.engine.stepguard import all_finite as _all_finite

    if steps <= 0:
        return 0
    model, opt = ctx.model, ctx.optimizer
    for g in opt.param_groups:
        if g.get("name") == "means":
            g["lr"] = ctx.means_lr(ctx.total_steps)
    rng = np.random.default_rng(seed)
    gen = torch.Generator(device=ctx.device).manual_seed(seed)
    own = ctx.regularizer_generators()  # replaced by seeded ones for the fine-tune, then put back
    saved = [getattr(holder, name) for holder, name in own]
    for i, (holder, name) in enumerate(own):
        setattr(holder, name, torch.Generator(device=ctx.device).manual_seed(seed + 1 + i))
    order: list[int] = []
    skipped = 0
    first = ctx.step
    try:
        for i in range(steps):
            step = first + i
            if not order:
                order = rng.permutation(len(ctx.cameras.train)).tolist()
            cam, bg = ctx.background.for_training(ctx.cameras.train[order.pop()], gen)
            out = model.render(cam.viewmat, cam.K, cam.width, cam.height, background=bg,
                               opacity_scale=ctx.opacity_scale(step, generator=gen))
            loss, parts = ctx.compute_loss(out, cam)
            loss = ctx.step_terms(step, out, cam, bg, loss, parts)
            loss.backward()
            if _all_finite([loss.detach()] + [p.grad for p in model.params.values()]):
                opt.step()
                ctx.after_regularized_update(step)
            else:
                skipped += 1
            opt.zero_grad(set_to_none=True)
    finally:
        for (holder, name), g in zip(own, saved):
            setattr(holder, name, g)
    return skipped


def _psnr(ctx, cams) -> float:
    return float(ctx.evaluate(cams, lpips=False)["mean"]["psnr"])


def search(ctx, cfg: CompactConfig | None = None) -> dict:
    """The search after training (see the module docstring). Leaves the trainer holding the chosen model
    (with its optimizer state) and returns the report that goes into metrics.json under ``compact``."""
    import time

    cfg = check_config(cfg if cfg is not None else ctx.cfg.compact)
    t0 = time.perf_counter()
    model = ctx.model
    test = cfg.report_test and bool(ctx.cameras.test)
    before = {**size_report(model), "train_psnr": _psnr(ctx, ctx.cameras.train)}
    if test:
        before["test_psnr"] = _psnr(ctx, ctx.cameras.test)
    start = ctx.state_dict(("model",))
    steps = ctx.reserved_steps or cfg.finetune_steps  # compact mode reserved the run's last steps for them
    cams = importance_cameras(ctx, cfg)
    scores = importance(model, cams, ctx.background.colour, cfg.importance, cfg.volume_power).to(ctx.device)
    points: list[dict] = []
    kept: dict[int, dict] = {}  # point index -> snapshot (on the CPU)

    def run_point(kind: str, ratio: float, degree: int) -> dict:
        """One point: from the trained model, prune ``ratio``, truncate to ``degree``, fine-tune, measure."""
        ctx.load_state_dict(start)
        if ratio > 0:
            prune_lowest(ctx.model, ctx.optimizer, ctx.state, scores, ratio)
        if degree < ctx.model.max_sh_degree:
            truncate_sh(ctx.model, degree, ctx.optimizer)
        skipped = finetune(ctx, steps, seed=cfg.seed + ctx.cfg.train.seed)
        row = {"kind": kind, "ratio": ratio, **size_report(ctx.model),
               "train_psnr": _psnr(ctx, ctx.cameras.train), "finetune_steps": steps}
        if skipped:
            row["skipped_steps"] = skipped
        if test:
            row["test_psnr"] = _psnr(ctx, ctx.cameras.test)
        kept[len(points)] = ctx.state_dict(("model",))
        points.append(row)
        ctx.log(f"warpgs: compact: {kind} ratio {ratio:.2f} degree {row['sh_degree']}: {row['num_gaussians']} "
                    f"Gaussians, train PSNR {row['train_psnr']:.3f}"
                    + (f", test PSNR {row['test_psnr']:.3f} (reported only)" if test else ""))
        return row

    def best() -> float:
        return max(p["train_psnr"] for p in points)

    def ok(row) -> bool:
        return row["train_psnr"] >= best() - cfg.tolerance_db

    # 1. the count: the unpruned reference, then bisection over the ratios, all at the full degree
    max_deg = model.max_sh_degree
    run_point("prune", 0.0, max_deg)
    ratios = sorted(float(r) for r in cfg.ratios)
    lo, hi = -1, len(ratios)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ok(run_point("prune", ratios[mid], max_deg)):
            lo = mid
        else:
            hi = mid
    chosen = min((i for i, p in enumerate(points) if ok(p)),
                 key=lambda i: (points[i]["num_gaussians"], -points[i]["train_psnr"]))
    # 2. the SH degree at that count, lowest first, within the same tolerance of the best PSNR (each point
    # is pruned, truncated and fine-tuned from the trained model alike, so all had the same extra steps)
    if cfg.sh_search and max_deg > 0:
        ratio = points[chosen]["ratio"]
        active = start["active_sh_degree"]
        for d in range(max_deg):
            if d >= active:  # the model never rendered above ``active``: dropping the rest changes nothing
                ctx.load_state_dict(kept[chosen])
                truncate_sh(ctx.model, d, ctx.optimizer)
                kept[len(points)] = ctx.state_dict(("model",))
                points.append({**points[chosen], "kind": "sh", **size_report(ctx.model),
                               "note": f"the active SH degree was {active}: same model, fewer stored coefficients"})
                chosen = len(points) - 1
                break
            if ok(run_point("sh", ratio, d)):
                chosen = len(points) - 1
                break
    chosen = min((i for i, p in enumerate(points) if ok(p) and p["num_gaussians"] == points[chosen]["num_gaussians"]),
                 key=lambda i: (points[i]["param_bytes"], -points[i]["train_psnr"]))
    ctx.load_state_dict(kept[chosen])
    for p in points:
        p["within_tolerance"] = ok(p)
    final = points[chosen]
    report = {
        "tolerance_db": cfg.tolerance_db,
        "judged_on": "train views",
        "best_train_psnr": best(),
        "importance": cfg.importance,
        "importance_views": list(cfg.importance_views),
        "num_importance_views": len(cams),
        "before": before,
        "after": {k: final[k] for k in ("num_gaussians", "sh_degree", "param_bytes", "ply_bytes", "train_psnr")
                  if k in final} | ({"test_psnr": final["test_psnr"]} if "test_psnr" in final else {}),
        "chosen": chosen,
        "reduction": 1.0 - final["num_gaussians"] / max(before["num_gaussians"], 1),
        "bytes_reduction": 1.0 - final["param_bytes"] / max(before["param_bytes"], 1),
        "points": points,
        "search_time_s": round(time.perf_counter() - t0, 2),
    }
    if isinstance(ctx.strategy, ScheduledPruning):
        report["pruned_during_training"] = ctx.strategy.log
    ctx.log(f"warpgs: compact: kept {final['num_gaussians']} of {before['num_gaussians']} Gaussians at SH degree "
                f"{final['sh_degree']} ({final['param_bytes'] / 2**20:.2f} MiB of parameters), train PSNR "
                f"{final['train_psnr']:.3f} (best {best():.3f}, tolerance {cfg.tolerance_db} dB)")
    return report


__all__ = ["CompactConfig", "CompactStage", "ScheduledPruning", "attach", "check_config", "finetune", "importance",
           "importance_cameras", "lowest_mask", "param_bytes", "ply_bytes", "prune_lowest", "search", "size_report", "truncate_sh",
           "virtual_cameras"]
