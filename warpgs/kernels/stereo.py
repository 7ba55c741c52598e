"""Multi-view plane-sweep stereo: NCC cost volume, winner-take-all with sub-plane refinement, and the
cross-view geometric consistency check. Only Warp code lives here (torch side: ``warpgs.densify.stereo``).

Geometry. For a reference view r and a source view s, a reference pixel q = (u, v, 1) on the
fronto-parallel plane of inverse depth d lands in s at pi(A q + d b), with A = K_s R_sr K_r^-1 and
b = K_s t_sr (R_sr, t_sr: the rigid motion from r's camera frame to s's); the caller precomputes A, b
per source. Pixel coordinates follow the library's convention: pixel (j, i) has its centre at
(j + 0.5, i + 0.5).

Cost. For every (plane, pixel) the (2 radius + 1)^2 patch around the pixel (taps ``step`` pixels
apart, clamped at the border) is compared with its plane-induced warp into each source (bilinear
samples) by normalised cross-correlation; the cost of a source is 1 - NCC in [0, 2]. The costs of
the sources whose warped centre falls inside their image are sorted and the ``top_k`` best averaged
(a view that is occluded at this pixel does not spoil the others). Textureless reference patches
(std < min_std) and planes no source sees cost 2.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

MAX_SOURCES = 8
BAD_COST = wp.constant(2.0)
vec_src = wp.types.vector(length=MAX_SOURCES, dtype=float)


@wp.func
def sample_bilinear(img: wp.array3d(dtype=float), view: int, u: float, v: float) -> float:
    """img[view] at continuous pixel coordinates (u, v) (pixel centres at +0.5), border clamped."""
    h = img.shape[1]
    w = img.shape[2]
    x = u - 0.5
    y = v - 0.5
    x0 = wp.floor(x)
    y0 = wp.floor(y)
    ax = x - x0
    ay = y - y0
    j0 = wp.clamp(int(x0), 0, w - 1)
    j1 = wp.clamp(int(x0) + 1, 0, w - 1)
    i0 = wp.clamp(int(y0), 0, h - 1)
    i1 = wp.clamp(int(y0) + 1, 0, h - 1)
    top = img[view, i0, j0] * (1.0 - ax) + img[view, i0, j1] * ax
    bot = img[view, i1, j0] * (1.0 - ax) + img[view, i1, j1] * ax
    return top * (1.0 - ay) + bot * ay


@wp.kernel
def patch_stats(
    gray: wp.array3d(dtype=float),
    ref: int,
    radius: int,
    step: int,
    mean: wp.array2d(dtype=float),
    std: wp.array2d(dtype=float),
):
    """Mean and standard deviation of the reference patch around every pixel (same taps as the cost)."""
    i, j = wp.tid()
    h = gray.shape[1]
    w = gray.shape[2]
    s = float(0.0)
    ss = float(0.0)
    n = float(0.0)
    for dy in range(-radius, radius + 1):
        ii = wp.clamp(i + dy * step, 0, h - 1)
        for dx in range(-radius, radius + 1):
            jj = wp.clamp(j + dx * step, 0, w - 1)
            g = gray[ref, ii, jj]
            s += g
            ss += g * g
            n += 1.0
    m = s / n
    mean[i, j] = m
    std[i, j] = wp.sqrt(wp.max(ss / n - m * m, 0.0))


@wp.kernel
def plane_sweep_ncc(
    gray: wp.array3d(dtype=float),  # [V, H, W] all views, one size
    ref: int,
    src_view: wp.array(dtype=wp.int32),  # [M] indices into gray, M <= MAX_SOURCES
    src_A: wp.array(dtype=wp.mat33),  # [M] K_s R_sr K_r^-1
    src_b: wp.array(dtype=wp.vec3),  # [M] K_s t_sr
    inv_depth: wp.array(dtype=float),  # [P] plane inverse depths
    ref_mean: wp.array2d(dtype=float),
    ref_std: wp.array2d(dtype=float),
    radius: int,
    step: int,
    top_k: int,
    min_std: float,
    cost: wp.array3d(dtype=float),  # [P, H, W] out
):
    p, i, j = wp.tid()
    h = gray.shape[1]
    w = gray.shape[2]
    sr = ref_std[i, j]
    if sr < min_std:
        cost[p, i, j] = BAD_COST
        return
    mr = ref_mean[i, j]
    d = inv_depth[p]
    costs = vec_src()
    nv = int(0)
    for s in range(src_view.shape[0]):
        A = src_A[s]
        b = src_b[s] * d
        v = src_view[s]
        xc = A @ wp.vec3(float(j) + 0.5, float(i) + 0.5, 1.0) + b
        if xc[2] <= 1.0e-8:
            continue
        uc = xc[0] / xc[2]
        vc = xc[1] / xc[2]
        if uc < 0.0 or uc > float(w) or vc < 0.0 or vc > float(h):
            continue
        s_sum = float(0.0)
        s_sq = float(0.0)
        rs = float(0.0)
        n = float(0.0)
        for dy in range(-radius, radius + 1):
            ii = wp.clamp(i + dy * step, 0, h - 1)
            for dx in range(-radius, radius + 1):
                jj = wp.clamp(j + dx * step, 0, w - 1)
                x = A @ wp.vec3(float(jj) + 0.5, float(ii) + 0.5, 1.0) + b
                z = wp.max(x[2], 1.0e-8)
                g = sample_bilinear(gray, v, x[0] / z, x[1] / z)
                s_sum += g
                s_sq += g * g
                rs += g * gray[ref, ii, jj]
                n += 1.0
        ms = s_sum / n
        var_s = s_sq / n - ms * ms
        ncc = float(0.0)
        if var_s > min_std * min_std:
            ncc = wp.clamp((rs / n - mr * ms) / (sr * wp.sqrt(var_s)), -1.0, 1.0)
        costs[nv] = 1.0 - ncc
        nv += 1
    if nv == 0:
        cost[p, i, j] = BAD_COST
        return
    k = wp.min(top_k, nv)
    total = float(0.0)
    for t in range(k):
        best = float(1.0e9)
        bi = int(0)
        for s in range(nv):
            if costs[s] < best:
                best = costs[s]
                bi = s
        total += best
        costs[bi] = 1.0e9
    cost[p, i, j] = total / float(k)


@wp.kernel
def winner_take_all(
    cost: wp.array3d(dtype=float),  # [P, H, W]
    inv_depth: wp.array(dtype=float),  # [P], uniformly spaced
    depth: wp.array2d(dtype=float),  # out: z-depth, 0 = no estimate
    score: wp.array2d(dtype=float),  # out: NCC at the refined minimum (1 - cost), -1 = no estimate
):
    """Best plane per pixel, refined by the parabola through its cost and its two neighbours' costs.
    A minimum on the first or last plane (the surface is likely outside the swept range) or at the
    'no evidence' cost gives no estimate."""
    i, j = wp.tid()
    num = cost.shape[0]
    best = float(1.0e9)
    b = int(0)
    for p in range(num):
        c = cost[p, i, j]
        if c < best:
            best = c
            b = p
    if b == 0 or b == num - 1 or best >= BAD_COST:
        depth[i, j] = 0.0
        score[i, j] = -1.0
        return
    c0 = cost[b - 1, i, j]
    c2 = cost[b + 1, i, j]
    den = c0 - 2.0 * best + c2
    delta = float(0.0)
    cmin = best
    if den > 1.0e-9:
        delta = wp.clamp(0.5 * (c0 - c2) / den, -0.5, 0.5)
        cmin = best - 0.25 * (c0 - c2) * delta
    step = 0.5 * (inv_depth[b + 1] - inv_depth[b - 1])
    inv = inv_depth[b] + delta * step
    if inv <= 0.0:
        depth[i, j] = 0.0
        score[i, j] = -1.0
        return
    depth[i, j] = 1.0 / inv
    score[i, j] = 1.0 - cmin


@wp.kernel
def sgm_path(
    cost: wp.array3d(dtype=float),  # [P, H, W] matching cost, BAD_COST = no evidence
    dx: int,  # the path's step: (1, 0), (-1, 0), (0, 1) or (0, -1)
    dy: int,
    p1: float,  # penalty of a step to the neighbouring plane
    p2: float,  # penalty of a larger jump
    neutral: float,  # the cost that a plane without evidence takes on the path
    path: wp.array3d(dtype=float),  # scratch [P, H, W]: this path's aggregated cost
    total: wp.array3d(dtype=float),  # in/out [P, H, W]: the sum over the paths
):
    """One direction of semi-global matching (Hirschmueller 2008) over the planes: along each image line in
    direction (dx, dy), L(q, p) = C(q, p) + min(L(q', p), L(q', p -+ 1) + p1, min_k L(q', k) + p2) - min_k L(q', k),
    q' the previous pixel on the line; L is added to ``total``. One thread per line (rows for horizontal paths,
    columns for vertical ones)."""
    t = wp.tid()
    num = cost.shape[0]
    h = cost.shape[1]
    w = cost.shape[2]
    x = int(0)
    y = int(0)
    n = int(0)
    if dy == 0:
        y = t
        n = w
        if dx < 0:
            x = w - 1
    else:
        x = t
        n = h
        if dy < 0:
            y = h - 1
    px = x
    py = y
    for s in range(n):
        m = float(0.0)
        if s > 0:
            m = float(1.0e30)
            for p in range(num):
                m = wp.min(m, path[p, py, px])
        for p in range(num):
            c = cost[p, y, x]
            if c >= BAD_COST:
                c = neutral
            v = c
            if s > 0:
                best = wp.min(path[p, py, px], m + p2)
                if p > 0:
                    best = wp.min(best, path[p - 1, py, px] + p1)
                if p < num - 1:
                    best = wp.min(best, path[p + 1, py, px] + p1)
                v = c + best - m
            path[p, y, x] = v
            total[p, y, x] = total[p, y, x] + v
        px = x
        py = y
        x = x + dx
        y = y + dy


@wp.kernel
def geometric_consistency(
    depth: wp.array3d(dtype=float),  # [V, H, W], 0 = no estimate
    w2c: wp.array(dtype=wp.mat44),  # [V]
    c2w: wp.array(dtype=wp.mat44),  # [V]
    K: wp.array(dtype=wp.mat33),  # [V]
    K_inv: wp.array(dtype=wp.mat33),  # [V]
    ref: int,
    neighbours: wp.array(dtype=wp.int32),  # [M] views checked against
    max_px: float,  # reprojection error bound in pixels
    max_rel_depth: float,  # relative depth difference bound
    max_cos_angle: float,  # a neighbour whose ray meets the reference's at a smaller angle (cosine above this) does
    #                        not count (1: every neighbour counts)
    count: wp.array2d(dtype=wp.int32),  # out: neighbours that agree
    depth_sum: wp.array2d(dtype=float),  # out: sum of the agreeing depths, the reference's own included
):
    """Forward-backward check: the reference pixel at its depth goes to the neighbour, picks up the
    neighbour's depth at the nearest pixel there, comes back, and must land within ``max_px`` pixels
    of where it started with a depth within ``max_rel_depth`` of its own. A neighbour whose viewing ray meets the
    reference's at the point under an angle with cosine above ``max_cos_angle`` (too short a baseline to place it in
    depth) is not checked."""
    i, j = wp.tid()
    h = depth.shape[1]
    w = depth.shape[2]
    d = depth[ref, i, j]
    n = int(0)
    acc = float(0.0)
    if d > 0.0:
        acc = d
        q = wp.vec3(float(j) + 0.5, float(i) + 0.5, 1.0)
        xr = K_inv[ref] @ q * d
        xw = wp.transform_point(c2w[ref], xr)
        for m in range(neighbours.shape[0]):
            s = neighbours[m]
            xs = wp.transform_point(w2c[s], xw)
            if xs[2] <= 0.0:
                continue
            if max_cos_angle < 1.0:
                ray_r = wp.normalize(xw - wp.transform_point(c2w[ref], wp.vec3(0.0)))
                ray_s = wp.normalize(xw - wp.transform_point(c2w[s], wp.vec3(0.0)))
                if wp.dot(ray_r, ray_s) > max_cos_angle:
                    continue
            ps = K[s] @ xs
            us = ps[0] / ps[2]
            vs = ps[1] / ps[2]
            js = int(wp.floor(us))
            is_ = int(wp.floor(vs))
            if js < 0 or js >= w or is_ < 0 or is_ >= h:
                continue
            ds = depth[s, is_, js]
            if ds <= 0.0:
                continue
            xs2 = K_inv[s] @ wp.vec3(us, vs, 1.0) * ds
            xr2 = wp.transform_point(w2c[ref], wp.transform_point(c2w[s], xs2))
            if xr2[2] <= 0.0:
                continue
            pr = K[ref] @ xr2
            du = pr[0] / pr[2] - q[0]
            dv = pr[1] / pr[2] - q[1]
            if du * du + dv * dv <= max_px * max_px and wp.abs(xr2[2] - d) <= max_rel_depth * d:
                n += 1
                acc += xr2[2]
    count[i, j] = n
    depth_sum[i, j] = acc
