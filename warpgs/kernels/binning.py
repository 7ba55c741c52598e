"""Tile binning: one (tile, depth) key per Gaussian-tile overlap, sorted with Warp's radix sort, then
the [start, end) range of every tile in the sorted list. Only Warp code lives here."""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def emit_intersections(
    means2d: wp.array(dtype=wp.vec2),
    radii: wp.array(dtype=wp.vec2i),
    depth_bits: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    tile_size: int,
    tiles_x: int,
    tiles_y: int,
    keys: wp.array(dtype=wp.int64),
    values: wp.array(dtype=wp.int32),
):
    """keys = tile id << 32 | depth as float bits (positive floats sort like their bit patterns)."""
    i = wp.tid()
    r = radii[i]
    if r[0] <= 0 and r[1] <= 0:
        return
    m2 = means2d[i]
    ts = float(tile_size)
    rx = float(r[0])
    ry = float(r[1])
    tx0 = wp.clamp(int(wp.floor((m2[0] - rx) / ts)), 0, tiles_x)
    ty0 = wp.clamp(int(wp.floor((m2[1] - ry) / ts)), 0, tiles_y)
    tx1 = wp.clamp(int(wp.ceil((m2[0] + rx) / ts)), 0, tiles_x)
    ty1 = wp.clamp(int(wp.ceil((m2[1] + ry) / ts)), 0, tiles_y)
    k = int(0)
    if i > 0:
        k = offsets[i - 1]
    dbits = wp.int64(depth_bits[i])
    cap = keys.shape[0]
    for ty in range(ty0, ty1):
        for tx in range(tx0, tx1):
            if k < cap:  # never false when the buffers were sized from the offsets (rasterize's two modes)
                tile = wp.int64(ty * tiles_x + tx)
                keys[k] = (tile << wp.int64(32)) | dbits
                values[k] = i
            k += 1


@wp.kernel
def tile_ranges_from_keys(keys: wp.array(dtype=wp.int64), count: int, ranges: wp.array2d(dtype=wp.int32)):
    """ranges[tile] = [first, last + 1) of the tile's entries in the sorted key list (zeros if empty).
    Each element is written by exactly one thread. Keys of a tile past the grid (``ranges.shape[0]``: the
    padding ``rasterize`` sorts after every real key when its buffers have a fixed capacity) end the range
    before them and are otherwise skipped."""
    k = wp.tid()
    n_tiles = ranges.shape[0]
    tile = int(keys[k] >> wp.int64(32))
    if tile >= n_tiles:
        if k > 0:
            prev = int(keys[k - 1] >> wp.int64(32))
            if prev < n_tiles:
                ranges[prev, 1] = k
        return
    if k == 0:
        ranges[tile, 0] = 0
    else:
        prev = int(keys[k - 1] >> wp.int64(32))
        if prev != tile:
            ranges[prev, 1] = k
            ranges[tile, 0] = k
    if k == count - 1:
        ranges[tile, 1] = count
