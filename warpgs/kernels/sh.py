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


def _sh_term(k: int):
    """Y_k(d), and its gradient with respect to d (before normalisation), for one ``k`` fixed when the code is
    generated. The kernels sum over k in loops that Warp unrolls, each step calling its own pair, so the
    compiled code holds no test on k (with k known only at run time, every coefficient went through a chain
    of up to 16 tests). On the H100 this alone did not make the backward faster: its writes did (see
    ``sh_coeffs_bwd``)."""

    @wp.func
    def basis(d: wp.vec3) -> float:
        x = d[0]
        y = d[1]
        z = d[2]
        if wp.static(k == 0):
            return C0
        if wp.static(k == 1):
            return -C1 * y
        if wp.static(k == 2):
            return C1 * z
        if wp.static(k == 3):
            return -C1 * x
        if wp.static(k == 4):
            return C2_0 * x * y
        if wp.static(k == 5):
            return C2_1 * y * z
        if wp.static(k == 6):
            return C2_2 * (2.0 * z * z - x * x - y * y)
        if wp.static(k == 7):
            return C2_3 * x * z
        if wp.static(k == 8):
            return C2_4 * (x * x - y * y)
        if wp.static(k == 9):
            return C3_0 * y * (3.0 * x * x - y * y)
        if wp.static(k == 10):
            return C3_1 * x * y * z
        if wp.static(k == 11):
            return C3_2 * y * (4.0 * z * z - x * x - y * y)
        if wp.static(k == 12):
            return C3_3 * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y)
        if wp.static(k == 13):
            return C3_4 * x * (4.0 * z * z - x * x - y * y)
        if wp.static(k == 14):
            return C3_5 * z * (x * x - y * y)
        return C3_6 * x * (x * x - 3.0 * y * y)

    @wp.func
    def grad(d: wp.vec3) -> wp.vec3:
        x = d[0]
        y = d[1]
        z = d[2]
        if wp.static(k == 0):
            return wp.vec3(0.0)
        if wp.static(k == 1):
            return wp.vec3(0.0, -C1, 0.0)
        if wp.static(k == 2):
            return wp.vec3(0.0, 0.0, C1)
        if wp.static(k == 3):
            return wp.vec3(-C1, 0.0, 0.0)
        if wp.static(k == 4):
            return C2_0 * wp.vec3(y, x, 0.0)
        if wp.static(k == 5):
            return C2_1 * wp.vec3(0.0, z, y)
        if wp.static(k == 6):
            return C2_2 * wp.vec3(-2.0 * x, -2.0 * y, 4.0 * z)
        if wp.static(k == 7):
            return C2_3 * wp.vec3(z, 0.0, x)
        if wp.static(k == 8):
            return C2_4 * wp.vec3(2.0 * x, -2.0 * y, 0.0)
        if wp.static(k == 9):
            return C3_0 * wp.vec3(6.0 * x * y, 3.0 * x * x - 3.0 * y * y, 0.0)
        if wp.static(k == 10):
            return C3_1 * wp.vec3(y * z, x * z, x * y)
        if wp.static(k == 11):
            return C3_2 * wp.vec3(-2.0 * x * y, 4.0 * z * z - x * x - 3.0 * y * y, 8.0 * y * z)
        if wp.static(k == 12):
            return C3_3 * wp.vec3(-6.0 * x * z, -6.0 * y * z, 6.0 * z * z - 3.0 * x * x - 3.0 * y * y)
        if wp.static(k == 13):
            return C3_4 * wp.vec3(4.0 * z * z - 3.0 * x * x - y * y, -2.0 * x * y, 8.0 * x * z)
        if wp.static(k == 14):
            return C3_5 * wp.vec3(2.0 * x * z, -2.0 * y * z, x * x - y * y)
        return C3_6 * wp.vec3(3.0 * x * x - 3.0 * y * y, -6.0 * x * y, 0.0)

    return basis, grad


MAX_COEFFS = 16  # degree 3
_TERMS = [_sh_term(k) for k in range(MAX_COEFFS)]
SH_BASIS = [b for b, _ in _TERMS]  # SH_BASIS[k](d) = Y_k(d)
SH_BASIS_GRAD = [g for _, g in _TERMS]  # SH_BASIS_GRAD[k](d) = dY_k/dd


@wp.func
def sh_color(coeffs: wp.array2d(dtype=wp.vec3), i: int, n: int, d: wp.vec3) -> wp.vec3:
    """0.5 + sum_{k < n} Y_k(d) coeffs[i, k], before the clamp at 0 (n <= coeffs.shape[1])."""
    c = wp.vec3(0.5)
    for k in range(wp.static(MAX_COEFFS)):
        if k < n:
            c = c + wp.static(SH_BASIS[k])(d) * coeffs[i, k]
    return c


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
    c = sh_color(coeffs, i, (degree + 1) * (degree + 1), d)
    colors[i] = wp.vec3(wp.max(c[0], 0.0), wp.max(c[1], 0.0), wp.max(c[2], 0.0))


@wp.func
def sh_basis_of(k: int, d: wp.vec3) -> float:
    """Y_k(d) for a k known only at run time: all sixteen evaluated, one kept (no branch that diverges between
    the lanes of a warp, whose threads hold different k in ``sh_coeffs_bwd``)."""
    y = float(0.0)
    for j in range(wp.static(MAX_COEFFS)):
        y = wp.where(k == j, wp.static(SH_BASIS[j])(d), y)
    return y


@wp.func
def clamp_pass(colors: wp.array(dtype=wp.vec3), v_colors: wp.array(dtype=wp.vec3), i: int) -> wp.vec3:
    """dL/d(colour before the clamp at 0): the clamp passes no gradient where it is active, which is where the
    forward's clamped colour is not above 0."""
    c = colors[i]
    vc = v_colors[i]
    return wp.vec3(wp.where(c[0] > 0.0, vc[0], 0.0), wp.where(c[1] > 0.0, vc[1], 0.0), wp.where(c[2] > 0.0, vc[2], 0.0))


# The backward is two kernels. The coefficients' gradient (K vec3 a Gaussian) is written with one thread per
# (Gaussian, coefficient), so that a warp's stores are contiguous: with one thread per Gaussian each store
# instruction of the warp touched 32 rows 192 bytes apart, and the writes, not the arithmetic, took 0.28 ms
# for 246k Gaussians on an H100 (gsplat: 0.10). The direction's gradient needs every coefficient of a Gaussian,
# so it keeps one thread per Gaussian and only reads them. Both take the clamp's mask from the forward's colours.

@wp.kernel
def sh_coeffs_bwd(
    means: wp.array(dtype=wp.vec3),
    campos: wp.array(dtype=wp.vec3),
    degree: int,
    radii: wp.array(dtype=wp.vec2i),
    colors: wp.array(dtype=wp.vec3),
    v_colors: wp.array(dtype=wp.vec3),
    v_coeffs: wp.array2d(dtype=wp.vec3),
):
    """v_coeffs[i, k] = Y_k(d_i) dL/dcolour_i (0 for k >= (degree + 1)^2 and for Gaussians not seen); one thread
    per (i, k)."""
    t = wp.tid()
    K = v_coeffs.shape[1]
    i = t / K
    k = t - i * K
    r = radii[i]
    if (r[0] <= 0 and r[1] <= 0) or k >= (degree + 1) * (degree + 1):
        v_coeffs[i, k] = wp.vec3(0.0)
        return
    d = wp.normalize(means[i] - campos[0])
    v_coeffs[i, k] = sh_basis_of(k, d) * clamp_pass(colors, v_colors, i)


@wp.kernel
def sh_dir_bwd(
    means: wp.array(dtype=wp.vec3),
    campos: wp.array(dtype=wp.vec3),
    coeffs: wp.array2d(dtype=wp.vec3),
    degree: int,
    radii: wp.array(dtype=wp.vec2i),
    colors: wp.array(dtype=wp.vec3),
    v_colors: wp.array(dtype=wp.vec3),
    v_means: wp.array(dtype=wp.vec3),
):
    """v_means[i]: the gradient through the view direction d = (mean - camera centre) / |...|."""
    i = wp.tid()
    r = radii[i]
    if r[0] <= 0 and r[1] <= 0:
        v_means[i] = wp.vec3(0.0)
        return
    dir = means[i] - campos[0]
    dlen = wp.length(dir)
    d = dir / dlen
    n = (degree + 1) * (degree + 1)
    g = clamp_pass(colors, v_colors, i)
    v_d = wp.vec3(0.0)
    for k in range(wp.static(MAX_COEFFS)):
        if k < n:
            v_d = v_d + wp.static(SH_BASIS_GRAD[k])(d) * wp.dot(coeffs[i, k], g)
    # d = dir / |dir|: dd/ddir = (I - d d^T) / |dir|
    v_means[i] = (v_d - d * wp.dot(d, v_d)) / dlen
