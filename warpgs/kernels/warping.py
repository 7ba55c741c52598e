"""Cross-view warping for pseudo-view guidance, Warp kernels only (no torch).

Two stages, one thread per pixel of a guidance frame ``(frame f, row i, column j)``:

``inverse_warp``
    the guidance image by inverse warping an input view (paper Sec. 3.2):
    ``q = K_inp P_inp P_guid^-1 D_guid(p) K_guid^-1 p``, then ``I_inp(q)`` sampled bilinearly.
``reproject_uncertainty``
    the backward projection with the depth rendered at the input,
    ``p' = K_guid P_guid P_inp^-1 D_inp(q) K_inp^-1 q``, and the cross-view uncertainty
    ``U(p) = 1 - exp(-|p - p'|^2 / s1 - |I_gs(p) - I_inp(q)|^2 / s2)``.

Conventions (``warpgs/__init__.py``): OpenCV cameras, world-to-camera ``P`` (4x4), ``K`` in pixels,
pixel (j, i) centred at (j + 0.5, i + 0.5); depth is z-depth along the optical axis, <= 0 = unknown.
Each guidance frame reads input view ``src_index[f]`` of a stack of inputs, so a whole trajectory
is one launch. Matrices arrive precomputed per frame (``dst_to_src = P_inp P_guid^-1`` and inverse
intrinsics), so the kernels do no matrix inversion.

Colour is interpolated bilinearly (clamped at the border). Depth is interpolated as inverse depth
(exact on a plane, where inverse depth is affine in the image), over the valid neighbours only;
a sample whose valid neighbours weigh less than one half counts as having no depth.
"""

import warp as wp

from warpgs.kernels.rasterize import to_fixed

INVALID = wp.constant(-1.0)  # coordinate written where a pixel has no correspondence


@wp.func
def pixel_ray(j: int, i: int) -> wp.vec3:
    # homogeneous pixel centre
    return wp.vec3(float(j) + 0.5, float(i) + 0.5, 1.0)


@wp.func
def bilinear_taps(w: int, h: int, x: float, y: float):
    # the four neighbouring pixels (clamped to the image) of continuous pixel coordinates (x, y), whose
    # centres sit at +0.5, and the interpolation weights along x and y
    fx = x - 0.5
    fy = y - 0.5
    x0 = int(wp.floor(fx))
    y0 = int(wp.floor(fy))
    return (wp.clamp(x0, 0, w - 1), wp.clamp(x0 + 1, 0, w - 1), wp.clamp(y0, 0, h - 1), wp.clamp(y0 + 1, 0, h - 1),
            fx - float(x0), fy - float(y0))


@wp.func
def sample_rgb(img: wp.array3d(dtype=wp.vec3), s: int, x: float, y: float) -> wp.vec3:
    # bilinear sample of image s at continuous pixel coordinates (x, y), edges clamped
    h = img.shape[1]
    w = img.shape[2]
    xa, xb, ya, yb, ax, ay = bilinear_taps(w, h, x, y)
    top = img[s, ya, xa] * (1.0 - ax) + img[s, ya, xb] * ax
    bot = img[s, yb, xa] * (1.0 - ax) + img[s, yb, xb] * ax
    return top * (1.0 - ay) + bot * ay


@wp.func
def _inv_depth_tap(depth: wp.array3d(dtype=float), s: int, i: int, j: int, wgt: float, min_depth: float) -> wp.vec2:
    # (weight * 1/d, weight) for a valid tap, zeros otherwise
    d = depth[s, i, j]
    if d > min_depth:
        return wp.vec2(wgt / d, wgt)
    return wp.vec2(0.0, 0.0)


@wp.func
def sample_depth(depth: wp.array3d(dtype=float), s: int, x: float, y: float, min_depth: float) -> float:
    # inverse-depth bilinear sample over valid neighbours; 0 where the valid weight is below 1/2
    h = depth.shape[1]
    w = depth.shape[2]
    xa, xb, ya, yb, ax, ay = bilinear_taps(w, h, x, y)
    acc = _inv_depth_tap(depth, s, ya, xa, (1.0 - ax) * (1.0 - ay), min_depth)
    acc += _inv_depth_tap(depth, s, ya, xb, ax * (1.0 - ay), min_depth)
    acc += _inv_depth_tap(depth, s, yb, xa, (1.0 - ax) * ay, min_depth)
    acc += _inv_depth_tap(depth, s, yb, xb, ax * ay, min_depth)
    if acc[1] < 0.5 or acc[0] <= 0.0:
        return 0.0
    return acc[1] / acc[0]


@wp.func
def transform_point(m: wp.mat44, p: wp.vec3) -> wp.vec3:
    return wp.vec3(
        m[0, 0] * p[0] + m[0, 1] * p[1] + m[0, 2] * p[2] + m[0, 3],
        m[1, 0] * p[0] + m[1, 1] * p[1] + m[1, 2] * p[2] + m[1, 3],
        m[2, 0] * p[0] + m[2, 1] * p[1] + m[2, 2] * p[2] + m[2, 3],
    )


@wp.kernel
def inverse_warp(
    dst_depth: wp.array3d(dtype=float),  # (F, H, W) D_guid: depth rendered at the guidance pose
    dst_to_src: wp.array(dtype=wp.mat44),  # (F,) P_inp P_guid^-1
    dst_K_inv: wp.array(dtype=wp.mat33),  # (F,) K_guid^-1
    src_K: wp.array(dtype=wp.mat33),  # (F,) K_inp of the frame's source
    src_index: wp.array(dtype=wp.int32),  # (F,) which input each frame warps from
    src_image: wp.array3d(dtype=wp.vec3),  # (S, Hs, Ws) input images
    min_depth: float,
    guidance: wp.array3d(dtype=wp.vec3),  # out (F, H, W): I_inp(q), 0 where invalid
    coords: wp.array3d(dtype=wp.vec2),  # out (F, H, W): q in input pixels, INVALID where none
    valid: wp.array3d(dtype=wp.int32),  # out (F, H, W): 1 where q lands inside the input image
):
    f, i, j = wp.tid()
    s = src_index[f]
    hs = float(src_image.shape[1])
    ws = float(src_image.shape[2])
    d = dst_depth[f, i, j]
    guidance[f, i, j] = wp.vec3(0.0, 0.0, 0.0)
    coords[f, i, j] = wp.vec2(INVALID, INVALID)
    valid[f, i, j] = 0
    if d <= min_depth:
        return
    x_dst = (dst_K_inv[f] @ pixel_ray(j, i)) * d  # point in the guidance camera
    x_src = transform_point(dst_to_src[f], x_dst)  # ... in the input camera
    if x_src[2] <= min_depth:
        return
    h = src_K[f] @ x_src
    qx = h[0] / h[2]
    qy = h[1] / h[2]
    if qx < 0.0 or qy < 0.0 or qx >= ws or qy >= hs:
        return
    coords[f, i, j] = wp.vec2(qx, qy)
    guidance[f, i, j] = sample_rgb(src_image, s, qx, qy)
    valid[f, i, j] = 1


@wp.kernel
def reproject_uncertainty(
    coords: wp.array3d(dtype=wp.vec2),  # (F, H, W) q from inverse_warp
    valid: wp.array3d(dtype=wp.int32),  # (F, H, W) from inverse_warp
    src_depth: wp.array3d(dtype=float),  # (S, Hs, Ws) D_inp: depth rendered at the inputs
    src_index: wp.array(dtype=wp.int32),  # (F,)
    src_to_dst: wp.array(dtype=wp.mat44),  # (F,) P_guid P_inp^-1
    src_K_inv: wp.array(dtype=wp.mat33),  # (F,) K_inp^-1 of the frame's source
    dst_K: wp.array(dtype=wp.mat33),  # (F,) K_guid
    render: wp.array3d(dtype=wp.vec3),  # (F, H, W) I_gs: colour rendered at the guidance pose
    guidance: wp.array3d(dtype=wp.vec3),  # (F, H, W) I_inp(q) from inverse_warp
    inv_s1: float,  # 1/s1 (pixels^-2); 0 drops the geometric term
    inv_s2: float,  # 1/s2; 0 drops the photometric term
    min_depth: float,
    uncertainty: wp.array3d(dtype=float),  # out (F, H, W) U in [0, 1]; 1 where no correspondence
    reprojected: wp.array3d(dtype=wp.vec2),  # out (F, H, W) p', INVALID where none
):
    f, i, j = wp.tid()
    uncertainty[f, i, j] = 1.0
    reprojected[f, i, j] = wp.vec2(INVALID, INVALID)
    if valid[f, i, j] == 0:
        return
    s = src_index[f]
    q = coords[f, i, j]
    d = sample_depth(src_depth, s, q[0], q[1], min_depth)
    if d <= 0.0:
        return
    x_src = (src_K_inv[f] @ wp.vec3(q[0], q[1], 1.0)) * d
    x_dst = transform_point(src_to_dst[f], x_src)
    if x_dst[2] <= min_depth:
        return
    h = dst_K[f] @ x_dst
    px = h[0] / h[2]
    py = h[1] / h[2]
    reprojected[f, i, j] = wp.vec2(px, py)
    ex = px - (float(j) + 0.5)
    ey = py - (float(i) + 0.5)
    dc = render[f, i, j] - guidance[f, i, j]
    energy = (ex * ex + ey * ey) * inv_s1 + wp.dot(dc, dc) * inv_s2
    uncertainty[f, i, j] = 1.0 - wp.exp(-energy)


# ----------------------------------------------------------------------------------------------------
# Binocular consistency (Han et al., NeurIPS 2024): a render from the input camera moved by t along its own
# x axis, warped back into the input with the input's rendered depth. A point at depth z seen at column x in
# the input is seen at x - fx t / z in the moved camera (same intrinsics, no rotation: a rectified pair), so
# the warp samples the moved render along the row. Differentiable in the moved render and in the depth.


@wp.func
def _row_taps(w: int, x: float):
    # the two neighbouring columns of continuous column coordinate x (centres at +0.5), their weights, and
    # whether each lies inside the image (outside: zero padding)
    fx = x - 0.5
    x0 = int(wp.floor(fx))
    a = fx - float(x0)
    v0 = 0.0
    v1 = 0.0
    if x0 >= 0 and x0 < w:
        v0 = 1.0
    if x0 + 1 >= 0 and x0 + 1 < w:
        v1 = 1.0
    return wp.clamp(x0, 0, w - 1), wp.clamp(x0 + 1, 0, w - 1), a, v0, v1


@wp.kernel
def shift_warp(
    moved: wp.array2d(dtype=wp.vec3),  # (H, W) render at the moved camera
    depth: wp.array2d(dtype=float),  # (H, W) z-depth rendered at the input
    ft: wp.array(dtype=float),  # (1,) fx * t: the disparity (pixels) of depth 1 (on the device: no host read)
    min_depth: float,
    warped: wp.array2d(dtype=wp.vec3),  # out (H, W): moved(x - ft / z), 0 where invalid
    weight: wp.array2d(dtype=float),  # out (H, W): the in-image share of the two taps, 0 where no depth
):
    i, j = wp.tid()
    z = depth[i, j]
    warped[i, j] = wp.vec3(0.0, 0.0, 0.0)
    weight[i, j] = 0.0
    if z <= min_depth:
        return
    xa, xb, a, v0, v1 = _row_taps(moved.shape[1], float(j) + 0.5 - ft[0] / z)
    warped[i, j] = moved[i, xa] * ((1.0 - a) * v0) + moved[i, xb] * (a * v1)
    weight[i, j] = (1.0 - a) * v0 + a * v1


@wp.kernel
def shift_warp_backward(
    moved: wp.array2d(dtype=wp.vec3),
    depth: wp.array2d(dtype=float),
    ft: wp.array(dtype=float),
    min_depth: float,
    v_warped: wp.array2d(dtype=wp.vec3),  # dL/d warped
    v_moved: wp.array2d(dtype=wp.vec3),  # out, accumulated (zeroed by the caller)
    v_depth: wp.array2d(dtype=float),  # out
):
    # one thread per row (launched over H): a row's pixels add their two taps into the row's v_moved in column
    # order, without atomics. Several pixels land on one tap where the warp compresses the row, and float sums
    # depend on their order: per-pixel atomic adds on CUDA arrive in the order the warps do, which changes from
    # run to run. This is the order a CPU launch of one thread per pixel took, so the CPU's sums are unchanged.
    i = wp.tid()
    for j in range(depth.shape[1]):
        z = depth[i, j]
        v_depth[i, j] = 0.0
        if z > min_depth:
            g = v_warped[i, j]
            xa, xb, a, v0, v1 = _row_taps(moved.shape[1], float(j) + 0.5 - ft[0] / z)
            if v0 > 0.0:
                v_moved[i, xa] = v_moved[i, xa] + g * (1.0 - a)
            if v1 > 0.0:
                v_moved[i, xb] = v_moved[i, xb] + g * a
            # d a / d z = d (x - 0.5) / d z = ft / z^2
            v_depth[i, j] = wp.dot(g, moved[i, xb] * v1 - moved[i, xa] * v0) * ft[0] / (z * z)


@wp.func
def _pose_warp_coords(depth: wp.array2d(dtype=float), rel: wp.array(dtype=wp.mat44), K: wp.array(dtype=wp.mat33),
                      min_depth: float, i: int, j: int):
    # where pixel (i, j) of the input, at its depth, lands in the moved camera: (x, y, ok), with d(x, y)/dz. K is
    # inverted here (a 3x3 per thread): no solver on the host or the GPU for it
    z = depth[i, j]
    r = wp.inverse(K[0]) @ pixel_ray(j, i)
    t = transform_point(rel[0], wp.vec3(0.0, 0.0, 0.0))
    q = transform_point(rel[0], r * z)
    ok = 1
    if z <= min_depth or q[2] <= min_depth:
        ok = 0
        q = wp.vec3(0.0, 0.0, 1.0)
    hq = K[0] @ q
    dh = K[0] @ (transform_point(rel[0], r) - t)  # d hq / dz (q is affine in z)
    x = hq[0] / hq[2]
    y = hq[1] / hq[2]
    dxdz = (dh[0] * hq[2] - hq[0] * dh[2]) / (hq[2] * hq[2])
    dydz = (dh[1] * hq[2] - hq[1] * dh[2]) / (hq[2] * hq[2])
    w = float(depth.shape[1])
    h = float(depth.shape[0])
    if x < -1.0 or y < -1.0 or x > w + 1.0 or y > h + 1.0:  # no tap inside the image (and no int overflow)
        ok = 0
    return x, y, ok, dxdz, dydz


@wp.kernel
def pose_warp(
    moved: wp.array2d(dtype=wp.vec3),  # (H, W) render at the moved camera (same intrinsics)
    depth: wp.array2d(dtype=float),  # (H, W) z-depth rendered at the input
    rel: wp.array(dtype=wp.mat44),  # (1,) input camera -> moved camera (P_moved P_input^-1), on the device
    K: wp.array(dtype=wp.mat33),  # (1,) intrinsics (pixels)
    min_depth: float,
    warped: wp.array2d(dtype=wp.vec3),  # out (H, W): moved at the pixel's reprojection, 0 where invalid
    weight: wp.array2d(dtype=float),  # out (H, W): the in-image share of the four taps, 0 where invalid
):
    # the general form of shift_warp: each input pixel, at its rendered depth, reprojected into the moved camera,
    # and the moved render sampled there bilinearly with zero padding
    i, j = wp.tid()
    warped[i, j] = wp.vec3(0.0, 0.0, 0.0)
    weight[i, j] = 0.0
    x, y, ok, dxdz, dydz = _pose_warp_coords(depth, rel, K, min_depth, i, j)
    if ok == 0:
        return
    xa, xb, a, v0, v1 = _row_taps(moved.shape[1], x)
    ya, yb, b, u0, u1 = _row_taps(moved.shape[0], y)
    w00 = (1.0 - a) * (1.0 - b) * v0 * u0
    w01 = a * (1.0 - b) * v1 * u0
    w10 = (1.0 - a) * b * v0 * u1
    w11 = a * b * v1 * u1
    warped[i, j] = moved[ya, xa] * w00 + moved[ya, xb] * w01 + moved[yb, xa] * w10 + moved[yb, xb] * w11
    weight[i, j] = w00 + w01 + w10 + w11


@wp.func
def _add_fixed(v_fixed: wp.array3d(dtype=wp.int64), y: int, x: int, v: wp.vec3):
    # v added to pixel (y, x) in 64-bit fixed point (the rasterizer's to_fixed, 2^-40 steps): integer sums do not
    # depend on the order the atomic adds arrive in
    for c in range(3):
        wp.atomic_add(v_fixed, y, x, c, to_fixed(v[c]))


@wp.kernel
def pose_warp_backward(
    moved: wp.array2d(dtype=wp.vec3),
    depth: wp.array2d(dtype=float),
    rel: wp.array(dtype=wp.mat44),
    K: wp.array(dtype=wp.mat33),
    min_depth: float,
    v_warped: wp.array2d(dtype=wp.vec3),  # dL/d warped
    v_fixed: wp.array3d(dtype=wp.int64),  # out (H, W, 3): dL/d moved in fixed point, accumulated (zeroed by the caller)
    v_depth: wp.array2d(dtype=float),  # out
):
    # pixels of several rows reach one tap of the moved render, so the sums are fixed-point integers: float atomic
    # adds on CUDA would sum in the order the warps arrive in, which changes from run to run
    i, j = wp.tid()
    v_depth[i, j] = 0.0
    x, y, ok, dxdz, dydz = _pose_warp_coords(depth, rel, K, min_depth, i, j)
    if ok == 0:
        return
    g = v_warped[i, j]
    xa, xb, a, v0, v1 = _row_taps(moved.shape[1], x)
    ya, yb, b, u0, u1 = _row_taps(moved.shape[0], y)
    if v0 * u0 > 0.0:
        _add_fixed(v_fixed, ya, xa, g * ((1.0 - a) * (1.0 - b)))
    if v1 * u0 > 0.0:
        _add_fixed(v_fixed, ya, xb, g * (a * (1.0 - b)))
    if v0 * u1 > 0.0:
        _add_fixed(v_fixed, yb, xa, g * ((1.0 - a) * b))
    if v1 * u1 > 0.0:
        _add_fixed(v_fixed, yb, xb, g * (a * b))
    m00 = moved[ya, xa] * (v0 * u0)
    m01 = moved[ya, xb] * (v1 * u0)
    m10 = moved[yb, xa] * (v0 * u1)
    m11 = moved[yb, xb] * (v1 * u1)
    d_dx = (m01 - m00) * (1.0 - b) + (m11 - m10) * b  # d warped / d x (d a / d x = 1)
    d_dy = (m10 - m00) * (1.0 - a) + (m11 - m01) * a
    v_depth[i, j] = wp.dot(g, d_dx * dxdz + d_dy * dydz)
