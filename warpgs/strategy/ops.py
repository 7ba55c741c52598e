"""The model-editing operations of densification and pruning (gsplat's ``strategy/ops.py``): each edits the
model's parameters together with their Adam moments and the strategy's running statistics, so an optimiser
and a strategy state stay aligned with the Gaussians they describe. ``contribution`` measures what each
Gaussian adds to a set of views (the unseen pruning, compact mode's importance, the path floaters)."""

from __future__ import annotations

from typing import Callable

import torch
from torch import nn

from warpgs.model import GaussianModel


def update_params(model: GaussianModel, optimizer: torch.optim.Optimizer | None,
                  param_fn: Callable[[str, torch.Tensor], torch.Tensor],
                  state_fn: Callable[[str, torch.Tensor], torch.Tensor], names=None) -> None:
    """Replaces each parameter by ``param_fn(name, p)`` and its Adam moments by ``state_fn(key, v)``."""
    names = list(model.params.keys()) if names is None else names
    for name in names:
        old = model.params[name]
        new = nn.Parameter(param_fn(name, old.detach()), requires_grad=old.requires_grad)
        if optimizer is not None:
            for group in optimizer.param_groups:
                for i, p in enumerate(group["params"]):
                    if p is old:
                        st = optimizer.state.pop(old, None)
                        group["params"][i] = new
                        if st:
                            optimizer.state[new] = {k: (state_fn(k, v) if isinstance(v, torch.Tensor) and v.dim() > 0
                                                        else v) for k, v in st.items()}
        model.params[name] = new


def duplicate(model, optimizer, state, mask: torch.Tensor) -> None:
    sel = torch.where(mask)[0]
    update_params(model, optimizer, lambda n, p: torch.cat([p, p[sel]]),
                  lambda k, v: torch.cat([v, torch.zeros((len(sel), *v.shape[1:]), device=v.device, dtype=v.dtype)]))
    for k, v in state.items():
        state[k] = torch.cat([v, v[sel]])


def split(model, optimizer, state, mask: torch.Tensor, generator: torch.Generator | None = None) -> None:
    sel = torch.where(mask)[0]
    rest = torch.where(~mask)[0]
    p = model.params
    scales = torch.exp(p["scales"].detach()[sel])
    q = torch.nn.functional.normalize(p["quats"].detach()[sel], dim=-1)
    R = quat_to_rotmat(q)
    noise = torch.randn(2, len(sel), 3, device=scales.device, generator=generator)
    samples = torch.einsum("nij,nj,bnj->bni", R, scales, noise)  # [2, n, 3]

    def param_fn(name, t):
        if name == "means":
            new = (t[sel] + samples).reshape(-1, 3)
        elif name == "scales":
            new = torch.log(scales / 1.6).repeat(2, 1)
        else:
            new = t[sel].repeat(2, *([1] * (t.dim() - 1)))
        return torch.cat([t[rest], new])

    update_params(model, optimizer, param_fn,
                  lambda k, v: torch.cat([v[rest], torch.zeros((2 * len(sel), *v.shape[1:]), device=v.device, dtype=v.dtype)]))
    for k, v in state.items():
        state[k] = torch.cat([v[rest], v[sel].repeat(2, *([1] * (v.dim() - 1)))])


def remove(model, optimizer, state, mask: torch.Tensor) -> None:
    keep = torch.where(~mask)[0]
    update_params(model, optimizer, lambda n, p: p[keep], lambda k, v: v[keep])
    for k, v in state.items():
        state[k] = v[keep]


def reset_opacities(model, optimizer, value: float) -> None:
    """Clamps opacities to at most ``value`` and zeroes their Adam moments (3D-GS's opacity reset)."""
    logit = float(torch.logit(torch.tensor(value)))
    update_params(model, optimizer, lambda n, p: p.clamp(max=logit), lambda k, v: torch.zeros_like(v), names=["opacities"])


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (w, x, y, z) [N, 4] -> rotation matrices [N, 3, 3]."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(q.shape[:-1] + (3, 3))


def contribution(model: GaussianModel, cameras, background=None) -> torch.Tensor:
    """Total blending weight sum_pixels w_i of each Gaussian over ``cameras`` (objects with viewmat, K,
    width, height as tensors on the model's device). The image is sum_i w_i c_i + T bg, so the
    gradient of the image's sum with respect to a plain RGB colour c_i is exactly that weight."""
    from warpgs.render import rasterize

    total = torch.zeros(len(model), device=model.device)
    means, quats = model.means.detach(), model.quats.detach()
    scales, opac = model.scales.detach(), model.opacities.detach()
    for cam in cameras:
        colors = torch.zeros(len(model), 3, device=model.device, requires_grad=True)
        out = rasterize(means, quats, scales, opac, colors, cam.viewmat, cam.K, cam.width, cam.height,
                        background=background)
        out.image[..., 0].sum().backward()
        total += colors.grad[:, 0]
    return total
