"""Tile binning: one (tile, depth) key per Gaussian-tile overlap, sorted with Warp's radix sort, then
the [start, end) range of every tile in the sorted list. Only Warp code lives here."""

import warp as wp

# one Gaussian as the compositing kernels read it (warpgs/kernels/rasterize.py)
splat = wp.types.vector(length=10, dtype=wp.float32)

wp.set_module_options({"enable_backward": False})

# The largest screen coordinate and radius (pixels) a Gaussian on screen may have: projection culls a Gaussian whose
# mean lies farther out and clamps its radius to ``MAX_RADIUS`` (the footprint then still covers every tile of an image
# up to 2^22 pixels wide), so that every tile index below comes from a finite float well inside the int32 range.
MAX_COORD = wp.constant(16777216.0)  # 2^24
MAX_RADIUS = wp.constant(8388608.0)  # 2^23


@wp.func
def on_screen(m2: wp.vec2, rx: float, ry: float, depth: float) -> bool:
    """Whether projection may keep a Gaussian with screen mean ``m2``, radii ``rx``, ``ry`` (before the clamp to
    ``MAX_RADIUS``) and camera depth ``depth``: every value finite and the mean within ``MAX_COORD`` of the origin.
    Written with negated comparisons so that a NaN answers False."""
    ok = wp.isfinite(m2[0]) and wp.isfinite(m2[1]) and wp.isfinite(rx) and wp.isfinite(ry) and wp.isfinite(depth)
    return ok and wp.abs(m2[0]) <= MAX_COORD and wp.abs(m2[1]) <= MAX_COORD and rx >= 0.0 and ry >= 0.0


@wp.func
def tile_rect(m2: wp.vec2, rx: float, ry: float, tile_size: int, tiles_x: int, tiles_y: int):
    """The tiles [x0, x1) x [y0, y1) a footprint of radii ``rx``, ``ry`` around ``m2`` touches, as gsplat's
    intersect_tile, clamped to the grid while still float (so no conversion leaves the int range): 0 <= x0 <= x1 <=
    tiles_x, 0 <= y0 <= y1 <= tiles_y for any finite input. Projection's tile counts and the binning's keys both come
    from here, so the keys a Gaussian writes are exactly the slots its count reserved."""
    ts = float(tile_size)
    x0 = wp.clamp(wp.floor((m2[0] - rx) / ts), 0.0, float(tiles_x))
    y0 = wp.clamp(wp.floor((m2[1] - ry) / ts), 0.0, float(tiles_y))
    x1 = wp.clamp(wp.ceil((m2[0] + rx) / ts), x0, float(tiles_x))
    y1 = wp.clamp(wp.ceil((m2[1] + ry) / ts), y0, float(tiles_y))
    return int(x0), int(y0), int(x1), int(y1)


@wp.kernel
def emit_intersections(
    means2d: wp.array(dtype=wp.vec2),
    radii: wp.array(dtype=wp.vec2i),
    depth_bits: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    tile_size: int,
    tiles_x: int,
    tiles_y: int,
    shift: int,
    base_bits: int,
    keys: wp.array(dtype=wp.int64),
    values: wp.array(dtype=wp.int32),
    conics: wp.array(dtype=wp.vec3),
    opacities: wp.array(dtype=float),
    colors: wp.array(dtype=wp.vec3),
    depths: wp.array(dtype=float),
    splats: wp.array(dtype=splat),
):
    """keys = tile id << ``shift`` | (depth's float bits - ``base_bits``): positive floats sort like their bit
    patterns, so within a tile the keys sort by depth; the caller picks ``base_bits`` at most the bits of any
    depth on screen and ``shift`` above the bits of the largest difference (``rasterize``: the near plane's bits, and
    the width of the largest depth's difference to them, which the radix sort then need not pass over beyond; or
    0 and 32). Also the Gaussian as the compositing kernels read it, ``splats[i]`` = (x, y, conic a, b, c, opacity,
    r, g, b, depth), written for the Gaussians on screen only (no tile list holds another). ``depth_bits`` is
    ``depths`` viewed as int32."""
    i = wp.tid()
    r = radii[i]
    if r[0] <= 0 and r[1] <= 0:
        return
    m2 = means2d[i]
    cn = conics[i]
    c = colors[i]
    splats[i] = splat(m2[0], m2[1], cn[0], cn[1], cn[2], opacities[i], c[0], c[1], c[2], depths[i])
    tx0, ty0, tx1, ty1 = tile_rect(m2, float(r[0]), float(r[1]), tile_size, tiles_x, tiles_y)
    k = int(0)
    if i > 0:
        k = offsets[i - 1]
    dbits = wp.int64(depth_bits[i] - base_bits)
    s64 = wp.int64(shift)
    cap = keys.shape[0]
    for ty in range(ty0, ty1):
        for tx in range(tx0, tx1):
            if k >= 0 and k < cap:  # never false when the buffers were sized from the offsets (both modes)
                tile = wp.int64(ty * tiles_x + tx)
                keys[k] = (tile << s64) | dbits
                values[k] = i
            k += 1


@wp.func
def lower_bound(keys: wp.array(dtype=wp.int64), count: int, v: wp.int64) -> int:
    """The first index of the sorted ``keys[:count]`` whose key is >= ``v`` (``count`` if none is)."""
    lo = int(0)
    hi = count
    while lo < hi:
        mid = (lo + hi) / 2
        if keys[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@wp.func
def tile_range(keys: wp.array(dtype=wp.int64), count: int, shift: int, tile: int):
    """[start, end) of ``tile``'s entries in the sorted ``keys[:count]`` of ``emit_intersections``'s ``shift`` (two
    binary searches: what ``tile_ranges_from_keys`` writes for it)."""
    t = wp.int64(tile)
    s = wp.int64(shift)
    return lower_bound(keys, count, t << s), lower_bound(keys, count, (t + wp.int64(1)) << s)


@wp.kernel
def tile_ranges_from_keys(keys: wp.array(dtype=wp.int64), count: int, shift: int, ranges: wp.array2d(dtype=wp.int32)):
    """ranges[tile] = [first, last + 1) of the tile's entries in the sorted key list (zeros if empty).
    Each element is written by exactly one thread. Keys of a tile past the grid (``ranges.shape[0]``: the
    padding ``rasterize`` sorts after every real key when its buffers have a fixed capacity) end the range
    before them and are otherwise skipped."""
    k = wp.tid()
    n_tiles = wp.int64(ranges.shape[0])
    s = wp.int64(shift)
    tile = keys[k] >> s  # compared as int64: a padding key's tile does not fit an int
    if tile < wp.int64(0):  # no key emit_intersections writes; skipped rather than written out of bounds
        return
    if tile >= n_tiles:
        if k > 0:
            prev = keys[k - 1] >> s
            if prev < n_tiles and prev >= wp.int64(0):
                ranges[int(prev), 1] = k
        return
    if k == 0:
        ranges[int(tile), 0] = 0
    else:
        prev = keys[k - 1] >> s
        if prev != tile:
            if prev >= wp.int64(0):
                ranges[int(prev), 1] = k
            ranges[int(tile), 0] = k
    if k == count - 1:
        ranges[int(tile), 1] = count
