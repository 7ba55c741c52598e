"""The CPU's compositing kernels: one thread per tile row of ``TILE_SIZE_CPU`` pixels (``warpgs.kernels.rasterize``
holds the per-pixel arithmetic they share with the Warp and CUDA kernels, and PARTS_NOTE on their launch parts).
Only Warp code lives here.
"""

import warp as wp

from warpgs.kernels.rasterize import (COMPOSITED, SATURATED, TILE_SIZE_CPU, Image, PixelGrads, SplatGrads, Tiles,
                                      accumulate_grad, composite_splat, grad10, pixel_grad_inputs, splat_backward,
                                      store_pixel)

# the module options of warpgs.kernels.rasterize, which these kernels were built with
wp.set_module_options({"enable_backward": False, "fast_math": True})

# The CPU's compositing kernels: one thread per tile row of TILE_SIZE_CPU pixels, so that each Gaussian
# of the tile's list is loaded once for the row and the row's independent per-pixel chains overlap (about
# 2x faster forward, 1.5x backward than one thread per pixel). Per pixel the arithmetic, and its order,
# are those of ``composite_splat`` / ``splat_backward``, so the images are those of the per-pixel kernels in
# warpgs.kernels.rasterize (tests check both against the torch oracle). The backward sums a Gaussian's gradients over the
# row before adding them to its totals.

rowf = wp.types.vector(length=TILE_SIZE_CPU, dtype=wp.float32)  # one value per pixel of a row
rowi = wp.types.vector(length=TILE_SIZE_CPU, dtype=wp.int32)


@wp.func
def row_of_thread(tiles: Tiles, tid: int):
    """-> (whether CPU thread ``tid``, TILE_SIZE_CPU threads per tile, has a row of pixels in the image; x of the
    row's first pixel, y, and its tile's [start, end) in ``gauss_ids``, the last three 0 where it has none)."""
    tile = tid / TILE_SIZE_CPU
    ty = tile / tiles.tiles_x
    tx = tile - ty * tiles.tiles_x
    x0 = tx * TILE_SIZE_CPU
    y = ty * TILE_SIZE_CPU + tid - tile * TILE_SIZE_CPU
    inside = tile < tiles.ranges.shape[0] and y < tiles.height and x0 < tiles.width
    start = int(0)
    end = int(0)
    if inside:
        start = tiles.ranges[tile, 0]
        end = tiles.ranges[tile, 1]
    return inside, x0, y, start, end


@wp.kernel
def rasterize_fwd_cpu(tiles: Tiles, image: Image, part: int, n_parts: int):
    inside, x0, y, start, end = row_of_thread(tiles, wp.tid() * n_parts + part)  # see PARTS_NOTE
    if not inside:
        return
    width = tiles.width
    py = float(y) + 0.5
    T = rowf(1.0)
    R = rowf(0.0)
    G = rowf(0.0)
    B = rowf(0.0)
    D = rowf(0.0)
    n = rowi(start)
    live = rowi(0)  # 1 while a pixel (inside the image) has not saturated
    for i in range(TILE_SIZE_CPU):
        if x0 + i < width:
            live[i] = 1
    n_live = int(0)
    for i in range(TILE_SIZE_CPU):
        n_live += live[i]
    for k in range(start, end):
        if n_live == 0:
            break
        s = tiles.splats[tiles.gauss_ids[k]]
        for i in range(TILE_SIZE_CPU):
            if live[i] != 0:
                status, t, c, d = composite_splat(s, float(x0 + i) + 0.5, py, tiles.alpha_max, T[i],
                                                  wp.vec3(R[i], G[i], B[i]), D[i])
                if status == SATURATED:
                    live[i] = 0
                    n_live -= 1
                elif status == COMPOSITED:
                    T[i] = t
                    R[i] = c[0]
                    G[i] = c[1]
                    B[i] = c[2]
                    D[i] = d
                    n[i] = k + 1
    bg = tiles.background[0]
    for i in range(TILE_SIZE_CPU):
        if x0 + i < width:
            store_pixel(y * width + x0 + i, wp.vec3(R[i], G[i], B[i]), D[i], T[i], n[i], bg, image)


@wp.kernel
def rasterize_bwd_cpu(tiles: Tiles, pixels: PixelGrads, grads: SplatGrads, part: int, n_parts: int):
    inside, x0, y, start, end = row_of_thread(tiles, wp.tid() * n_parts + part)  # see PARTS_NOTE
    if not inside:
        return
    width = tiles.width
    py = float(y) + 0.5
    bg = tiles.background[0]
    last = rowi(start)
    T_final = rowf(1.0)
    T = rowf(1.0)
    vR = rowf(0.0)
    vG = rowf(0.0)
    vB = rowf(0.0)
    vD = rowf(0.0)
    vA_bg = rowf(0.0)
    SR = rowf(0.0)
    SG = rowf(0.0)
    SB = rowf(0.0)
    SD = rowf(0.0)
    k_end = start
    for i in range(TILE_SIZE_CPU):
        if x0 + i < width:
            li, tf, vc, vd, va = pixel_grad_inputs(True, y * width + x0 + i, start, pixels)
            last[i] = li
            T_final[i] = tf
            T[i] = tf
            vR[i] = vc[0]
            vG[i] = vc[1]
            vB[i] = vc[2]
            vD[i] = vd
            vA_bg[i] = va - wp.dot(bg, vc)
            k_end = wp.max(k_end, li)
    for j in range(k_end - start):
        k = k_end - 1 - j
        g = tiles.gauss_ids[k]
        s = tiles.splats[g]
        total = grad10()  # the row's sum of this Gaussian's gradient
        any_valid = int(0)
        for i in range(TILE_SIZE_CPU):
            if k < last[i]:
                valid, t, sc, sd, gi = splat_backward(s, float(x0 + i) + 0.5, py, tiles.alpha_max, T[i],
                                                      wp.vec3(SR[i], SG[i], SB[i]), SD[i],
                                                      wp.vec3(vR[i], vG[i], vB[i]), vD[i], vA_bg[i], T_final[i],
                                                      grads.with_depth)
                if valid != 0:
                    T[i] = t
                    SR[i] = sc[0]
                    SG[i] = sc[1]
                    SB[i] = sc[2]
                    SD[i] = sd
                    total = total + gi
                    any_valid = 1
        accumulate_grad(any_valid, g, total, grads)

