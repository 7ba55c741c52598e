"""The torch-facing Gaussian rasterizer: plain tensors in, image / depth / alpha out, differentiable.

    out = rasterize(means, quats, scales, opacities, colors, viewmat, K, width, height)
    out.image  [H, W, 3]   colour composited over ``background``
    out.depth  [H, W]      expected depth sum(w_i z_i) / alpha (0 where nothing was hit)
    out.alpha  [H, W]      accumulated opacity 1 - T

Tensors stay on their device (cpu or cuda) and are handed to the Warp kernels without copies; Warp runs
on torch's current CUDA stream. Gradients flow to means, quats, scales, opacities and colors (RGB or
SH coefficients) through image, depth and alpha. ``out.means2d`` is the projected centre tensor in
the graph: call ``out.means2d.retain_grad()`` before backward to read the 2D positional gradient that
densification uses (``means2d_grad_norm``).

Conventions: see ``warpgs/__init__.py`` (OpenCV camera, world-to-camera ``viewmat``, K in pixels,
quaternions (w, x, y, z), scales as standard deviations, opacities in [0, 1]).
"""

from __future__ import annotations

import collections
import functools
import math
import struct
from typing import NamedTuple

import torch
import warp as wp

from warpgs._warp import (KeptFields, device_of, fast_launch, launch_parts, launch_stream, native_function,
                          native_on_stream, to_wp, wp_stream)
from warpgs.kernels import binning as kb
from warpgs.kernels import projection as kp
from warpgs.kernels import rasterize as kr
from warpgs.kernels import rasterize_cpu as krc
from warpgs.kernels import sh as ksh


# The CPU composites in two interleaved halves of the image's tile rows, on two threads where the process
# may use two cores (``warpgs._warp.launch_parts``; kernels: PARTS_NOTE in warpgs/kernels/rasterize.py).
# Fixed at 2 whatever the machine, so a CPU run gives the same numbers on one core or two.
CPU_PARTS = 2


def _tile_grid(dev: str, width: int, height: int) -> tuple[int, int, int]:
    """(tile edge, tiles across, tiles down) of an image on Warp device ``dev`` (the edge is the device's:
    ``kr.tile_size_for``)."""
    ts = kr.tile_size_for(dev)
    return ts, (width + ts - 1) // ts, (height + ts - 1) // ts


class RenderOutput(NamedTuple):
    image: torch.Tensor
    depth: torch.Tensor
    alpha: torch.Tensor
    means2d: torch.Tensor
    radii: torch.Tensor
    depths: torch.Tensor
    n_intersections: int
    # with ``isect_capacity``: the intersections the render had (a device scalar, no host read), which a render
    # that needed more than its capacity exceeds (it drew some Gaussians in fewer tiles); else None
    needed: torch.Tensor | None = None


def _grad_or_zeros(g: torch.Tensor | None, shape, device) -> torch.Tensor:
    """``g`` (an output's gradient), or zeros of ``shape`` (``_zero_input``) where the loss did not use that
    output."""
    return _zero_input(shape, device) if g is None else g.contiguous()


_ZERO_INPUTS: dict = {}
_ZERO_VIEWS: dict = {}  # (device, shape) -> the view ``_zero_input`` gave of the device's current buffer


def _zero_input(shape, device) -> torch.Tensor:
    """A float32 zero tensor of ``shape`` for a kernel to read (never to write): a view of a per-device buffer
    that only grows, so a backward pass whose loss leaves out the depth or alpha allocates and clears nothing
    for their gradients. The view of a shape is made once (per buffer) and handed out again; nothing writes
    into it, and none reaches the caller of ``rasterize``."""
    key = (device, shape)
    view = _ZERO_VIEWS.get(key)
    if view is not None:
        return view
    n = math.prod(shape)
    buf = _ZERO_INPUTS.get(device)
    if buf is None or buf.numel() < n:
        buf = _ZERO_INPUTS[device] = torch.zeros(n, device=device)
        _ZERO_VIEWS.clear()  # views of the smaller buffer: let it go
    if len(_ZERO_VIEWS) >= 256:  # many image sizes: keep the table small
        _ZERO_VIEWS.clear()
    view = _ZERO_VIEWS[key] = buf[:n].view(shape)
    return view


_CAMERAS: collections.OrderedDict = collections.OrderedDict()  # ``_camera``'s tuples, the latest used last
_CAMERAS_KEPT = 32


def _camera(viewmat, K, width, height, eps2d, antialiased):
    """The fields of ``kp.Camera`` for one view: viewmat [4, 4] and K [3, 3] (contiguous float32, as ``rasterize``
    makes them) stay on their device as one-element arrays. (A ``kp.Gaussians`` argument is the tuple (means,
    quats, scales, opacities).)

    The tuple of a view is made once and handed out again while it is among the last ``_CAMERAS_KEPT`` used: it is
    found by the two matrices' memory (their data pointers; the tuple's views keep that memory alive, so no other
    tensor can have been given it since) and the numbers. A render's forward and backward, and a training run's
    steps on one camera, pass the same tuple, and the launcher writes a struct argument only when it is given
    another tuple than last time (``warpgs._warp.KeptFields``). Matrices changed in place are read as they are at
    the launch, as before: the views share their memory. ``rasterize`` passes them detached from any autograd graph,
    and the tuple holds no other tensor."""
    key = (viewmat.data_ptr(), K.data_ptr(), width, height, eps2d, antialiased)
    got = _CAMERAS.get(key)
    if got is None or got[0].data_ptr() != key[0] or got[1].data_ptr() != key[1] or got[0].device != viewmat.device:
        # (a view whose memory moved since, by an in-place resize of its tensor, is made again)
        got = _CAMERAS[key] = KeptFields((viewmat.reshape(1, 4, 4), K.reshape(1, 3, 3), width, height, eps2d,
                                          int(antialiased)))
        if len(_CAMERAS) > _CAMERAS_KEPT:
            _CAMERAS.popitem(last=False)
    else:
        try:
            _CAMERAS.move_to_end(key)
        except KeyError:  # another thread's render dropped it meanwhile: it is still this view's tuple
            pass
    return got


def _project(means, quats, scales, opacities, viewmat, K, width, height, eps2d, near, far, antialiased, dev, stream):
    """The projection kernel on Warp device ``dev`` and ``stream`` (``launch_stream``): (means2d, conics, depths,
    opac_eff, radii, tiles_touched)."""
    n = means.shape[0]
    ts, tiles_x, tiles_y = _tile_grid(dev, width, height)
    f = dict(device=means.device, dtype=torch.float32)
    means2d = torch.empty(n, 2, **f)
    conics = torch.empty(n, 3, **f)
    depths = torch.empty(n, **f)
    opac_eff = torch.empty(n, **f)
    radii = torch.empty(n, 2, device=means.device, dtype=torch.int32)
    tiles_touched = torch.empty(n, device=means.device, dtype=torch.int32)
    fast_launch(
        kp.project_gaussians_fwd, n, dev, stream,
        (means, quats, scales, opacities), _camera(viewmat, K, width, height, eps2d, antialiased),
        near, far, ts, tiles_x, tiles_y, means2d, conics, depths, radii, opac_eff, tiles_touched,
    )
    return means2d, conics, depths, opac_eff, radii, tiles_touched


class _Project(torch.autograd.Function):
    # dev, stream: the Warp device of the tensors and the stream of the launches (``launch_stream``; looked up here
    # where not given), kept for the backward, which autograd runs on the forward's stream
    @staticmethod
    def forward(ctx, means, quats, scales, opacities, viewmat, K, width, height, eps2d, near, far, antialiased,
                dev=None, stream=None):
        if dev is None:
            dev, stream = device_of(means), launch_stream(means)
        means2d, conics, depths, opac_eff, radii, tiles_touched = _project(
            means, quats, scales, opacities, viewmat, K, width, height, eps2d, near, far, antialiased, dev, stream)
        ctx.save_for_backward(means, quats, scales, opacities, viewmat, K, radii, conics)
        ctx.cfg = (width, height, eps2d, antialiased, dev, stream)
        ctx.mark_non_differentiable(radii, tiles_touched)
        return means2d, conics, depths, opac_eff, radii, tiles_touched

    @staticmethod
    def backward(ctx, v_means2d, v_conics, v_depths, v_opac_eff, _r, _t):
        means, quats, scales, opacities, viewmat, K, radii, conics = ctx.saved_tensors
        width, height, eps2d, antialiased, dev, stream = ctx.cfg
        n = means.shape[0]
        v_means = torch.empty_like(means)
        v_quats = torch.empty_like(quats)
        v_scales = torch.empty_like(scales)
        v_opacities = torch.empty_like(opacities)
        # the structs are rebuilt from the saved tensors rather than kept on ctx, so that autograd's
        # checks of saved tensors (in-place changes since the forward) cover everything the kernel reads
        fast_launch(
            kp.project_gaussians_bwd, n, dev, stream,
            (means, quats, scales, opacities), _camera(viewmat, K, width, height, eps2d, antialiased),
            radii, conics, _grad_or_zeros(v_means2d, (n, 2), means.device),
            _grad_or_zeros(v_conics, conics.shape, means.device), _grad_or_zeros(v_depths, (n,), means.device),
            _grad_or_zeros(v_opac_eff, (n,), means.device),
            (v_means, v_quats, v_scales, v_opacities),
        )
        return v_means, v_quats, v_scales, v_opacities, None, None, None, None, None, None, None, None, None, None


class _SHColors(torch.autograd.Function):
    @staticmethod
    def forward(ctx, coeffs, means, campos, radii, degree, dev=None, stream=None):  # dev, stream: as _Project's
        if dev is None:
            dev, stream = device_of(means), launch_stream(means)
        colors = torch.empty(means.shape[0], 3, device=means.device, dtype=torch.float32)
        fast_launch(ksh.sh_to_color_fwd, means.shape[0], dev, stream,
                    means, campos.reshape(1, 3), coeffs, degree, radii, colors)
        ctx.save_for_backward(coeffs, means, campos, radii, colors)
        ctx.cfg = (degree, dev, stream)
        return colors

    @staticmethod
    def backward(ctx, v_colors):
        coeffs, means, campos, radii, colors = ctx.saved_tensors
        degree, dev, stream = ctx.cfg
        v_coeffs = torch.empty_like(coeffs)
        v_means = torch.empty_like(means)
        v_colors = v_colors.contiguous()
        campos = campos.reshape(1, 3)
        fast_launch(ksh.sh_coeffs_bwd, coeffs.shape[0] * coeffs.shape[1], dev, stream,
                    means, campos, degree, radii, colors, v_colors, v_coeffs)
        fast_launch(ksh.sh_dir_bwd, means.shape[0], dev, stream,
                    means, campos, coeffs, degree, radii, colors, v_colors, v_means)
        return v_coeffs, v_means, None, None, None, None, None


def _bin_gaussians(means2d, radii, depths, conics, opac_eff, colors, splats, offsets, ranges, tiles_x, tiles_y,
                   near: float, capacity: int | None = None, dev: str | None = None, stream=None):
    """Sorted Gaussian ids per tile: returns (gauss_ids [total] int32, the sorted keys, their shift, total), and
    packs the Gaussians on screen into ``splats`` [N, 10] as the compositing kernels read them (the same launch).
    ``offsets``: the inclusive cumulative sum of the Gaussians' tile counts (int32). On the CPU it also fills
    ``ranges`` [tiles, 2] int32 (zeros on entry) with each tile's [start, end) in the sorted list; on CUDA the
    forward compositing kernel finds them in the keys itself and writes them there.

    A key is the tile id above the depth's float bits (every depth on screen is positive, so its bits sort as the
    depth does). On the CPU the depth part is those bits less the near plane's ``near``, and the one host read of a
    render takes the largest depth's bits with the count: the shift is the width of that difference
    (``_key_shift``; 27 bits while the largest depth is below 65,536 times the near plane, instead of 32), so the
    CPU's radix sort, whose passes are its cost, makes fewer. On CUDA the depth keeps its raw 32 bits (the shift is
    32) and the host read is the count alone: the largest depth's reduction and the tensors that gather the two
    cost the host about as much as the GPU spends on the sort's extra 8-bit pass (six instead of five at up to
    8,192 tiles; with an even count the result should end in the first buffer, sparing the native sort its copy
    back), and a render of up to a few hundred thousand Gaussians waits on its host, not on its GPU (issue 15). The
    order is the same either way, so the render is too.

    ``capacity``: the key buffers hold that many entries whatever the count, so nothing is read on the host
    (a CUDA graph can hold the render; ``warpgs.graphstep``): the unused entries are padding keys that sort
    after every real one (a tile past the grid), the sort is torch's stable one (the same order as Warp's
    radix sort of the real keys), and ``total`` is the capacity. The caller guarantees that the count fits
    (``count_intersections``); the kernel writes no entry past the buffers either way. ``dev``, ``stream``: the Warp
    device and the stream of the launches (``launch_stream``), looked up where not given."""
    if dev is None:
        dev, stream = device_of(means2d), launch_stream(means2d)
    n = means2d.shape[0]
    shift, base = 32, 0  # CUDA, or a fixed capacity: the depth's raw bits
    if capacity is None:
        count = 0
        if n and dev == "cpu":  # the one host read of a render: the count sizes the key buffers, the largest depth
            # the keys (the two int32 read as one int64, low half first: one scalar copy)
            both = torch.stack((offsets[-1], depths.view(torch.int32).amax())).view(torch.int64).item()
            count, top = both & 0xFFFFFFFF, both >> 32
            base = _float_bits(near)
            shift = _key_shift(top - base)
        elif n:  # the one host sync of a CUDA render: the count alone
            count = offsets[-1].item()
        keys = torch.empty(2 * count, device=means2d.device, dtype=torch.int64)  # the sort's double buffer
        values = torch.empty(2 * count, device=means2d.device, dtype=torch.int32)
    else:
        count = capacity
        keys = torch.full((count,), _PADDING_KEY, device=means2d.device, dtype=torch.int64)
        values = torch.zeros(count, device=means2d.device, dtype=torch.int32)
    if n == 0 or count == 0:
        return values[:count], keys, shift, count
    fast_launch(kb.emit_intersections, n, dev, stream,
                means2d, radii, depths.view(torch.int32), offsets, kr.tile_size_for(dev), tiles_x, tiles_y, shift,
                base, keys, values, conics, opac_eff, colors, depths, splats)
    if capacity is None:
        tile_bits = int(math.floor(math.log2(tiles_x * tiles_y))) + 1
        _sort_pairs(keys, values, count, shift + tile_bits, stream, dev)
    else:
        keys, order = torch.sort(keys, stable=True)
        values = values[order]
    if dev == "cpu":
        fast_launch(kb.tile_ranges_from_keys, count, dev, stream, keys, count, shift, ranges)
    return values[:count], keys, shift, count


def _float_bits(x: float) -> int:
    """The bits of ``x`` as a float32, read as an int32."""
    return struct.unpack("<i", struct.pack("<f", x))[0]


def _key_shift(span: int) -> int:
    """The key bits the depth takes when the largest depth's bits exceed the near plane's by ``span``: its width
    (at least 1). Every depth on screen lies between the two, so its difference fits; a span past 31 bits (no
    finite positive depth has one) keeps 32."""
    return min(32, span.bit_length()) if span > 0 else 1


def _unused_grads(device) -> tuple:
    """Empty read-only stand-ins for the float gradient outputs of the fixed-point CUDA backward, which does not
    write them: (means2d [0, 2], conics [0, 3], opacities [0], colours [0, 3], depths [0])."""
    return tuple(_zero_input(shape, device) for shape in ((0, 2), (0, 3), (0,), (0, 3), (0,)))


# a key past every tile (tile id 2^31 - 1): the padding of fixed-capacity key buffers, sorted last
_PADDING_KEY = (1 << 63) - 1


def _sort_pairs(keys: torch.Tensor, values: torch.Tensor, count: int, end_bit: int, stream,
                dev: str | None = None) -> None:
    """Warp's radix sort of the first ``count`` (int64 key, int32 value) pairs by the key bits below ``end_bit``
    (both buffers hold 2 x count: the sort's double buffer), on ``stream`` (None: the CPU; else a raw handle
    or a wp.Stream of CUDA device ``dev``). On CUDA the native sort is called directly on the torch tensors'
    memory, with the stream as the current one of Warp's context and no wait on Warp's previous stream (torch's
    stream already orders it): ``wp.utils.radix_sort_pairs``'s checks, its two array wrappers and the scope's
    event cost more host time than the sort's launches. A raw handle is made current natively
    (``native_on_stream``: no Python scope objects); a wp.Stream, or a handle during a Warp graph capture, goes
    through ``wp.ScopedStream`` as before."""
    if stream is None:
        wp.utils.radix_sort_pairs(to_wp(keys), to_wp(values), count, 0, end_bit)
        return
    native = native_function("wp_radix_sort_pairs_int64_device")
    if native is not None and native_on_stream(dev, stream, native, keys.data_ptr(), values.data_ptr(), count, 0,
                                               end_bit, 4):
        return
    with wp.ScopedStream(wp_stream(dev, stream), sync_enter=False):
        if native is None:  # pragma: no cover - other Warp versions
            wp.utils.radix_sort_pairs(to_wp(keys), to_wp(values), count, 0, end_bit)
        else:
            native(keys.data_ptr(), values.data_ptr(), count, 0, end_bit, 4)


class _Composite(torch.autograd.Function):
    # The tile binning runs inside the forward, after the work that does not need the sorted lists (the cumulative
    # tile counts, the outputs' allocations): the binning's read of the intersection count waits for the GPU, so
    # what the host does before it overlaps the GPU's work, and what it does after leaves the GPU idle. The launches
    # are three on CUDA (keys and packed splats, the sort, the compositing, which finds its tile's range in the
    # keys): each costs the host more than the GPU at 100k-200k Gaussians. ``info``: a list that receives the
    # intersection count (``RenderOutput.n_intersections``).
    @staticmethod
    def forward(ctx, means2d, conics, opac_eff, colors, depths, background, radii, tiles_touched, width, height,
                alpha_max, deterministic, near, capacity, info, dev=None, stream=None):  # dev, stream: as _Project's
        if dev is None:
            dev, stream = device_of(means2d), launch_stream(means2d)
        _, tiles_x, tiles_y = _tile_grid(dev, width, height)
        n_tiles = tiles_x * tiles_y
        n_threads = kr.compositing_threads(dev, n_tiles)
        offsets = torch.cumsum(tiles_touched, 0, dtype=torch.int32)
        f = dict(device=means2d.device, dtype=torch.float32)
        splats = torch.empty(means2d.shape[0], 10, **f)
        color = torch.empty(height, width, 3, **f)
        depth = torch.empty(height, width, **f)
        alpha = torch.empty(height, width, **f)
        last = torch.empty(height, width, device=means2d.device, dtype=torch.int32)
        # written by the CPU's binning (which leaves empty tiles at zero) or by the CUDA forward (every tile)
        ranges = (torch.zeros if dev == "cpu" else torch.empty)(n_tiles, 2, device=means2d.device, dtype=torch.int32)
        gauss_ids, keys, shift, total = _bin_gaussians(means2d, radii, depths, conics, opac_eff, colors, splats,
                                                       offsets, ranges, tiles_x, tiles_y, near, capacity, dev, stream)
        info.append(total)
        info.append(offsets[-1] if capacity is not None and offsets.numel() else None)  # what it needed
        # the kernels' struct arguments as field tuples (kr.Tiles, kr.Image)
        tiles = (ranges, gauss_ids, splats, background.reshape(1, 3), width, height, tiles_x, alpha_max)
        image = (color.view(-1, 3), depth.view(-1), alpha.view(-1), last.view(-1))
        if dev == "cpu":  # the parts write disjoint pixels
            launch_parts(krc.rasterize_fwd_cpu, n_threads, dev, CPU_PARTS, lambda p: (tiles, image))
        else:
            fast_launch(kr.rasterize_fwd_cuda, n_threads, dev, stream, keys, total, shift, tiles, image)
        ctx.save_for_backward(splats, background, ranges, gauss_ids, depth, alpha, last)
        ctx.cfg = (width, height, alpha_max, deterministic, dev, stream)
        # an output the loss does not use gets None in backward, not a zero tensor: no allocation, and a
        # loss without the depth skips its terms in the kernel
        ctx.set_materialize_grads(False)
        return color, depth, alpha

    @staticmethod
    def backward(ctx, v_color, v_depth, v_alpha):
        splats, background, ranges, gauss_ids, depth, alpha, last = ctx.saved_tensors
        width, height, alpha_max, deterministic, dev, stream = ctx.cfg
        tiles_x = _tile_grid(dev, width, height)[1]
        n = splats.shape[0]
        # the CPU backend runs one thread, so its float sums are deterministic already
        fixed = bool(deterministic) and (dev != "cpu" or deterministic == "fixed")
        z = dict(device=splats.device, dtype=torch.float32)

        def float_grads(make):  # (v_means2d, v_conics, v_opac, v_colors, v_depths)
            return make(n, 2, **z), make(n, 3, **z), make(n, **z), make(n, 3, **z), make(n, **z)

        def grad_buffers(make):  # (v_fixed, the float gradients)
            return (torch.zeros(n if fixed else 0, 10, device=splats.device, dtype=torch.int64),) + float_grads(make)

        with_depth = int(v_depth is not None)  # a loss without the depth skips its (zero) terms
        # the kernels' struct arguments as field tuples (kr.Tiles, kr.PixelGrads; kr.SplatGrads: flags + buffers)
        tiles = (ranges, gauss_ids, splats, background.reshape(1, 3), width, height, tiles_x, alpha_max)
        pixels = (depth.view(-1), alpha.view(-1), last.view(-1),
                  _grad_or_zeros(v_color, (height, width, 3), alpha.device).view(-1, 3),
                  _grad_or_zeros(v_depth, alpha.shape, alpha.device).view(-1),
                  _grad_or_zeros(v_alpha, alpha.shape, alpha.device).view(-1))
        flags = (int(fixed), with_depth)
        n_threads = kr.compositing_threads(dev, ranges.shape[0])
        if dev == "cpu":
            # each part adds into buffers of its own (a CPU "atomic" add is a plain one), summed in part order
            parts = [grad_buffers(torch.empty if fixed else torch.zeros)]
            parts += [grad_buffers(torch.zeros) for _ in range(CPU_PARTS - 1)]
            launch_parts(krc.rasterize_bwd_cpu, n_threads, dev, CPU_PARTS, lambda p: (tiles, pixels, flags + parts[p]))
            for extra in parts[1:]:
                for total, t in zip(parts[0], extra):
                    total += t
            v_fixed, *grads = parts[0]
        elif fixed:
            # the fixed-point variant writes v_fixed alone: its float outputs are empty views, and the float
            # gradients are made after the launch, while the GPU runs it
            v_fixed = torch.zeros(n, 10, device=splats.device, dtype=torch.int64)
            fast_launch(kr.rasterize_bwd_cuda[1][with_depth], n_threads, dev, stream, tiles, pixels,
                        flags + (v_fixed,) + _unused_grads(splats.device), 0, 1)
            grads = float_grads(torch.empty)
        else:
            v_fixed, *grads = grad_buffers(torch.zeros)
            fast_launch(kr.rasterize_bwd_cuda[0][with_depth], n_threads, dev, stream, tiles, pixels,
                        (*flags, v_fixed, *grads), 0, 1)
        if fixed and n:
            fast_launch(kr.fixed_to_grads, n, dev, stream, (*flags, v_fixed, *grads))
        return tuple(grads) + (None,) * 12


# ----------------------------------------------------------------------------------------------------
# input checks


def _fail(name: str, problem: str):
    raise ValueError(f"rasterize: argument '{name}' {problem}")


def _check_tensor(name, t, shape, device):
    if not isinstance(t, torch.Tensor):
        _fail(name, f"must be a torch.Tensor, got {type(t).__name__}")
    if not _shape_matches(t.shape, shape):
        want = "[" + ", ".join("*" if s is None else str(s) for s in shape) + "]"
        _fail(name, f"must have shape {want}, got {list(t.shape)}")
    if not t.is_floating_point():
        _fail(name, f"must be a floating-point tensor, got {t.dtype}")
    if t.device != device:
        _fail(name, f"is on {t.device} but means is on {device}")


def _shape_matches(got, shape) -> bool:
    """Whether tensor shape ``got`` is ``shape`` (None: any size there)."""
    if len(got) != len(shape):
        return False
    for s, d in zip(shape, got):
        if s is not None and s != d:
            return False
    return True


def _f32(t: torch.Tensor) -> torch.Tensor:
    """``t.float().contiguous()``, without the two calls where ``t`` already is both (the usual case)."""
    return t if t.dtype is torch.float32 and t.is_contiguous() else t.float().contiguous()


def _check_finite(named: dict[str, torch.Tensor]):
    for name, t in named.items():
        if not bool(torch.isfinite(t).all()):
            _fail(name, "contains NaN or Inf values")


def rasterize(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    opacities: torch.Tensor,
    colors: torch.Tensor,
    viewmat: torch.Tensor,
    K: torch.Tensor,
    width: int,
    height: int,
    *,
    sh_degree: int | None = None,
    background: torch.Tensor | None = None,
    near_plane: float = 0.01,
    far_plane: float = 1e10,
    eps2d: float = 0.3,
    antialiased: bool = False,
    alpha_max: float = 0.99,
    deterministic: bool | str = True,
    check_finite: bool = True,
    isect_capacity: int | None = None,
) -> RenderOutput:
    """Render N 3D Gaussians from one pinhole camera.

    Args:
        means [N, 3], quats [N, 4] (w, x, y, z; need not be normalised), scales [N, 3] (>= 0),
        opacities [N] in [0, 1].
        colors: [N, 3] RGB, or [N, K, 3] SH coefficients with ``sh_degree`` in 0..3 and K >= (d+1)^2
            (colour = max(0, SH + 0.5), 3D-GS convention).
        viewmat [4, 4] world-to-camera (OpenCV axes), K [3, 3] intrinsics in pixels, width, height.
        background [3]: colour behind the Gaussians (default black); or [H, W, 3], one colour per pixel
            (a far field, ``warpgs.farfield``), composited as image + (1 - alpha) background, with gradients
            to it if it requires them.
        near_plane / far_plane: camera-z range kept (gsplat's 0.01 default; 3D-GS uses 0.2).
        eps2d: screen-space dilation added to the 2D covariance (0.3 px).
        antialiased: scale opacity by sqrt(det S / det(S + eps2d I)) (gsplat's antialiased mode).
        alpha_max: per-Gaussian alpha clamp (0.99 in 3D-GS, 0.999 in gsplat).
        deterministic: on CUDA, sum the backward pass's per-Gaussian gradients in 64-bit fixed point
            (2^-40 steps), so two runs give identical gradients; False: float atomics (as gsplat; a
            little faster, but the order of additions varies run to run). The CPU backend is
            deterministic either way; "fixed" forces the fixed-point path there too (tests).
        check_finite: raise a ValueError naming the argument that holds NaN or Inf.
        isect_capacity: size the tile-intersection buffers to this many entries instead of reading the count on
            the host (the render's one device sync), so that a CUDA graph can hold the render; it must be at least
            ``count_intersections`` of the same inputs. ``n_intersections`` is then the capacity.
    """
    if not isinstance(means, torch.Tensor):
        _fail("means", f"must be a torch.Tensor, got {type(means).__name__}")
    device = means.device
    _check_tensor("means", means, (None, 3), device)
    n = means.shape[0]
    _check_tensor("quats", quats, (n, 4), device)
    _check_tensor("scales", scales, (n, 3), device)
    _check_tensor("opacities", opacities, (n,), device)
    if sh_degree is None:
        _check_tensor("colors", colors, (n, 3), device)
    else:
        if sh_degree not in (0, 1, 2, 3):
            _fail("sh_degree", f"must be 0, 1, 2 or 3, got {sh_degree}")
        _check_tensor("colors", colors, (n, None, 3), device)
        if colors.shape[1] < (sh_degree + 1) ** 2:
            _fail("colors", f"needs at least {(sh_degree + 1) ** 2} SH coefficients for degree {sh_degree}, "
                            f"got {colors.shape[1]}")
    _check_tensor("viewmat", viewmat, (4, 4), device)
    _check_tensor("K", K, (3, 3), device)
    if background is None:
        background = _zero_input((3,), device)  # read only (the kernels', and no gradient flows to it)
    for name, v in (("width", width), ("height", height)):
        if not isinstance(v, int) or v <= 0:
            _fail(name, f"must be a positive int, got {v!r}")
    backdrop = None  # a per-pixel background, composited after the kernels (which take one colour)
    if isinstance(background, torch.Tensor) and background.dim() == 3:
        _check_tensor("background", background, (height, width, 3), device)
        backdrop, background = background, _zero_input((3,), device)
    _check_tensor("background", background, (3,), device)
    if not (0.0 < alpha_max < 1.0):
        _fail("alpha_max", f"must lie in (0, 1), got {alpha_max}")
    if not (0.0 < near_plane < far_plane):
        _fail("near_plane", f"must satisfy 0 < near_plane < far_plane, got {near_plane}, {far_plane}")

    means, quats, scales, opacities, colors = (_f32(means), _f32(quats), _f32(scales), _f32(opacities), _f32(colors))
    viewmat, K, background = (_f32(viewmat.detach() if viewmat.requires_grad else viewmat),
                              _f32(K.detach() if K.requires_grad else K),
                              _f32(background.detach() if background.requires_grad else background))
    if check_finite:
        _check_finite(dict(means=means, quats=quats, scales=scales, opacities=opacities, colors=colors,
                           viewmat=viewmat, K=K, background=background if backdrop is None else backdrop))
        if n and bool((scales < 0).any()):
            _fail("scales", "must be >= 0 (they are standard deviations, not log-scales)")
        if n and bool((quats.detach().norm(dim=-1) == 0).any()):
            _fail("quats", "contains a zero quaternion, which has no rotation")

    dev = device_of(means)
    stream = launch_stream(means)  # torch's current stream: every launch of the render, its backward's too
    means2d, conics, depths, opac_eff, radii, tiles_touched = _Project.apply(
        means, quats, scales, opacities, viewmat, K, width, height, eps2d, near_plane, far_plane, antialiased,
        dev, stream
    )
    if means2d.requires_grad:
        means2d.retain_grad()
    if sh_degree is not None:
        R, t = viewmat[:3, :3], viewmat[:3, 3]
        campos = -(R.T @ t)
        rgb = _SHColors.apply(colors, means, campos.contiguous(), radii, sh_degree, dev, stream)
    else:
        rgb = colors
    info: list = []  # receives the intersection count
    image, depth, alpha = _Composite.apply(
        means2d, conics, opac_eff, rgb, depths, background, radii, tiles_touched, width, height, alpha_max,
        deterministic, near_plane, isect_capacity, info, dev, stream
    )
    total, needed = info[0], info[1] if len(info) > 1 else None
    if backdrop is not None:
        image = image + (1.0 - alpha)[..., None] * backdrop.float()
    return RenderOutput(image, depth, alpha, means2d, radii, depths, total, needed)


def count_intersections(means, quats, scales, opacities, viewmat, K, width: int, height: int, *,
                        near_plane: float = 0.01, far_plane: float = 1e10, eps2d: float = 0.3,
                        antialiased: bool = False, read: bool = True) -> int | torch.Tensor:
    """How many (Gaussian, tile) pairs ``rasterize`` of the same inputs (and the same keyword arguments) sorts: its
    ``n_intersections`` without ``isect_capacity``, from the projection alone and one host read. What a
    fixed-capacity render (``isect_capacity``) must hold. ``read`` False: the count as a device scalar (int64),
    not read (several counts read in one transfer)."""
    with torch.no_grad():
        means, quats, scales, opacities = (t.detach().float().contiguous() for t in (means, quats, scales, opacities))
        viewmat, K = (t.detach().float().contiguous() for t in (viewmat, K))
        if means.shape[0] == 0:
            return 0 if read else torch.zeros((), dtype=torch.int64, device=means.device)
        tiles_touched = _project(means, quats, scales, opacities, viewmat, K, width, height, eps2d, near_plane,
                                 far_plane, antialiased, device_of(means), launch_stream(means))[5]
        total = tiles_touched.sum(dtype=torch.int64)
        return int(total) if read else total


def means2d_grad_norm(out: RenderOutput, width: int, height: int) -> torch.Tensor:
    """Per-Gaussian norm of dL/d(means2d) in normalised device units (gsplat's densification statistic).
    Needs ``out.means2d.grad`` (set after backward; ``rasterize`` retains it)."""
    g = out.means2d.grad
    if g is None:
        raise RuntimeError("means2d has no gradient: call backward() on a loss of this render first")
    return (g * _ndc_scale(width, height, g.device)).norm(dim=-1)


@functools.cache  # never evicted: a CUDA graph of a training step reads it where it is
def _ndc_scale(width: int, height: int, device: torch.device) -> torch.Tensor:
    """[width / 2, height / 2] on ``device``, made once (a copy from the host cannot be part of a CUDA graph)."""
    return torch.tensor([width / 2.0, height / 2.0], device=device)


def eval_sh(coeffs: torch.Tensor, dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """Colour max(0, SH(dirs) + 0.5) of [N, K, 3] coefficients along [N, 3] directions (differentiable)."""
    if coeffs.dim() != 3 or coeffs.shape[-1] != 3 or coeffs.shape[1] < (degree + 1) ** 2:
        raise ValueError(f"eval_sh: argument 'coeffs' must be [N, >= {(degree + 1) ** 2}, 3], got {list(coeffs.shape)}")
    if dirs.shape != (coeffs.shape[0], 3):
        raise ValueError(f"eval_sh: argument 'dirs' must be [{coeffs.shape[0]}, 3], got {list(dirs.shape)}")
    radii = torch.ones(dirs.shape[0], 2, device=dirs.device, dtype=torch.int32)
    origin = torch.zeros(3, device=dirs.device)
    return _SHColors.apply(coeffs.float().contiguous(), dirs.float().contiguous(), origin, radii, degree)
