"""Front-to-back alpha compositing of depth-sorted Gaussians per 16x16 tile, and its hand-written backward.

One thread per pixel; threads are numbered tile-major (256 consecutive threads = one tile), so a CUDA
block of 256 threads is one image tile and every 32-lane warp shares one tile's Gaussian list. The CUDA
backward sums each Gaussian's gradient over a warp with shuffles before adding it once (as gsplat does;
``accumulate_grad_scattered``); the CPU kernels (one thread each) add theirs directly (``accumulate_grad``).

Constants (3D-GS / gsplat): a Gaussian is skipped where alpha < 1/255; alpha is clamped at ``alpha_max``
(0.99 in 3D-GS, 0.999 in gsplat); a pixel stops before the Gaussian that would bring its transmittance
to <= 1e-4. Outputs: colour over the background, expected depth sum(w_i z_i) / A (0 where A <= 1e-6),
accumulated alpha A = 1 - T.
Only Warp code lives here.
"""

import warp as wp

from warpgs.kernels import binning as kb

# fast_math: CUDA fast intrinsics (__expf, approximate division), as gsplat builds with -use_fast_math.
wp.set_module_options({"enable_backward": False, "fast_math": True})

TILE_SIZE = 16  # CUDA: one 256-thread block per tile
BLOCK = TILE_SIZE * TILE_SIZE
# The CPU walks each pixel's tile list one Gaussian after another, so a smaller tile means fewer
# (pixel, Gaussian) pairs whose Gaussian does not reach the pixel: 8x8 tiles take about 40% fewer pairs
# than 16x16 on a typical scene, for about 2.5x the (cheap) tile-Gaussian intersections to sort.
TILE_SIZE_CPU = 8
ALPHA_MIN = wp.constant(1.0 / 255.0)
T_MIN = wp.constant(1.0e-4)
DEPTH_ALPHA_MIN = wp.constant(1.0e-6)  # below this accumulated alpha the expected depth is reported as 0
# Beyond this Mahalanobis half-distance alpha = opacity exp(-sigma) < 1/255 for any opacity <= 1
# (ln 255 = 5.5413): the loops evaluate exp only below it. Most pairs of a tile lie beyond, and there
# exp(-sigma) is often subnormal, which is slow on x86 CPUs. Same result either way.
SIGMA_SKIP = wp.constant(5.55)


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    int r = v;
    for (int o = 16; o > 0; o >>= 1) r = max(r, __shfl_xor_sync(0xffffffff, r, o));
    return r;
#else
    return v;
#endif
"""
)
def warp_max(v: int) -> int: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    return __any_sync(0xffffffff, v != 0) ? 1 : 0;
#else
    return v;
#endif
"""
)
def warp_any(v: int) -> int: ...


@wp.func
def pixel_of_thread(tid: int, tiles_x: int, tile_size: int):
    block = tile_size * tile_size
    tile = tid / block
    local = tid - tile * block
    ty = tile / tiles_x
    tx = tile - ty * tiles_x
    return tile, tx * tile_size + local % tile_size, ty * tile_size + local / tile_size


# One Gaussian as the compositing loops read it, (x, y, conic a, b, c, opacity, r, g, b, depth), packed (by
# ``binning.emit_intersections``) so that a tile's loop issues one gathered load per Gaussian instead of five.
splat = kb.splat


# The compositing kernels' arguments, one struct per role, shared by all of them (the CPU's and CUDA's); a launch
# passes each as the tuple of its fields, torch tensors for the arrays (``warpgs._warp.Launcher``: no copies).
@wp.struct
class Tiles:
    """What every compositing kernel reads of a render: each tile's [start, end) in ``gauss_ids`` (``ranges``
    [n_tiles, 2]; the CUDA forward writes them), the tiles' depth-sorted Gaussian ids, the packed splats [N], the
    background colour (a one-element array), the image size in pixels, the tiles across, and the alpha clamp."""

    ranges: wp.array2d(dtype=wp.int32)
    gauss_ids: wp.array(dtype=wp.int32)
    splats: wp.array(dtype=splat)
    background: wp.array(dtype=wp.vec3)
    width: int
    height: int
    tiles_x: int
    alpha_max: float


@wp.struct
class Image:
    """The forward's outputs per pixel [H * W] (``store_pixel``)."""

    color: wp.array(dtype=wp.vec3)
    depth: wp.array(dtype=float)
    alpha: wp.array(dtype=float)
    last_count: wp.array(dtype=wp.int32)


@wp.struct
class PixelGrads:
    """What the backward reads per pixel [H * W]: the forward's depth, alpha and count composited, and the loss's
    gradients of the colour, depth and alpha (``pixel_grad_inputs``)."""

    depth: wp.array(dtype=float)
    alpha: wp.array(dtype=float)
    last_count: wp.array(dtype=wp.int32)
    v_color: wp.array(dtype=wp.vec3)
    v_depth: wp.array(dtype=float)
    v_alpha: wp.array(dtype=float)


@wp.struct
class SplatGrads:
    """The backward's per-Gaussian gradients [N], accumulated with atomics (zero-initialised by the caller): floats,
    or with ``fixed`` fixed-point integers in ``v_fixed`` [N, 10] (``accumulate_grad``). ``with_depth`` = 0: the
    loss does not use the depth (``splat_backward``). The CUDA backward's variants fix both flags when their code is
    generated and ignore these."""

    fixed: int
    with_depth: int
    v_fixed: wp.array2d(dtype=wp.int64)
    v_means2d: wp.array(dtype=wp.vec2)
    v_conics: wp.array(dtype=wp.vec3)
    v_opacities: wp.array(dtype=float)
    v_colors: wp.array(dtype=wp.vec3)
    v_depths: wp.array(dtype=float)


@wp.func
def splat_sigma(s: splat, px: float, py: float) -> float:
    dx = s[0] - px
    dy = s[1] - py
    return 0.5 * (s[2] * dx * dx + s[4] * dy * dy) + s[3] * dx * dy


# what composite_splat did with a Gaussian
SKIPPED = wp.constant(0)  # alpha < 1/255 (or sigma < 0): the pixel goes on behind it
COMPOSITED = wp.constant(1)
SATURATED = wp.constant(2)  # it would bring T to <= 1e-4: not composited, the pixel stops before it


@wp.func
def composite_splat(s: splat, px: float, py: float, alpha_max: float, T: float, C: wp.vec3, D: float):
    """One Gaussian of a pixel, front to back: -> (SKIPPED / COMPOSITED / SATURATED, T, C, D), where C and
    D are the colour and depth sums in front of it and T the transmittance; T, C, D change only when
    COMPOSITED."""
    sigma = splat_sigma(s, px, py)
    status = SKIPPED
    alpha = float(0.0)
    if sigma >= 0.0 and sigma <= SIGMA_SKIP:
        alpha = wp.min(alpha_max, s[5] * wp.exp(-sigma))
    if alpha >= ALPHA_MIN:
        next_T = T * (1.0 - alpha)
        if next_T <= T_MIN:
            status = SATURATED
        else:
            w = alpha * T
            C = C + w * wp.vec3(s[6], s[7], s[8])
            D = D + w * s[9]
            T = next_T
            status = COMPOSITED
    return status, T, C, D


# per-Gaussian gradient of one pixel: means2d (2) | conic (3) | opacity | colour (3) | depth
grad10 = wp.types.vector(length=10, dtype=wp.float32)


@wp.func
def pixel_grad_inputs(inside: bool, pix: int, start: int, pixels: PixelGrads):
    """-> (Gaussians composited, final T, dL/dcolour, dL/d(accumulated depth D = sum w_i z_i), dL/dalpha)."""
    last = start
    T_final = float(1.0)
    vC = wp.vec3(0.0)
    vD = float(0.0)
    vA = float(0.0)
    if inside:
        last = pixels.last_count[pix]
        A = pixels.alpha[pix]
        T_final = 1.0 - A
        vC = pixels.v_color[pix]
        vA = pixels.v_alpha[pix]
        if A > DEPTH_ALPHA_MIN:
            # expected depth E = D / A: dL/dD = v_E / A, dL/dA += -v_E E / A
            vE = pixels.v_depth[pix]
            vD = vE / A
            vA = vA - vE * pixels.depth[pix] / A
    return last, T_final, vC, vD, vA


@wp.func
def splat_backward(s: splat, px: float, py: float, alpha_max: float, T: float, S_c: wp.vec3, S_d: float,
                   vC: wp.vec3, vD: float, vA_bg: float, T_final: float, with_depth: int):
    """One Gaussian of a pixel, back to front: -> (valid, T in front of it, S_c, S_d, its gradient).
    S_c, S_d: sums over the Gaussians behind of w_j c_j and w_j z_j; vA_bg = dL/dA - background . dL/dC.
    ``with_depth`` = 0 (the loss does not use the depth, vD = 0): the depth terms, all zero, are skipped; the
    other sums are the same floats in the same order."""
    g = grad10()
    dx = s[0] - px
    dy = s[1] - py
    sigma = 0.5 * (s[2] * dx * dx + s[4] * dy * dy) + s[3] * dx * dy
    if sigma < 0.0 or sigma > SIGMA_SKIP:  # alpha < 1/255 (see SIGMA_SKIP)
        return int(0), T, S_c, S_d, g
    o = s[5]
    vis = wp.exp(-sigma)
    alpha = wp.min(alpha_max, o * vis)
    if alpha < ALPHA_MIN:
        return int(0), T, S_c, S_d, g
    ra = 1.0 / (1.0 - alpha)
    T = T * ra
    fac = alpha * T
    c = wp.vec3(s[6], s[7], s[8])
    z = s[9]
    v_alpha = float(0.0)
    if with_depth != 0:
        v_alpha = (wp.dot(c, vC) * T - wp.dot(S_c, vC) * ra) + (z * T - S_d * ra) * vD + T_final * ra * vA_bg
        S_d = S_d + fac * z
    else:
        v_alpha = (wp.dot(c, vC) * T - wp.dot(S_c, vC) * ra) + T_final * ra * vA_bg
    S_c = S_c + fac * c
    v_sigma = float(0.0)
    vop = float(0.0)
    if o * vis <= alpha_max:  # the alpha clamp passes no gradient
        v_sigma = -o * vis * v_alpha
        vop = vis * v_alpha
    g = grad10(v_sigma * (s[2] * dx + s[3] * dy), v_sigma * (s[3] * dx + s[4] * dy),
               0.5 * v_sigma * dx * dx, v_sigma * dx * dy, 0.5 * v_sigma * dy * dy, vop,
               fac * vC[0], fac * vC[1], fac * vC[2], fac * vD)
    return int(1), T, S_c, S_d, g


# Deterministic accumulation: each warp's sum is rounded to a 64-bit fixed-point number (2^-40 steps)
# and added with an integer atomic, so the total does not depend on the order the warps arrive in
# (float atomics do: two runs with one seed drift apart on CUDA). Terms are clamped to +-2^20 first,
# so no sum of them can overflow; gradients of a mean-reduced image loss are many orders smaller.
FIXED_SCALE = wp.constant(1099511627776.0)  # 2^40
FIXED_CLAMP = wp.constant(1048576.0)  # 2^20


@wp.func
def to_fixed(v: float) -> wp.int64:
    return wp.int64(wp.round(wp.clamp(v, -FIXED_CLAMP, FIXED_CLAMP) * FIXED_SCALE))


@wp.func
def accumulate_grad(valid: int, gid: int, g: grad10, grads: SplatGrads):
    """Adds a Gaussian's gradient from a CPU kernel (one thread: nothing to sum over a warp; the CUDA backward's
    is ``accumulate_grad_scattered``), as floats or (``fixed``) as fixed-point integers into ``v_fixed`` [N, 10]."""
    if valid != 0:
        if grads.fixed != 0:
            for c in range(9):
                wp.atomic_add(grads.v_fixed, gid, c, to_fixed(g[c]))
            if grads.with_depth != 0:
                wp.atomic_add(grads.v_fixed, gid, 9, to_fixed(g[9]))
        else:
            wp.atomic_add(grads.v_means2d, gid, wp.vec2(g[0], g[1]))
            wp.atomic_add(grads.v_conics, gid, wp.vec3(g[2], g[3], g[4]))
            wp.atomic_add(grads.v_opacities, gid, g[5])
            wp.atomic_add(grads.v_colors, gid, wp.vec3(g[6], g[7], g[8]))
            if grads.with_depth != 0:
                wp.atomic_add(grads.v_depths, gid, g[9])


# The CUDA backward's accumulation, as one native function: the warp's ten sums by a reduce-scatter instead of
# ten all-reduces. An all-reduce sums each value over the warp with five xor shuffles (50 shuffles a Gaussian,
# and the shuffle unit, a quarter of the FP32 rate, was what the backward waited on with them); here the first
# xor round swaps halves of a 16-slot vector (8 shuffles), the next a quarter (4), then 2, 1 and 1: 16 shuffles,
# after which lane l holds the warp's sum of value l / 2. Each value goes through the same pairs in the same
# order as in that all-reduce (own partial + partner's, partners lane ^ 16, ^ 8, ^ 4, ^ 2, ^ 1), so the sums
# are the same floats. The atomics are then one instruction of nine or ten lanes (the even lanes of the first
# ten) instead of nine or ten in a row from lane 0; in fixed point the ten integers of a Gaussian are
# contiguous ([N, 10] int64), so they go out as one request. Every lane must call it.
@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    const unsigned lane = threadIdx.x & 31;
    float a[16];
    #pragma unroll
    for (int j = 0; j < 10; ++j) a[j] = g.c[j];
    #pragma unroll
    for (int j = 10; j < 16; ++j) a[j] = 0.0f;
    // 16 -> 8 -> 4 -> 2 -> 1 slots: the lanes with the round's bit set keep the upper half
#define WARPGS_HALVE(HALF, BIT) { \
        const bool up = (lane & (BIT)) != 0; \
        _Pragma("unroll") for (int j = 0; j < (HALF); ++j) { \
            const float send = up ? a[j] : a[j + (HALF)]; \
            const float keep = up ? a[j + (HALF)] : a[j]; \
            a[j] = keep + __shfl_xor_sync(0xffffffff, send, (BIT)); \
        } }
    WARPGS_HALVE(8, 16)
    WARPGS_HALVE(4, 8)
    WARPGS_HALVE(2, 4)
    WARPGS_HALVE(1, 2)
#undef WARPGS_HALVE
    a[0] = a[0] + __shfl_xor_sync(0xffffffff, a[0], 1);
    const int idx = (int)(lane >> 1);  // which of the ten sums this lane holds (each is held by two lanes)
    if ((lane & 1) == 0 && idx < (with_depth != 0 ? 10 : 9)) {
        // the byte address of Gaussian gid's row of gradient array A
#define WARPGS_ROW(A) ((char*)grads.A.data + (size_t)gid * grads.A.strides[0])
        if (fixed != 0) {
            const float v = fminf(fmaxf(a[0], -FIXED_CLAMP), FIXED_CLAMP) * FIXED_SCALE;  // to_fixed
            long long* row = (long long*)WARPGS_ROW(v_fixed);
            atomicAdd((unsigned long long*)(row + idx), (unsigned long long)(long long)roundf(v));
        } else {
            float* dst;
            if (idx < 2) dst = (float*)WARPGS_ROW(v_means2d) + idx;
            else if (idx < 5) dst = (float*)WARPGS_ROW(v_conics) + (idx - 2);
            else if (idx == 5) dst = (float*)WARPGS_ROW(v_opacities);
            else if (idx < 9) dst = (float*)WARPGS_ROW(v_colors) + (idx - 6);
            else dst = (float*)WARPGS_ROW(v_depths);
            atomicAdd(dst, a[0]);
        }
#undef WARPGS_ROW
    }
#endif
""".replace("FIXED_CLAMP", f"{float(FIXED_CLAMP)!r}f").replace("FIXED_SCALE", f"{float(FIXED_SCALE)!r}f")
)
def accumulate_grad_scattered(gid: int, g: grad10, fixed: int, with_depth: int, grads: SplatGrads): ...


@wp.kernel
def fixed_to_grads(grads: SplatGrads):
    """The fixed-point sums of ``accumulate_grad`` (``v_fixed``) as the float gradients (one thread per Gaussian)."""
    i = wp.tid()
    inv = 1.0 / FIXED_SCALE
    v = grads.v_fixed
    grads.v_means2d[i] = wp.vec2(float(v[i, 0]) * inv, float(v[i, 1]) * inv)
    grads.v_conics[i] = wp.vec3(float(v[i, 2]) * inv, float(v[i, 3]) * inv, float(v[i, 4]) * inv)
    grads.v_opacities[i] = float(v[i, 5]) * inv
    grads.v_colors[i] = wp.vec3(float(v[i, 6]) * inv, float(v[i, 7]) * inv, float(v[i, 8]) * inv)
    grads.v_depths[i] = float(v[i, 9]) * inv


@wp.func
def store_pixel(pix: int, C: wp.vec3, D: float, T: float, n: int, background: wp.vec3, image: Image):
    """Colour over the background, expected depth D / A (0 where A <= 1e-6), alpha A = 1 - T, and the
    count of Gaussians composited (where the backward pass starts)."""
    A = 1.0 - T
    image.color[pix] = C + T * background
    image.depth[pix] = wp.where(A > DEPTH_ALPHA_MIN, D / A, 0.0)
    image.alpha[pix] = A
    image.last_count[pix] = n


# ----------------------------------------------------------------------------------------------------
# The backward is one definition with two variants, picked when the code is generated: the CPU variant walks the
# tile's list one Gaussian after another; the CUDA variant has each 256-thread block (one tile) load the tile's
# Gaussians into shared memory in batches of 256, one per thread, then every thread works from shared memory (as
# gsplat does). The CUDA variant needs cooperating threads, which Warp's CPU backend does not have (one thread
# per block), so the CPU runs the other; the CUDA tests check it against the same torch oracle. The forward's CPU
# variant is ``rasterize_fwd`` below (per pixel), its CUDA one ``rasterize_fwd_cuda`` further down. The CPU
# variants (tiles TILE_SIZE_CPU wide) are the CUDA kernels' per-pixel logic without the shared memory: the
# library composites on the CPU with the row kernels further down, and tests check those against them (same
# images) and both against the oracle.

splat_id = wp.types.vector(length=11, dtype=wp.float32)  # a splat and its Gaussian id (as float bits)


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    // 12 floats a slot (splat, id bits, padding) as three float4: a read is three 128-bit shared loads
    // (broadcast: every lane of a warp reads one slot) instead of eleven 32-bit ones
    __shared__ float4 warpgs_batch[256 * 3];
    wp::vec_t<11, wp::float32> out;
    if (store) {
        warpgs_batch[slot * 3] = make_float4(s.c[0], s.c[1], s.c[2], s.c[3]);
        warpgs_batch[slot * 3 + 1] = make_float4(s.c[4], s.c[5], s.c[6], s.c[7]);
        warpgs_batch[slot * 3 + 2] = make_float4(s.c[8], s.c[9], __int_as_float(g), 0.0f);
    } else {
        const float4 a = warpgs_batch[slot * 3];
        const float4 b = warpgs_batch[slot * 3 + 1];
        const float4 c = warpgs_batch[slot * 3 + 2];
        out.c[0] = a.x; out.c[1] = a.y; out.c[2] = a.z; out.c[3] = a.w;
        out.c[4] = b.x; out.c[5] = b.y; out.c[6] = b.z; out.c[7] = b.w;
        out.c[8] = c.x; out.c[9] = c.y; out.c[10] = c.z;
    }
    return out;
#else
    return wp::vec_t<11, wp::float32>();
#endif
"""
)
def batch_splat(store: int, slot: int, s: splat, g: int) -> splat_id: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    return __float_as_int(f);
#else
    return 0;
#endif
"""
)
def float_bits(f: float) -> int: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    return __syncthreads_count(v);
#else
    return v;
#endif
"""
)
def block_count(v: int) -> int: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    __syncthreads();
#endif
"""
)
def block_sync(): ...


@wp.func
def stored_splat(sg: splat_id) -> splat:
    """The splat part of a shared-memory entry read by ``batch_splat``."""
    return splat(sg[0], sg[1], sg[2], sg[3], sg[4], sg[5], sg[6], sg[7], sg[8], sg[9])


# Registers (Nsight Compute on an H100, 138,766 Gaussians at 648x420): the CUDA backward took 80 a thread, so
# 3 blocks of 256 fit an SM (37.5% occupancy), the forward 56 (50%). Each backward is compiled for one
# (fixed, with_depth) pair, the two known when the code is generated, which takes the branches and their live
# values out (64 registers without the depth, 70 with it, in a local NVRTC build), and carries launch bounds
# of at most 64 registers (4 blocks an SM; no spills): 864-874 us became 809-828 us on the H100. Bounding the
# forward to 48 (5 blocks) made it slower there (377-395 -> 405-420 us), so it has none.
# (tests/test_rasterizer.py checks the variants against the oracle on CUDA.)
BWD_LAUNCH_BOUNDS = (BLOCK, 4)


def _compositing_kernels(cuda: bool, fixed_variant: int = -1, depth_variant: int = -1):
    """The CPU's per-pixel forward kernel (colour, depth, alpha and the count composited per pixel) and the CPU or
    CUDA backward kernel (per-Gaussian gradients from the pixels' output gradients); on CUDA the backward for
    ``fixed_variant`` / ``depth_variant`` (0 or 1: the backward's ``fixed`` / ``with_depth``, fixed when the code is
    generated; ``SplatGrads``'s flags are then ignored), and no forward (the CUDA forward is ``rasterize_fwd_cuda``)."""
    tile_size = TILE_SIZE if cuda else TILE_SIZE_CPU
    static_flags = fixed_variant >= 0

    def rasterize_fwd(tiles: Tiles, image: Image, part: int, n_parts: int):
        tid = wp.tid() * n_parts + part  # the CPU's interleaved parts (see PARTS_NOTE)
        if tid >= tiles.ranges.shape[0] * wp.static(tile_size * tile_size):
            return
        tile, x, y = pixel_of_thread(tid, tiles.tiles_x, wp.static(tile_size))
        width = tiles.width
        inside = x < width and y < tiles.height
        px = float(x) + 0.5
        py = float(y) + 0.5
        start = tiles.ranges[tile, 0]
        end = tiles.ranges[tile, 1]
        T = float(1.0)
        C = wp.vec3(0.0)
        D = float(0.0)
        n = start
        if inside:
            for k in range(start, end):
                status, T, C, D = composite_splat(tiles.splats[tiles.gauss_ids[k]], px, py, tiles.alpha_max, T, C, D)
                if status == SATURATED:
                    break
                if status == COMPOSITED:
                    n = k + 1
        if inside:
            store_pixel(y * width + x, C, D, T, n, tiles.background[0], image)

    def rasterize_bwd(tiles: Tiles, pixels: PixelGrads, grads: SplatGrads, part: int, n_parts: int):
        # No early return on CUDA: every lane of a warp must reach the shuffles below.
        fixed = grads.fixed
        with_depth = grads.with_depth
        if wp.static(static_flags):
            fixed = wp.static(fixed_variant)
            with_depth = wp.static(depth_variant)
        tid = wp.tid()
        if not wp.static(cuda):  # the CPU's interleaved parts (see PARTS_NOTE)
            tid = tid * n_parts + part
            if tid >= tiles.ranges.shape[0] * wp.static(tile_size * tile_size):
                return
        tile, x, y = pixel_of_thread(tid, tiles.tiles_x, wp.static(tile_size))
        width = tiles.width
        height = tiles.height
        inside = x < width and y < height
        start = tiles.ranges[tile, 0]
        pix = wp.min(y, height - 1) * width + wp.min(x, width - 1)
        px = float(x) + 0.5
        py = float(y) + 0.5
        alpha_max = tiles.alpha_max

        last, T_final, vC, vD, vA = pixel_grad_inputs(inside, pix, start, pixels)
        vA_bg = vA - wp.dot(tiles.background[0], vC)
        T = T_final
        S_c = wp.vec3(0.0)
        S_d = float(0.0)
        warp_last = warp_max(last)

        if wp.static(cuda):
            lane = tid % BLOCK
            end = tiles.ranges[tile, 1]
            n_batches = (end - start + BLOCK - 1) / BLOCK
            for b in range(n_batches):
                block_sync()
                k_hi = end - 1 - b * BLOCK  # batches run back to front
                if k_hi - lane >= start:
                    g = tiles.gauss_ids[k_hi - lane]
                    batch_splat(1, lane, tiles.splats[g], g)
                block_sync()
                count = wp.min(BLOCK, k_hi - start + 1)
                t0 = wp.max(0, k_hi - warp_last + 1)  # skip Gaussians behind every pixel of this warp
                for t in range(t0, count):
                    k = k_hi - t
                    sg = batch_splat(0, t, splat(), 0)
                    s = stored_splat(sg)
                    g = float_bits(sg[10])
                    valid = int(0)
                    grad = grad10()
                    if inside and k < last:
                        valid, T, S_c, S_d, grad = splat_backward(s, px, py, alpha_max, T, S_c, S_d, vC, vD, vA_bg,
                                                                  T_final, with_depth)
                    if warp_any(valid) != 0:  # the same for every lane of the warp
                        accumulate_grad_scattered(g, grad, fixed, with_depth, grads)
        else:
            g_nxt = int(0)
            s_nxt = splat()
            if warp_last > start:
                g_nxt = tiles.gauss_ids[warp_last - 1]
                s_nxt = tiles.splats[g_nxt]
            for j in range(warp_last - start):
                k = warp_last - 1 - j
                g = g_nxt
                s = s_nxt
                if k > start:  # prefetch the next (nearer) Gaussian
                    g_nxt = tiles.gauss_ids[k - 1]
                    s_nxt = tiles.splats[g_nxt]
                valid = int(0)
                grad = grad10()
                if inside and k < last:
                    valid, T, S_c, S_d, grad = splat_backward(s, px, py, alpha_max, T, S_c, S_d, vC, vD, vA_bg, T_final,
                                                              with_depth)
                accumulate_grad(valid, g, grad, grads)

    if not cuda:
        return wp.kernel(rasterize_fwd, name="rasterize_fwd"), wp.kernel(rasterize_bwd, name="rasterize_bwd")
    return None, wp.kernel(rasterize_bwd, name=f"rasterize_bwd_cuda_f{fixed_variant}d{depth_variant}",
                           launch_bounds=BWD_LAUNCH_BOUNDS)


rasterize_fwd, rasterize_bwd = _compositing_kernels(cuda=False)
# the CUDA backward for each (fixed, with_depth): rasterize_bwd_cuda[fixed][with_depth]
rasterize_bwd_cuda = [[_compositing_kernels(True, f, d)[1] for d in (0, 1)] for f in (0, 1)]


# ----------------------------------------------------------------------------------------------------
# The CUDA forward (it replaced the CUDA variant of ``rasterize_fwd`` above, over ``batch_splat``):
# a batch of a tile's Gaussians is composited by one native function, laid out for the forward alone. A slot is
# two shared-memory loads, (x, y, conic a, b) and (conic c, opacity), before the pixel knows whether the Gaussian
# reaches it; the colour and depth, (r, g, b, z), are a third load made only where it does (most pairs of a
# tile do not), as gsplat reads its colours only there. alpha = min(alpha_max, opacity exp(-sigma)) is evaluated
# for every pair, and a pair with sigma < 0, sigma > SIGMA_SKIP or alpha < 1/255 is skipped: the Warp loops' test
# (the backward's too), so the sums are the same floats in the same order (on an H100 the forward took 170 us
# instead of 263 us at 138,766 Gaussians, 648x420, where gsplat's takes 207 us: git show e26aeea:bench/results/s24).
# Its first version left out the SIGMA_SKIP test (gsplat's, where alpha < 1/255 decides alone): that is the same
# only for opacities up to 1, and DropGaussian's survivors (opacity x 1 / (1 - p)) and opacity noise exceed 1. Such
# a pair past SIGMA_SKIP was composited by this forward and skipped by the backward, so their transmittances
# disagreed; a few pixels per training render differed from the Warp forward's (found with
# bench/diagnostics/rasterizer_commits.py on DTU scan65's training renders, steps 71-75).
# state: (T, colour r, g, b, depth sum, count as int bits, done, 0) in and out.
fwd_state = wp.types.vector(length=8, dtype=wp.float32)


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    __shared__ float4 warpgs_fwd_geom[256];
    __shared__ float2 warpgs_fwd_opac[256];
    __shared__ float4 warpgs_fwd_rgbz[256];
    if (load) {
        warpgs_fwd_geom[lane] = make_float4(s.c[0], s.c[1], s.c[2], s.c[3]);
        warpgs_fwd_opac[lane] = make_float2(s.c[4], s.c[5]);
        warpgs_fwd_rgbz[lane] = make_float4(s.c[6], s.c[7], s.c[8], s.c[9]);
    }
    __syncthreads();
    float T = state.c[0], R = state.c[1], G = state.c[2], B = state.c[3], D = state.c[4];
    int n = __float_as_int(state.c[5]);
    bool done = state.c[6] != 0.0f;
    for (int t = 0; t < count && !done; ++t) {
        const float4 q = warpgs_fwd_geom[t];
        const float2 o = warpgs_fwd_opac[t];
        const float dx = q.x - px;
        const float dy = q.y - py;
        const float sigma = 0.5f * (q.z * dx * dx + o.x * dy * dy) + q.w * dx * dy;
        const float alpha = fminf(alpha_max, o.y * __expf(-sigma));
        if (sigma < 0.0f || sigma > SIGMA_SKIP_F || alpha < ALPHA_MIN_F) continue;
        const float next_T = T * (1.0f - alpha);
        if (next_T <= T_MIN_F) { done = true; break; }
        const float4 c = warpgs_fwd_rgbz[t];
        const float w = alpha * T;
        R = R + w * c.x;
        G = G + w * c.y;
        B = B + w * c.z;
        D = D + w * c.w;
        T = next_T;
        n = k0 + t + 1;
    }
    __syncthreads();
    wp::vec_t<8, wp::float32> out;
    out.c[0] = T; out.c[1] = R; out.c[2] = G; out.c[3] = B; out.c[4] = D;
    out.c[5] = __int_as_float(n); out.c[6] = done ? 1.0f : 0.0f; out.c[7] = 0.0f;
    return out;
#else
    return state;
#endif
""".replace("ALPHA_MIN_F", f"{float(ALPHA_MIN)!r}f").replace("T_MIN_F", f"{float(T_MIN)!r}f").replace(
    "SIGMA_SKIP_F", f"{float(SIGMA_SKIP)!r}f")
)
def composite_batch(load: int, lane: int, s: splat, count: int, k0: int, px: float, py: float, alpha_max: float,
                    state: fwd_state) -> fwd_state: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
    return __int_as_float(v);
#else
    return 0.0f;
#endif
"""
)
def int_bits(v: int) -> float: ...


@wp.kernel
def rasterize_fwd_cuda(keys: wp.array(dtype=wp.int64), count: int, shift: int, tiles: Tiles, image: Image):
    """The CUDA forward: one 256-thread block per tile. Each thread finds its tile's [start, end) in the sorted
    ``keys[:count]`` (``binning.tile_range``; the block's first thread writes it to ``tiles.ranges`` for the
    backward, so no kernel of its own and no cleared buffer are needed for them); the block loads the tile's
    Gaussians in batches of 256, one per thread, and each batch is composited by ``composite_batch``."""
    tid = wp.tid()
    tile, x, y = pixel_of_thread(tid, tiles.tiles_x, TILE_SIZE)
    width = tiles.width
    inside = x < width and y < tiles.height
    start, end = kb.tile_range(keys, count, shift, tile)
    lane = tid % BLOCK
    if lane == 0:
        tiles.ranges[tile, 0] = start
        tiles.ranges[tile, 1] = end
    state = fwd_state(1.0, 0.0, 0.0, 0.0, 0.0, int_bits(start), 0.0, 0.0)
    if not inside:
        state[6] = 1.0
    n_batches = (end - start + BLOCK - 1) / BLOCK
    for b in range(n_batches):
        if block_count(int(state[6])) == BLOCK:  # every pixel of the tile is saturated
            break
        k0 = start + b * BLOCK
        load = int(0)
        s = splat()
        if k0 + lane < end:
            load = 1
            s = tiles.splats[tiles.gauss_ids[k0 + lane]]
        state = composite_batch(load, lane, s, wp.min(BLOCK, end - k0), k0, float(x) + 0.5, float(y) + 0.5,
                                tiles.alpha_max, state)
    if inside:
        store_pixel(y * width + x, wp.vec3(state[1], state[2], state[3]), state[4], state[0],
                    float_bits(state[5]), tiles.background[0], image)


def tile_size_for(device: str) -> int:
    """The tile edge the compositing kernels of ``device`` ('cpu' or 'cuda:N') expect."""
    return TILE_SIZE_CPU if device == "cpu" else TILE_SIZE



# PARTS_NOTE: Warp's CPU backend runs a kernel on one thread. The compositing kernels take (part, n_parts):
# on the CPU, launch ``part`` of ``n_parts`` runs every n_parts-th thread of the whole launch (tile rows,
# interleaved, so the parts cost about the same), and the caller runs the parts on threads of its own
# (ctypes lets go of the GIL while a kernel runs). Each part's backward adds its gradients into buffers of
# its own, summed in part order afterwards, so the result does not depend on how many cores ran them.
# CUDA ignores both (one launch, part 0 of 1).


def compositing_threads(device: str, n_tiles: int) -> int:
    """The launch size of ``device``'s compositing kernels: a thread per pixel on CUDA, per tile row on the CPU
    (all parts together)."""
    return n_tiles * (TILE_SIZE_CPU if device == "cpu" else BLOCK)
