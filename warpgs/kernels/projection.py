"""Projection of 3D Gaussians to the image plane (EWA splatting), forward and hand-written backward.

Per Gaussian: world mean -> camera (OpenCV axes), covariance R S S^T R^T -> camera -> 2D through the
perspective Jacobian (with gsplat's clamping of the view direction to 1.3x the field of view), 0.3 px
dilation, optional antialiasing compensation sqrt(det S2 / det(S2 + eps I)), conic = inverse 2D
covariance, and an opacity-aware screen box: extent = min(3.33, sqrt(2 ln(255 o))) sigmas per axis
(gsplat 1.5's tight box; a pixel outside it has alpha < 1/255, the compositing cut-off).

Culling is the one guard of every later index: a Gaussian whose depth, 2D covariance, opacity, screen mean or
radius is NaN or infinite, whose mean lies beyond ``binning.MAX_COORD`` pixels, or whose tile rectangle is empty
gets radius 0 and zero outputs, and the binning, the colours and the compositing read only Gaussians of radius > 0
(their gradients are 0). The radius is clamped to ``binning.MAX_RADIUS`` and the tile rectangle to the grid while
still float (``binning.tile_rect``), so no float-to-int conversion leaves its range. Every test is written so that
NaN fails it (``not (x >= lo)``), and none of it changes a Gaussian of an ordinary scene.

Both kernels take the Gaussians and the camera as structs (``Gaussians``, ``Camera``), so the forward and
the backward read one definition of what they share; the backward writes its gradients into a second
``Gaussians`` laid out like the first. Only Warp code lives here; the launches, which build the structs
from torch tensors without copies, are in ``warpgs/render.py``.
"""

import warp as wp

from warpgs.kernels.binning import MAX_RADIUS, on_screen, tile_rect

wp.set_module_options({"enable_backward": False, "fast_math": True})

ALPHA_MIN = wp.constant(1.0 / 255.0)
MAX_EXTENT = wp.constant(3.33)
mat23 = wp.types.matrix(shape=(2, 3), dtype=wp.float32)


vec8 = wp.types.vector(length=8, dtype=wp.float32)


@wp.func_native(
    """
    // The forward 2D covariance chain written as gsplat 1.5.3 writes it with glm (column-major g[col][row],
    // same expressions, same evaluation order), so that with fast math both round alike and the two
    // rasterizers agree bit for bit: quaternion -> rotation, M = R S, cov = M M^T, R_view cov R_view^T,
    // J cov J^T, 0.3 px dilation, glm::inverse. Returns (a, c, det_orig, det_blur, conic x, y, z, 0)
    // with a, c the dilated diagonal.
    float w = q.c[0], x = q.c[1], y = q.c[2], z = q.c[3];
#if defined(__CUDA_ARCH__)
    float inv_norm = rsqrtf(x * x + y * y + z * z + w * w);
#else
    float inv_norm = 1.0f / sqrtf(x * x + y * y + z * z + w * w);
#endif
    x *= inv_norm; y *= inv_norm; z *= inv_norm; w *= inv_norm;
    float x2 = x * x, y2 = y * y, z2 = z * z;
    float xy = x * y, xz = x * z, yz = y * z;
    float wx = w * x, wy = w * y, wz = w * z;
    float Rq[3][3] = {{1.f - 2.f * (y2 + z2), 2.f * (xy + wz), 2.f * (xz - wy)},
                      {2.f * (xy - wz), 1.f - 2.f * (x2 + z2), 2.f * (yz + wx)},
                      {2.f * (xz + wy), 2.f * (yz - wx), 1.f - 2.f * (x2 + y2)}};
    float S[3][3] = {{s.c[0], 0.f, 0.f}, {0.f, s.c[1], 0.f}, {0.f, 0.f, s.c[2]}};
    float Rv[3][3], Rvt[3][3];
    for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r) { Rv[c][r] = Rview.data[r][c]; Rvt[c][r] = Rview.data[c][r]; }
    float M[3][3], Mt[3][3], C[3][3], T1[3][3], Cc[3][3];
#define WARPGS_GLM_MUL3(A, B, O) \
    for (int c = 0; c < 3; ++c) for (int r = 0; r < 3; ++r) { \
        float t = A[0][r] * B[c][0]; t += A[1][r] * B[c][1]; t += A[2][r] * B[c][2]; O[c][r] = t; }
    WARPGS_GLM_MUL3(Rq, S, M)
    for (int c = 0; c < 3; ++c) for (int r = 0; r < 3; ++r) Mt[c][r] = M[r][c];
    WARPGS_GLM_MUL3(M, Mt, C)
    WARPGS_GLM_MUL3(Rv, C, T1)
    WARPGS_GLM_MUL3(T1, Rvt, Cc)
#undef WARPGS_GLM_MUL3
    float Jg[3][2];
    for (int k = 0; k < 3; ++k) for (int r = 0; r < 2; ++r) Jg[k][r] = J.data[r][k];
    float JC[3][2];
    for (int c = 0; c < 3; ++c) for (int r = 0; r < 2; ++r)
        JC[c][r] = Jg[0][r] * Cc[c][0] + Jg[1][r] * Cc[c][1] + Jg[2][r] * Cc[c][2];
    float cv[2][2];
    for (int c = 0; c < 2; ++c) for (int r = 0; r < 2; ++r)
        cv[c][r] = JC[0][r] * Jg[0][c] + JC[1][r] * Jg[1][c] + JC[2][r] * Jg[2][c];
    float det_orig = cv[0][0] * cv[1][1] - cv[0][1] * cv[1][0];
    cv[0][0] += eps2d;
    cv[1][1] += eps2d;
    float det_blur = cv[0][0] * cv[1][1] - cv[0][1] * cv[1][0];
    float ood = 1.f / (+cv[0][0] * cv[1][1] - cv[1][0] * cv[0][1]);
    wp::vec_t<8, wp::float32> out;
    out.c[0] = cv[0][0]; out.c[1] = cv[1][1]; out.c[2] = det_orig; out.c[3] = det_blur;
    out.c[4] = +cv[1][1] * ood; out.c[5] = -cv[0][1] * ood; out.c[6] = +cv[0][0] * ood; out.c[7] = 0.f;
    return out;
"""
)
def covariance_2d(q: wp.vec4, s: wp.vec3, Rview: wp.mat33, J: mat23, eps2d: float) -> vec8: ...


@wp.func
def quat_to_rotmat(q: wp.vec4) -> wp.mat33:
    """Rotation matrix of a unit quaternion q = (w, x, y, z)."""
    w = q[0]
    x = q[1]
    y = q[2]
    z = q[3]
    return wp.mat33(
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
        2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
        2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y),
    )


@wp.func
def quat_to_rotmat_vjp(q: wp.vec4, g: wp.mat33) -> wp.vec4:
    """Gradient w.r.t. the unit quaternion q = (w, x, y, z) given dL/dR = g."""
    w = q[0]
    x = q[1]
    y = q[2]
    z = q[3]
    dw = 2.0 * (-z * g[0, 1] + y * g[0, 2] + z * g[1, 0] - x * g[1, 2] - y * g[2, 0] + x * g[2, 1])
    dx = 2.0 * (
        y * g[0, 1] + z * g[0, 2] + y * g[1, 0] - 2.0 * x * g[1, 1] - w * g[1, 2]
        + z * g[2, 0] + w * g[2, 1] - 2.0 * x * g[2, 2]
    )
    dy = 2.0 * (
        -2.0 * y * g[0, 0] + x * g[0, 1] + w * g[0, 2] + x * g[1, 0] + z * g[1, 2]
        - w * g[2, 0] + z * g[2, 1] - 2.0 * y * g[2, 2]
    )
    dz = 2.0 * (
        -2.0 * z * g[0, 0] - w * g[0, 1] + x * g[0, 2] + w * g[1, 0] - 2.0 * z * g[1, 1]
        + y * g[1, 2] + x * g[2, 0] + y * g[2, 1]
    )
    return wp.vec4(dw, dx, dy, dz)


@wp.func
def view_rotation(V: wp.mat44) -> wp.mat33:
    return wp.mat33(V[0, 0], V[0, 1], V[0, 2], V[1, 0], V[1, 1], V[1, 2], V[2, 0], V[2, 1], V[2, 2])


@wp.func
def clamped_tan(v: float, lim_pos: float, lim_neg: float) -> float:
    return wp.min(lim_pos, wp.max(-lim_neg, v))


@wp.func
def persp_jacobian(p: wp.vec3, fx: float, fy: float, cx: float, cy: float, width: float, height: float):
    """Jacobian of the pinhole projection at camera-space point p, its view direction clamped to
    1.3x the field of view (gsplat; keeps the footprint of far off-screen Gaussians bounded)."""
    tan_fovx = 0.5 * width / fx
    tan_fovy = 0.5 * height / fy
    lim_x_pos = (width - cx) / fx + 0.3 * tan_fovx
    lim_x_neg = cx / fx + 0.3 * tan_fovx
    lim_y_pos = (height - cy) / fy + 0.3 * tan_fovy
    lim_y_neg = cy / fy + 0.3 * tan_fovy
    rz = 1.0 / p[2]
    rz2 = rz * rz
    tx = p[2] * clamped_tan(p[0] * rz, lim_x_pos, lim_x_neg)
    ty = p[2] * clamped_tan(p[1] * rz, lim_y_pos, lim_y_neg)
    J = mat23(fx * rz, 0.0, -fx * tx * rz2, 0.0, fy * rz, -fy * ty * rz2)
    return J


@wp.struct
class Gaussians:
    """Per-Gaussian arrays [N]: world means, quaternions (w, x, y, z, not necessarily unit), scales
    (standard deviations) and opacities. The backward kernel's ``v_gs`` holds their gradients."""

    means: wp.array(dtype=wp.vec3)
    quats: wp.array(dtype=wp.vec4)
    scales: wp.array(dtype=wp.vec3)
    opacities: wp.array(dtype=float)


@wp.struct
class Camera:
    """The view both kernels project through: world-to-camera ``viewmat`` and pinhole ``intrinsics``
    (one-element arrays, so a pose on the GPU is read there without a host copy), the image size in
    pixels, and the screen-space filter: ``eps2d`` added to the 2D covariance's diagonal and, when
    ``antialiased`` != 0, opacity scaled by sqrt(det S2 / det(S2 + eps2d I)) to compensate."""

    viewmat: wp.array(dtype=wp.mat44)
    intrinsics: wp.array(dtype=wp.mat33)
    width: int
    height: int
    eps2d: float
    antialiased: int


@wp.kernel
def project_gaussians_fwd(
    gs: Gaussians,
    cam: Camera,
    near: float,
    far: float,
    tile_size: int,
    tiles_x: int,
    tiles_y: int,
    # outputs
    means2d: wp.array(dtype=wp.vec2),
    conics: wp.array(dtype=wp.vec3),
    depths: wp.array(dtype=float),
    radii: wp.array(dtype=wp.vec2i),
    opac_eff: wp.array(dtype=float),
    tiles_touched: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    radii[i] = wp.vec2i(0, 0)
    tiles_touched[i] = 0
    means2d[i] = wp.vec2(0.0, 0.0)
    conics[i] = wp.vec3(0.0, 0.0, 0.0)
    depths[i] = 0.0
    opac_eff[i] = 0.0

    V = cam.viewmat[0]
    R = view_rotation(V)
    p = R * gs.means[i] + wp.vec3(V[0, 3], V[1, 3], V[2, 3])
    if not (p[2] >= near and p[2] <= far):  # NaN fails too
        return

    Kc = cam.intrinsics[0]
    fx = Kc[0, 0]
    fy = Kc[1, 1]
    cx = Kc[0, 2]
    cy = Kc[1, 2]
    W = float(cam.width)
    H = float(cam.height)

    J = persp_jacobian(p, fx, fy, cx, cy, W, H)
    cv = covariance_2d(gs.quats[i], gs.scales[i], R, J, cam.eps2d)
    a = cv[0]
    c = cv[1]
    det_orig = cv[2]
    det = cv[3]
    if not (det > 0.0):
        return
    if not (wp.isfinite(cv[4]) and wp.isfinite(cv[5]) and wp.isfinite(cv[6])):
        return
    o = gs.opacities[i]
    if cam.antialiased != 0:
        o = o * wp.sqrt(wp.max(0.0, det_orig / det))
    if not (o >= ALPHA_MIN and wp.isfinite(o)):
        return
    extent = wp.min(MAX_EXTENT, wp.sqrt(2.0 * wp.log(o / ALPHA_MIN)))
    rx = wp.ceil(extent * wp.sqrt(a))
    ry = wp.ceil(extent * wp.sqrt(c))
    if rx <= 0.0 and ry <= 0.0:
        return

    rz = 1.0 / p[2]
    m2 = wp.vec2(fx * p[0] * rz + cx, fy * p[1] * rz + cy)
    if not on_screen(m2, rx, ry, p[2]):
        return
    if m2[0] + rx <= 0.0 or m2[0] - rx >= W or m2[1] + ry <= 0.0 or m2[1] - ry >= H:
        return
    rx = wp.min(rx, MAX_RADIUS)
    ry = wp.min(ry, MAX_RADIUS)

    # Tile rectangle [tx0, tx1) x [ty0, ty1), as gsplat's intersect_tile.
    tx0, ty0, tx1, ty1 = tile_rect(m2, rx, ry, tile_size, tiles_x, tiles_y)
    if tx1 <= tx0 or ty1 <= ty0:
        return

    means2d[i] = m2
    conics[i] = wp.vec3(cv[4], cv[5], cv[6])
    depths[i] = p[2]
    radii[i] = wp.vec2i(int(rx), int(ry))
    opac_eff[i] = o
    tiles_touched[i] = (tx1 - tx0) * (ty1 - ty0)


@wp.kernel
def project_gaussians_bwd(
    gs: Gaussians,
    cam: Camera,
    radii: wp.array(dtype=wp.vec2i),
    conics: wp.array(dtype=wp.vec3),
    # gradients of the outputs
    v_means2d: wp.array(dtype=wp.vec2),
    v_conics: wp.array(dtype=wp.vec3),
    v_depths: wp.array(dtype=float),
    v_opac_eff: wp.array(dtype=float),
    # gradients of the inputs, written here: dL/d(gs.means) to v_gs.means, ...
    v_gs: Gaussians,
):
    i = wp.tid()
    r = radii[i]
    if r[0] <= 0 and r[1] <= 0:
        v_gs.means[i] = wp.vec3(0.0)
        v_gs.quats[i] = wp.vec4(0.0)
        v_gs.scales[i] = wp.vec3(0.0)
        v_gs.opacities[i] = 0.0
        return

    V = cam.viewmat[0]
    R = view_rotation(V)
    p = R * gs.means[i] + wp.vec3(V[0, 3], V[1, 3], V[2, 3])
    Kc = cam.intrinsics[0]
    fx = Kc[0, 0]
    fy = Kc[1, 1]
    cx = Kc[0, 2]
    cy = Kc[1, 2]
    W = float(cam.width)
    H = float(cam.height)

    q = gs.quats[i]
    qlen = wp.length(q)
    qn = q / qlen
    s = gs.scales[i]
    Rq = quat_to_rotmat(qn)
    M = Rq * wp.diag(s)
    cov = M * wp.transpose(M)
    cov_c = R * cov * wp.transpose(R)
    J = persp_jacobian(p, fx, fy, cx, cy, W, H)
    cov2 = J * cov_c * wp.transpose(J)

    # conic = inverse(cov2 + eps I): dL/dX = -Y^T G Y^T with G split symmetrically.
    cn = conics[i]
    Y = wp.mat22(cn[0], cn[1], cn[1], cn[2])
    vc = v_conics[i]
    G = wp.mat22(vc[0], 0.5 * vc[1], 0.5 * vc[1], vc[2])
    v_cov2 = -(Y * G * Y)

    o = gs.opacities[i]
    v_oe = v_opac_eff[i]
    if cam.antialiased != 0:
        # comp = sqrt(det(S) / det(S + eps I)); d comp^2/dS = (adj S - comp^2 adj(S + eps I)) / det(S + eps I)
        det_orig = cov2[0, 0] * cov2[1, 1] - cov2[0, 1] * cov2[1, 0]
        a = cov2[0, 0] + cam.eps2d
        c = cov2[1, 1] + cam.eps2d
        det_b = a * c - cov2[0, 1] * cov2[1, 0]
        comp2 = wp.max(0.0, det_orig / det_b)
        comp = wp.sqrt(comp2)
        v_gs.opacities[i] = v_oe * comp
        if comp > 0.0:
            v_comp = v_oe * o
            adj = wp.mat22(cov2[1, 1], -cov2[0, 1], -cov2[1, 0], cov2[0, 0])
            adj_b = wp.mat22(c, -cov2[0, 1], -cov2[1, 0], a)
            v_cov2 = v_cov2 + (v_comp * 0.5 / comp) * (adj - comp2 * adj_b) / det_b
    else:
        v_gs.opacities[i] = v_oe

    # cov2 = J cov_c J^T
    v_cov_c = wp.transpose(J) * v_cov2 * J
    v_J = (v_cov2 + wp.transpose(v_cov2)) * J * cov_c

    # mean2d = (fx x/z + cx, fy y/z + cy), depth = z, and J's dependence on p.
    vm2 = v_means2d[i]
    rz = 1.0 / p[2]
    rz2 = rz * rz
    rz3 = rz2 * rz
    vp = wp.vec3(fx * rz * vm2[0], fy * rz * vm2[1], -(fx * p[0] * vm2[0] + fy * p[1] * vm2[1]) * rz2)
    vp = vp + wp.vec3(0.0, 0.0, v_depths[i])
    tan_fovx = 0.5 * W / fx
    tan_fovy = 0.5 * H / fy
    lim_x_pos = (W - cx) / fx + 0.3 * tan_fovx
    lim_x_neg = cx / fx + 0.3 * tan_fovx
    lim_y_pos = (H - cy) / fy + 0.3 * tan_fovy
    lim_y_neg = cy / fy + 0.3 * tan_fovy
    tx = p[2] * clamped_tan(p[0] * rz, lim_x_pos, lim_x_neg)
    ty = p[2] * clamped_tan(p[1] * rz, lim_y_pos, lim_y_neg)
    vx = vp[0]
    vy = vp[1]
    vz = vp[2]
    if p[0] * rz <= lim_x_pos and p[0] * rz >= -lim_x_neg:
        vx = vx - fx * rz2 * v_J[0, 2]
    else:
        vz = vz - fx * rz3 * v_J[0, 2] * tx
    if p[1] * rz <= lim_y_pos and p[1] * rz >= -lim_y_neg:
        vy = vy - fy * rz2 * v_J[1, 2]
    else:
        vz = vz - fy * rz3 * v_J[1, 2] * ty
    vz = vz - fx * rz2 * v_J[0, 0] - fy * rz2 * v_J[1, 1] + 2.0 * fx * tx * rz3 * v_J[0, 2] + 2.0 * fy * ty * rz3 * v_J[1, 2]

    # p = R mean + t; cov_c = R cov R^T
    v_gs.means[i] = wp.transpose(R) * wp.vec3(vx, vy, vz)
    v_cov = wp.transpose(R) * v_cov_c * R

    # cov = M M^T, M = Rq diag(s)
    v_M = (v_cov + wp.transpose(v_cov)) * M
    v_Rq = v_M * wp.diag(s)
    v_gs.scales[i] = wp.vec3(
        v_M[0, 0] * Rq[0, 0] + v_M[1, 0] * Rq[1, 0] + v_M[2, 0] * Rq[2, 0],
        v_M[0, 1] * Rq[0, 1] + v_M[1, 1] * Rq[1, 1] + v_M[2, 1] * Rq[2, 1],
        v_M[0, 2] * Rq[0, 2] + v_M[1, 2] * Rq[1, 2] + v_M[2, 2] * Rq[2, 2],
    )
    v_qn = quat_to_rotmat_vjp(qn, v_Rq)
    v_gs.quats[i] = (v_qn - qn * wp.dot(qn, v_qn)) / qlen
