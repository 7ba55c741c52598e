"""View-dependent colour from real spherical harmonics of degree 0..3 (3D-GS basis and ordering).

colour = max(0, sum_k Y_k(d) c_k + 0.5), d the unit direction from the camera centre to the Gaussian.
Only Warp code lives here.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

C0 = wp.constant(0.28209479177387814)
C1 = wp.constant(0.4886025119029199)
C2_0 = wp.constant(1.0925484305920792)
C2_1 = wp.constant(-1.0925484305920792)
C2_2 = wp.constant(0.31539156525252005)
C2_3 = wp.constant(-1.0925484305920792)
C2_4 = wp.constant(0.5462742152960396)
C3_0 = wp.constant(-0.5900435899266435)
C3_1 = wp.constant(2.890611442640554)
C3_2 = wp.constant(-0.4570457994644658)
C3_3 = wp.constant(0.3731763325901154)
C3_4 = wp.constant(-0.4570457994644658)
C3_5 = wp.constant(1.445305721320277)
C3_6 = wp.constant(-0.5900435899266435)


@wp.func
def sh_basis(k: int, d: wp.vec3) -> float:
    x = d[0]
    y = d[1]
    z = d[2]
    if k == 0:
        return C0
    if k == 1:
        return -C1 * y
    if k == 2:
        return C1 * z
    if k == 3:
        return -C1 * x
    if k == 4:
        return C2_0 * x * y
    if k == 5:
        return C2_1 * y * z
    if k == 6:
        return C2_2 * (2.0 * z * z - x * x - y * y)
    if k == 7:
        return C2_3 * x * z
    if k == 8:
        return C2_4 * (x * x - y * y)
    if k == 9:
        return C3_0 * y * (3.0 * x * x - y * y)
    if k == 10:
        return C3_1 * x * y * z
    if k == 11:
        return C3_2 * y * (4.0 * z * z - x * x - y * y)
    if k == 12:
        return C3_3 * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y)
    if k == 13:
        return C3_4 * x * (4.0 * z * z - x * x - y * y)
    if k == 14:
        return C3_5 * z * (x * x - y * y)
    return C3_6 * x * (x * x - 3.0 * y * y)


@wp.func
def sh_basis_grad(k: int, d: wp.vec3) -> wp.vec3:
    """Gradient of ``sh_basis(k, d)`` with respect to d (before normalisation)."""
    x = d[0]
    y = d[1]
    z = d[2]
    if k == 0:
        return wp.vec3(0.0)
    if k == 1:
        return wp.vec3(0.0, -C1, 0.0)
    if k == 2:
        return wp.vec3(0.0, 0.0, C1)
    if k == 3:
        return wp.vec3(-C1, 0.0, 0.0)
    if k == 4:
        return C2_0 * wp.vec3(y, x, 0.0)
    if k == 5:
        return C2_1 * wp.vec3(0.0, z, y)
    if k == 6:
        return C2_2 * wp.vec3(-2.0 * x, -2.0 * y, 4.0 * z)
    if k == 7:
        return C2_3 * wp.vec3(z, 0.0, x)
    if k == 8:
        return C2_4 * wp.vec3(2.0 * x, -2.0 * y, 0.0)
    if k == 9:
        return C3_0 * wp.vec3(6.0 * x * y, 3.0 * x * x - 3.0 * y * y, 0.0)
    if k == 10:
        return C3_1 * wp.vec3(y * z, x * z, x * y)
    if k == 11:
        return C3_2 * wp.vec3(-2.0 * x * y, 4.0 * z * z - x * x - 3.0 * y * y, 8.0 * y * z)
    if k == 12:
        return C3_3 * wp.vec3(-6.0 * x * z, -6.0 * y * z, 6.0 * z * z - 3.0 * x * x - 3.0 * y * y)
    if k == 13:
        return C3_4 * wp.vec3(4.0 * z * z - 3.0 * x * x - y * y, -2.0 * x * y, 8.0 * x * z)
    if k == 14:
        return C3_5 * wp.vec3(2.0 * x * z, -2.0 * y * z, x * x - y * y)
    return C3_6 * wp.vec3(3.0 * x * x - 3.0 * y * y, -6.0 * x * y, 0.0)


@wp.kernel
def sh_to_color_fwd(
    means: wp.array(dtype=wp.vec3),
    campos: wp.array(dtype=wp.vec3),
    coeffs: wp.array2d(dtype=wp.vec3),
    degree: int,
    radii: wp.array(dtype=wp.vec2i),
    colors: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    r = radii[i]
    if r[0] <= 0 and r[1] <= 0:
        colors[i] = wp.vec3(0.0)
        return
    d = wp.normalize(means[i] - campos[0])
    n = (degree + 1) * (degree + 1)
    c = wp.vec3(0.5)
    for k in range(n):
        c = c + sh_basis(k, d) * coeffs[i, k]
    colors[i] = wp.vec3(wp.max(c[0], 0.0), wp.max(c[1], 0.0), wp.max(c[2], 0.0))


@wp.kernel
def sh_to_color_bwd(
    means: wp.array(dtype=wp.vec3),
    campos: wp.array(dtype=wp.vec3),
    coeffs: wp.array2d(dtype=wp.vec3),
    degree: int,
    radii: wp.array(dtype=wp.vec2i),
    v_colors: wp.array(dtype=wp.vec3),
    v_coeffs: wp.array2d(dtype=wp.vec3),
    v_means: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    K = coeffs.shape[1]
    r = radii[i]
    if r[0] <= 0 and r[1] <= 0:
        for k in range(K):
            v_coeffs[i, k] = wp.vec3(0.0)
        v_means[i] = wp.vec3(0.0)
        return
    dir = means[i] - campos[0]
    dlen = wp.length(dir)
    d = dir / dlen
    n = (degree + 1) * (degree + 1)
    c = wp.vec3(0.5)
    for k in range(n):
        c = c + sh_basis(k, d) * coeffs[i, k]
    vc = v_colors[i]
    # The clamp at 0 passes no gradient where it is active.
    g = wp.vec3(wp.where(c[0] > 0.0, vc[0], 0.0), wp.where(c[1] > 0.0, vc[1], 0.0), wp.where(c[2] > 0.0, vc[2], 0.0))
    v_d = wp.vec3(0.0)
    for k in range(K):
        if k < n:
            v_coeffs[i, k] = sh_basis(k, d) * g
            v_d = v_d + sh_basis_grad(k, d) * wp.dot(coeffs[i, k], g)
        else:
            v_coeffs[i, k] = wp.vec3(0.0)
    # d = dir / |dir|: dd/ddir = (I - d d^T) / |dir|
    v_means[i] = (v_d - d * wp.dot(d, v_d)) / dlen
