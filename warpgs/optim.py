"""The optimiser side of training, shared by the trainer (warpgs/engine) and the co-regularised pair's second
model (warpgs/coreg.py): Adam with each parameter group's learning rate, its implementation per device (fused on
CUDA), a step applied or skipped on the device without a host read, and one model's training state (parameters,
Adam's moments, densification statistics) copied to the CPU and back, as checkpoints and rollback snapshots
keep it. ``warpgs.train`` re-exports the names scripts imported from it."""

from __future__ import annotations

import copy

import torch

from warpgs.config import Config
from warpgs.guard import inf_norms
from warpgs.model import GaussianModel

STATE_PARTS = ("model", "progress", "history")  # what a checkpoint holds; a rollback snapshot takes them all


def base_learning_rates(cfg: Config, scene_scale: float) -> dict[str, float]:
    """Each parameter group's learning rate at the start (the means' then decays; see ``Trainer.means_lr``)."""
    o = cfg.optim
    return {"means": o.means_lr * scene_scale, "quats": o.quats_lr, "scales": o.scales_lr,
            "opacities": o.opacities_lr, "sh0": o.sh0_lr, "shN": o.shN_lr}


def make_optimizer(model: GaussianModel, cfg: Config, scene_scale: float) -> torch.optim.Adam:
    """Adam, one group per parameter, with ``adam_options`` for the model's device (``GroupedAdam``)."""
    o = cfg.optim
    lrs = base_learning_rates(cfg, scene_scale)
    groups = [{"params": [model.params[k]], "lr": lrs[k], "name": k} for k in model.params.keys()]
    return GroupedAdam(groups, eps=o.eps, **adam_options(model.device))


class GroupedAdam(torch.optim.Adam):
    """torch's Adam, whose fused step (all groups ``fused``) does the same arithmetic with less host work.

    torch's ``Adam.step`` runs, for every parameter group, its state set-up, a regrouping of the tensors by
    device and dtype, and three launches (step count + 1, the fused update, and with ``found_inf`` the count
    back); with one group per parameter that is six times per training step, and on CUDA, where a step is
    bound by the host, it is time the GPU waits. Here the step counts of all groups move in one launch each
    way and each group's update is the same ``torch._fused_adam_`` call: identical results (tests check it
    bit for bit), about a third of the host time. Anything else (a non-fused group, amsgrad, maximize,
    weight decay, a tensor learning rate, a group mixing devices or dtypes, a parameter without state yet, a
    closure, a ``grad_scale``) takes torch's own step. A ``found_inf`` attribute skips the update on the
    device, as torch's GradScaler and ``masked_step`` set it. ``set_lr`` keeps a group's rate on the device too
    (``lr_tensors``), and the fused update reads it there."""

    def __init__(self, params, **kwargs):
        super().__init__(params, **kwargs)
        self.lr_tensors: dict[str, torch.Tensor] = {}  # by group name: a learning rate read on the device

    def set_lr(self, name: str, value: float) -> None:
        """Group ``name``'s learning rate, also kept on the device where the fused step runs (float32, the
        precision fused Adam reads a tensor learning rate in): a CUDA graph of the step then reads each step's
        rate (``warpgs.engine.graphstep``), and a step outside the graph uses the same rounded value."""
        for g in self.param_groups:
            if g.get("name") == name:
                g["lr"] = value
                if g.get("fused") and g["params"] and g["params"][0].device.type == "cuda":
                    t = self.lr_tensors.get(name)
                    if t is None:
                        t = self.lr_tensors[name] = torch.empty((), dtype=torch.float32, device=g["params"][0].device)
                    t.fill_(value)

    def step(self, closure=None):
        work = self._fused_work() if closure is None and getattr(self, "grad_scale", None) is None else None
        if work is None:
            return super().step(closure)
        found_inf = getattr(self, "found_inf", None)
        steps = [s for *_, ss in work for s in ss]
        if not steps:
            return None
        torch._foreach_add_(steps, 1)
        for g, ps, gs, ms, vs, ss in work:
            b1, b2 = g["betas"]
            lr = self.lr_tensors.get(g.get("name"), g["lr"])
            torch._fused_adam_(ps, gs, ms, vs, [], ss, amsgrad=False, lr=lr, beta1=b1, beta2=b2,
                               weight_decay=0.0, eps=g["eps"], maximize=False, grad_scale=None,
                               found_inf=found_inf)
        if found_inf is not None:
            torch._foreach_sub_(steps, [found_inf] * len(steps))
        return None

    def _fused_work(self):
        """Per group with gradients: (group, params, grads, exp_avgs, exp_avg_sqs, steps); None where torch's step
        must run instead."""
        work = []
        for g in self.param_groups:
            if (not g.get("fused") or g["amsgrad"] or g["maximize"] or g["weight_decay"] or g["capturable"]
                    or g["differentiable"] or g.get("decoupled_weight_decay") or isinstance(g["lr"], torch.Tensor)):
                return None
            ps, gs, ms, vs, ss = [], [], [], [], []
            for p in g["params"]:
                if p.grad is None:
                    continue
                st = self.state.get(p)
                if not st:  # its first step: torch's makes the state
                    return None
                ps.append(p)
                gs.append(p.grad)
                ms.append(st["exp_avg"])
                vs.append(st["exp_avg_sq"])
                ss.append(st["step"])
            if any(p.device != ps[0].device or p.dtype != ps[0].dtype for p in ps[1:]):
                return None
            if ps:
                work.append((g, ps, gs, ms, vs, ss))
        return work


def adam_options(device) -> dict:
    """Adam's implementation on ``device``: fused on CUDA (one kernel per group instead of a dozen, and a
    step skipped on the device when ``found_inf`` is set: ``masked_step``). The CPU keeps torch's default:
    its fused kernel is faster (2.5x on the update of 50k Gaussians) but not bit-identical to it, and the
    CPU runs are the ones whose numbers must stay the same across refactors (bench/fingerprint.py)."""
    return {"fused": True} if torch.device(device).type == "cuda" else {}


def with_adam_options(saved: dict, optimizer: torch.optim.Optimizer) -> dict:
    """An optimiser state dict (``saved``, changed in place) with ``optimizer``'s implementation options, so
    that a checkpoint of a CUDA run (fused Adam) resumes on the CPU and the other way round (torch's
    ``load_state_dict`` would take the saved ones)."""
    for g_saved, g in zip(saved["param_groups"], optimizer.param_groups):
        for k in ("fused", "foreach", "capturable"):
            if k in g:
                g_saved[k] = g[k]
    return saved


def finite_flags(tensors: list[torch.Tensor]) -> torch.Tensor:
    """Whether each tensor is all finite, as a bool tensor on the device (no host read; ``inf_norms``)."""
    return torch.isfinite(inf_norms(tensors))


def masked_step(optimizer: torch.optim.Optimizer, apply: torch.Tensor, found_inf: torch.Tensor | None = None) -> None:
    """``optimizer.step()`` where the 0-dim bool tensor ``apply`` is true, and no change at all (parameters,
    moments, step counts) where it is false, without reading ``apply`` on the host. Fused Adam skips on the
    device (its ``found_inf``, as torch's GradScaler sets it); other optimisers step and put back what the
    step changed (their step counts must then be on ``apply``'s device; where they are not, ``apply`` is
    read). ``found_inf``: ``apply`` negated as float32, made once for several optimisers (default: here)."""
    groups = optimizer.param_groups
    if all(g.get("fused") for g in groups):
        optimizer.grad_scale = None
        optimizer.found_inf = (~apply).to(torch.float32) if found_inf is None else found_inf
        try:
            optimizer.step()
        finally:
            del optimizer.grad_scale, optimizer.found_inf
        return
    if apply.device.type != "cpu" and not all(g.get("capturable") for g in groups):  # step counts on the CPU
        if bool(apply):
            optimizer.step()
        return
    params = [p for g in groups for p in g["params"] if p.grad is not None]
    before = [(p.detach().clone(), {k: v.clone() for k, v in optimizer.state.get(p, {}).items()
                                    if isinstance(v, torch.Tensor)}) for p in params]
    optimizer.step()
    with torch.no_grad():
        for p, (old, old_state) in zip(params, before):
            p.copy_(torch.where(apply, p, old))
            for k, v in optimizer.state[p].items():
                if isinstance(v, torch.Tensor):  # a state the step created: as it starts (zeros, step 0)
                    v.copy_(torch.where(apply, v, old_state.get(k, torch.zeros_like(v))))


def state_copy(obj, device="cpu"):
    """A deep copy of a (nested) state with every tensor copied to ``device`` (checkpoints and, by default,
    snapshots: the CPU, which keeps no GPU memory; the trainer's snapshots on CUDA: the GPU itself, a copy
    within its memory instead of a transfer that stops the host)."""
    if isinstance(obj, torch.Tensor):
        return obj.detach().to(device, copy=True)
    if isinstance(obj, dict):
        return {k: state_copy(v, device) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(state_copy(v, device) for v in obj)
    return copy.deepcopy(obj)


def model_state(model: GaussianModel, optimizer: torch.optim.Optimizer, state: dict, device="cpu") -> dict:
    """A copy (on ``device``) of one model's training state: its parameters and SH degrees, Adam's moments, the
    densification statistics (``Trainer.state_dict``'s ``model`` part; the co-regularised pair's second model's)."""
    return dict(params=state_copy(dict(model.params), device), max_sh_degree=model.max_sh_degree,
                active_sh_degree=model.active_sh_degree, optimizer=state_copy(optimizer.state_dict(), device),
                strategy_state=state_copy(state, device))


def load_model_state(st: dict, model: GaussianModel, cfg: Config, scene_scale: float, device
                     ) -> tuple[torch.optim.Adam, dict]:
    """Puts ``model_state``'s copy ``st`` back into ``model`` (on ``device``; ``st`` stays usable); returns the
    new optimiser, with the saved moments, and the densification statistics."""
    for k, v in st["params"].items():
        model.params[k] = torch.nn.Parameter(v.to(device, copy=True))
    model.max_sh_degree = st["max_sh_degree"]
    model.active_sh_degree = st["active_sh_degree"]
    optimizer = make_optimizer(model, cfg, scene_scale)
    optimizer.load_state_dict(with_adam_options(copy.deepcopy(st["optimizer"]), optimizer))
    return optimizer, {k: v.to(device, copy=True) for k, v in st["strategy_state"].items()}
