"""Warped guidance and cross-view uncertainty (paper Sec. 3.2): torch tensors in, torch tensors out.

    src = PosedViews(src_viewmats, src_Ks, images=src_images, depths=src_depths)  # the input views
    dst = PosedViews(dst_viewmats, dst_Ks, images=renders, depths=dst_depths)     # the guidance frames
    g, q, valid = warp_guidance(src, dst)
    U, p2 = uncertainty_map(q, valid, src, dst, guidance=g, cfg=UncertaintyConfig())
    r = guidance_and_uncertainty(src, dst)      # both, as one ``WarpResult``

A guidance frame ``f`` (pose ``P_guid``, depth ``D_guid`` rendered by 3D-GS there) is filled by inverse
warping input ``src_index[f]``: ``q = K P_inp P_guid^-1 D_guid(p) K^-1 p``, ``g(p) = I_inp(q)``. The
backward projection ``p' = K P_guid P_inp^-1 D_inp(q) K^-1 q`` uses the depth rendered at the input,
and ``U(p) = 1 - exp(-|p - p'|^2 / s1 - |I_gs(p) - I_inp(q)|^2 / s2)`` (s1 in pixels^2, colours in
[0, 1], ``|.|`` the Euclidean norm over RGB). The settings come from ``UncertaintyConfig``, whose s1 is
given for 1024-wide frames as in the paper's SVD setting and converted to the image's width
(``effective_s1``; ``reference_width=None`` takes it in the image's own pixels). Pixels with no
correspondence (no depth, q outside the input image, no input depth at q, a point behind a camera)
get ``U = 1``.

Both sets of views are ``PosedViews``; each function reads the fields it needs: ``warp_guidance`` the
inputs' images and the frames' depths, ``uncertainty_map`` the inputs' depths and, for the photometric
term, the frames' images (the 3D-GS renders ``I_gs``). Shapes: inputs stacked ``images [S, Hs, Ws, 3]``,
``depths [S, Hs, Ws]``, ``viewmats [S, 4, 4]``, ``Ks [S, 3, 3]`` or ``[3, 3]``; guidance frames
``depths [F, H, W]``, ``images [F, H, W, 3]``, ``viewmats [F, 4, 4]``, ``Ks [F, 3, 3]`` or ``[3, 3]``;
``src_index [F]`` (default: input 0 for every frame when S == 1, else frame f from input f).
Unbatched views (one image ``[H, W, 3]``, one pose ``[4, 4]``, one depth ``[H, W]``) are accepted
and give unbatched results. Tensors stay on their device and go to the Warp kernels without copies
(``warpgs._warp.arg``); float32 contiguous tensors are used as they are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch
import warp as wp

from warpgs._warp import arg, device_of, launch, stream_of
from warpgs.geometry import small_inv
from warpgs.kernels import warping as kw


@dataclass
class UncertaintyConfig:
    s1: float = 100.0  # pixels^2 (of a reference_width-wide image): scale of the squared reprojection error
    reference_width: float | None = 1024.0  # s1's pixels: SVD's 1024-wide frames; None = the image's own
    s2: float = 0.25  # scale of the squared RGB difference between the 3D-GS render and the warp
    geometric: bool = True  # keep the |p - p'|^2 / s1 term
    photometric: bool = True  # keep the |I_gs(p) - I_inp(q)|^2 / s2 term
    min_depth: float = 1e-6  # depths at or below this count as "no surface"

    LIMITS = {"s1": "> 0", "reference_width": "> 0", "s2": "> 0", "min_depth": ">= 0"}


def effective_s1(cfg: UncertaintyConfig, width: int) -> float:
    """s1 in this image's pixels^2: the paper measures the reprojection error on SVD's 1024-wide frames,
    so an image ``width`` pixels wide uses ``s1 * (width / reference_width)^2`` (the same angular tolerance)."""
    if cfg.reference_width is None:
        return cfg.s1
    return cfg.s1 * (width / cfg.reference_width) ** 2


class PosedViews(NamedTuple):
    """Views of the scene, stacked ``[N, ...]`` or one unbatched: world-to-camera ``viewmats [N, 4, 4]``,
    pinhole ``Ks [N, 3, 3]`` (or one ``[3, 3]`` for all), and the ``images [N, H, W, 3]`` (RGB in [0, 1])
    and ``depths [N, H, W]`` (z-depth, 0 where nothing is seen) where a function reads them."""

    viewmats: torch.Tensor
    Ks: torch.Tensor
    images: torch.Tensor | None = None
    depths: torch.Tensor | None = None


def _field(views: PosedViews, name: str, who: str, role: str) -> torch.Tensor:
    """``views.<name>``, which function ``who`` reads of its ``role`` (src or dst) views; an error if not given."""
    t = getattr(views, name)
    if t is None:
        raise ValueError(f"{who} needs {role}.{name}")
    return t


class WarpResult(NamedTuple):
    guidance: torch.Tensor  # [F, H, W, 3] I_inp(q); 0 where there is no correspondence
    uncertainty: torch.Tensor  # [F, H, W] U in [0, 1]; 1 where there is no correspondence
    coords: torch.Tensor  # [F, H, W, 2] q in input pixels; -1 where none
    reprojected: torch.Tensor  # [F, H, W, 2] p' in guidance pixels; -1 where none
    valid: torch.Tensor  # [F, H, W] bool: q lands inside the input image


def _f32(t: torch.Tensor) -> torch.Tensor:
    return t.contiguous() if t.dtype == torch.float32 else t.float().contiguous()


def _stack(t: torch.Tensor, nd: int) -> tuple[torch.Tensor, bool]:
    """Adds a leading batch dim to an unbatched tensor of ``nd`` dims; returns (tensor, was_batched)."""
    return (t, True) if t.dim() == nd + 1 else (t.unsqueeze(0), False)


def _per_frame(m: torch.Tensor, n: int, what: str, nd: int = 2) -> torch.Tensor:
    """A per-frame stack [n, ...] from one matrix or a stack of n (broadcast without copy)."""
    if m.dim() == nd:
        return m.unsqueeze(0).expand(n, *m.shape)
    if m.shape[0] == 1:
        return m.expand(n, *m.shape[1:])
    if m.shape[0] != n:
        raise ValueError(f"{what}: expected {n} matrices (or one), got shape {tuple(m.shape)}")
    return m


def _check_index(src_index, n_src: int, n_frames: int, device) -> torch.Tensor:
    if src_index is None:
        if n_src == 1:
            return torch.zeros(n_frames, dtype=torch.int32, device=device)
        if n_src == n_frames:
            return torch.arange(n_frames, dtype=torch.int32, device=device)
        raise ValueError(f"src_index is needed to pair {n_frames} guidance frames with {n_src} input views")
    idx = torch.as_tensor(src_index, device=device).to(torch.int32).reshape(-1).contiguous()
    if idx.numel() != n_frames:
        raise ValueError(f"src_index has {idx.numel()} entries for {n_frames} guidance frames")
    if idx.numel() and (int(idx.min()) < 0 or int(idx.max()) >= n_src):
        raise ValueError(f"src_index must lie in [0, {n_src}), got {idx.tolist()}")
    return idx


def relative_transforms(src_viewmats: torch.Tensor, dst_viewmats: torch.Tensor, src_index: torch.Tensor):
    """Per frame ``(P_inp P_guid^-1, P_guid P_inp^-1)`` as float32 [F, 4, 4] (composed in float64).

    The inverses are taken on the CPU (``small_inv``): no cuSOLVER handle on a shared GPU."""
    S = src_viewmats[src_index.long()].double()
    D = dst_viewmats.double()
    Dinv = small_inv(D)
    Sinv = small_inv(S)
    return (S @ Dinv).float().contiguous(), (D @ Sinv).float().contiguous()


def _inv3(K: torch.Tensor) -> torch.Tensor:
    return small_inv(K.double()).float().contiguous()


def warp_guidance(
    src: PosedViews,
    dst: PosedViews,
    src_index=None,
    *,
    min_depth: float = 1e-6,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Inverse-warps input views ``src`` (their images) into guidance frames ``dst`` (their depths)
    -> (guidance [F,H,W,3], coords q [F,H,W,2], valid [F,H,W]).

    ``guidance`` is ``I_inp(q)`` sampled bilinearly, 0 where ``valid`` is False (no depth at p, the point
    behind the input camera, or q outside the input image)."""
    src_images, _ = _stack(_field(src, "images", "warp_guidance", "src"), 3)
    dst_depths, batched = _stack(_field(dst, "depths", "warp_guidance", "dst"), 2)
    src_viewmats, _ = _stack(src.viewmats, 2)
    dst_viewmats, _ = _stack(dst.viewmats, 2)
    n_src, n = src_images.shape[0], dst_depths.shape[0]
    dev_t = dst_depths.device
    idx = _check_index(src_index, n_src, n, dev_t)
    if src_images.shape[-1] != 3:
        raise ValueError(f"src.images must be [S, H, W, 3], got {tuple(src_images.shape)}")
    if src_viewmats.shape[0] != n_src or dst_viewmats.shape[0] != n:
        raise ValueError("one viewmat per input view and one per guidance frame are needed")
    src_K = _per_frame(src.Ks.to(dev_t), n_src, "src.Ks")[idx.long()]
    dst_K = _per_frame(dst.Ks.to(dev_t), n, "dst.Ks")
    to_src, _ = relative_transforms(src_viewmats.to(dev_t), dst_viewmats, idx)
    F, H, W = dst_depths.shape
    guidance = torch.empty(F, H, W, 3, device=dev_t, dtype=torch.float32)
    coords = torch.empty(F, H, W, 2, device=dev_t, dtype=torch.float32)
    valid = torch.empty(F, H, W, device=dev_t, dtype=torch.int32)
    src_images = _f32(src_images.to(dev_t))
    dst_depths = _f32(dst_depths)
    src_K32 = _f32(src_K)
    dst_Kinv = _inv3(dst_K)
    dev = device_of(dst_depths)
    launch(
        kw.inverse_warp, (F, H, W),
        [arg(dst_depths), arg(to_src, wp.mat44), arg(dst_Kinv, wp.mat33), arg(src_K32, wp.mat33), arg(idx),
         arg(src_images, wp.vec3), float(min_depth), arg(guidance, wp.vec3), arg(coords, wp.vec2), arg(valid)],
        dev, stream_of(dev),
    )
    valid = valid.bool()
    if not batched:
        return guidance[0], coords[0], valid[0]
    return guidance, coords, valid


def uncertainty_map(
    coords: torch.Tensor,
    valid: torch.Tensor,
    src: PosedViews,
    dst: PosedViews,
    src_index=None,
    *,
    guidance: torch.Tensor | None = None,
    cfg: UncertaintyConfig | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Cross-view uncertainty from ``warp_guidance``'s correspondences -> (U [F,H,W], p' [F,H,W,2]).

    Reads the depths of the inputs ``src``; the photometric term also needs the guidance frames' images
    ``dst.images`` (I_gs, the 3D-GS renders at their poses) and ``guidance`` (I_inp(q)). ``cfg``
    (default: the paper's settings) gives s1, s2, the terms to keep (the paper's ablations) and min_depth."""
    cfg = cfg or UncertaintyConfig()
    coords, batched = _stack(coords, 3)
    valid, _ = _stack(valid, 2)
    src_depths, _ = _stack(_field(src, "depths", "uncertainty_map", "src"), 2)
    src_viewmats, _ = _stack(src.viewmats, 2)
    dst_viewmats, _ = _stack(dst.viewmats, 2)
    F, H, W, _ = coords.shape
    n_src = src_depths.shape[0]
    dev_t = coords.device
    idx = _check_index(src_index, n_src, F, dev_t)
    if src_viewmats.shape[0] != n_src or dst_viewmats.shape[0] != F:
        raise ValueError("one viewmat per input view and one per guidance frame are needed")
    s1, s2, photometric = effective_s1(cfg, W), cfg.s2, cfg.photometric
    if s1 <= 0 or s2 <= 0:
        raise ValueError(f"s1 and s2 must be positive, got {s1}, {s2}")
    if photometric:
        if dst.images is None or guidance is None:
            raise ValueError("the photometric term needs dst.images (I_gs, the renders at the guidance poses) "
                             "and guidance (I_inp(q)); pass them or set photometric=False")
        renders, _ = _stack(dst.images, 3)
        guidance, _ = _stack(guidance, 3)
        renders, guidance = _f32(renders.to(dev_t)), _f32(guidance.to(dev_t))
        if renders.shape != (F, H, W, 3) or guidance.shape != (F, H, W, 3):
            raise ValueError(f"dst.images and guidance must be [{F}, {H}, {W}, 3]")
    else:  # the kernel reads them but multiplies by inv_s2 = 0
        renders = guidance = torch.zeros(F, H, W, 3, device=dev_t)
    src_K = _per_frame(src.Ks.to(dev_t), n_src, "src.Ks")[idx.long()]
    dst_K = _f32(_per_frame(dst.Ks.to(dev_t), F, "dst.Ks"))
    _, to_dst = relative_transforms(src_viewmats.to(dev_t), dst_viewmats.to(dev_t), idx)
    U = torch.empty(F, H, W, device=dev_t, dtype=torch.float32)
    p2 = torch.empty(F, H, W, 2, device=dev_t, dtype=torch.float32)
    # every tensor handed to the kernel is held by a local name until the launch is enqueued
    coords = _f32(coords)
    valid_i = valid.to(torch.int32).contiguous()
    src_depths = _f32(src_depths.to(dev_t))
    src_Kinv = _inv3(src_K)
    dev = device_of(coords)
    launch(
        kw.reproject_uncertainty, (F, H, W),
        [arg(coords, wp.vec2), arg(valid_i), arg(src_depths), arg(idx), arg(to_dst, wp.mat44),
         arg(src_Kinv, wp.mat33), arg(dst_K, wp.mat33), arg(renders, wp.vec3), arg(guidance, wp.vec3),
         1.0 / s1 if cfg.geometric else 0.0, 1.0 / s2 if photometric else 0.0, float(cfg.min_depth),
         arg(U), arg(p2, wp.vec2)],
        dev, stream_of(dev),
    )
    if not batched:
        return U[0], p2[0]
    return U, p2


def guidance_and_uncertainty(
    src: PosedViews,
    dst: PosedViews,
    src_index=None,
    *,
    cfg: UncertaintyConfig | None = None,
) -> WarpResult:
    """``warp_guidance`` then ``uncertainty_map`` with the settings of ``cfg`` (paper defaults): ``src``
    needs images and depths, ``dst`` depths, and images (the renders) for the photometric term."""
    cfg = cfg or UncertaintyConfig()
    g, q, valid = warp_guidance(src, dst, src_index, min_depth=cfg.min_depth)
    idx = src_index
    if idx is None:
        n_src = src.images.shape[0] if src.images.dim() == 4 else 1
        n = dst.depths.shape[0] if dst.depths.dim() == 3 else 1
        idx = _check_index(None, n_src, n, dst.depths.device)
    U, p2 = uncertainty_map(q, valid, src, dst, idx, guidance=g, cfg=cfg)
    return WarpResult(g, U, q, p2, valid)


def match_colour(warped: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, sources: torch.Tensor | None = None,
                 min_pixels: int = 64, gain_range: tuple[float, float] = (0.5, 2.0)) -> torch.Tensor:
    """``warped`` [F, H, W, 3] with each frame's colour brought to ``target``'s (the 3D-GS renders): per frame, per
    source input (``sources`` [F, H, W], the input each pixel was warped from; None: one) and per channel, the gain
    and offset that fit ``target`` best in least squares over the ``mask`` pixels [F, H, W] (the reliable ones),
    applied to all its pixels and clipped to [0, 1] (``pseudo.trajectory.guidance_colour: affine``). The inputs of
    a capture differ in exposure and white balance, so a warped input disagrees with the render even where the
    geometry agrees (measured on the captures: the warps were 0.4-3.9 dB worse than the render in the reliable
    pixels); the fit removes that difference and keeps the photo's detail. A frame's source with fewer than
    ``min_pixels`` masked pixels is left as it is; the gain is held within ``gain_range``."""
    out = warped.clone()
    src = torch.zeros(mask.shape, dtype=torch.long, device=mask.device) if sources is None else sources.long()
    for f in range(warped.shape[0]):
        for s in torch.unique(src[f]).tolist():
            sel = src[f] == s
            fit = sel & mask[f]
            if int(fit.sum()) < min_pixels:
                continue
            w, t = warped[f][fit].double(), target[f][fit].double()  # [P, 3]
            wm, tm = w.mean(0), t.mean(0)
            var = ((w - wm) ** 2).mean(0)
            gain = torch.where(var > 1e-8, ((w - wm) * (t - tm)).mean(0) / var.clamp_min(1e-8), torch.ones_like(var))
            gain = gain.clamp(*gain_range)
            offset = tm - gain * wm
            out[f][sel] = (warped[f][sel].double() * gain + offset).clamp(0, 1).to(out.dtype)
    return out
