"""Ray-traced rendering of a textured triangle mesh (the synthetic scene), Warp kernels only.

One thread per (camera, pixel row, pixel column). Primary rays go through a ``wp.Mesh`` BVH
(``wp.mesh_query_ray``); shading is Lambertian under point lights and a directional sun with hard
shadows (``wp.mesh_query_ray_anyhit``) plus an ambient term; albedo is a procedural texture evaluated
at the hit point in world space (checker, stripes, bricks or marble per material, all modulated by
fine Perlin noise), so surfaces carry texture without UV maps. Rays that miss get a sky gradient.

Cameras follow the library's convention: OpenCV axes, pixel (j, i) centred at (j + 0.5, i + 0.5).
The primary ray direction is ``R_c2w @ ((u - cx) / fx, (v - cy) / fy, 1)``, unnormalised, so the hit
parameter ``t`` is the z-depth along the camera axis (not the ray length); misses get depth 0.
"""

import warp as wp

PATTERN_CHECKER = 0
PATTERN_STRIPES = 1
PATTERN_BRICKS = 2
PATTERN_MARBLE = 3
PATTERN_PLAIN = 4


@wp.func
def plane_coords(p: wp.vec3, n: wp.vec3) -> wp.vec2:
    # 2D texture coordinates on the plane the normal is most aligned with (z-up world)
    ax = wp.abs(n[0])
    ay = wp.abs(n[1])
    az = wp.abs(n[2])
    if az >= ax and az >= ay:
        return wp.vec2(p[0], p[1])
    if ax >= ay:
        return wp.vec2(p[1], p[2])
    return wp.vec2(p[0], p[2])


@wp.func
def fract(x: float) -> float:
    # x - floor(x), in [0, 1) for negative x too (wp.frac keeps the sign)
    return x - wp.floor(x)


@wp.func
def fbm(state: wp.uint32, p: wp.vec3, octaves: int) -> float:
    s = float(0.0)
    amp = float(0.5)
    q = p
    for _ in range(octaves):
        s += amp * wp.noise(state, q)
        q = q * 2.03
        amp *= 0.5
    return s


@wp.func
def albedo(
    material: int,
    p: wp.vec3,
    n: wp.vec3,
    color_a: wp.array(dtype=wp.vec3),
    color_b: wp.array(dtype=wp.vec3),
    pattern: wp.array(dtype=wp.int32),
    scale: wp.array(dtype=float),
    state: wp.uint32,
) -> wp.vec3:
    a = color_a[material]
    b = color_b[material]
    s = scale[material]
    kind = pattern[material]
    uv = plane_coords(p, n) / s
    w = float(0.0)
    if kind == 0:  # checker
        w = float((int(wp.floor(uv[0])) + int(wp.floor(uv[1]))) & 1)
    elif kind == 1:  # stripes
        if fract(uv[0] + 0.15 * wp.noise(state, p * 0.7)) > 0.5:
            w = 1.0
    elif kind == 2:  # bricks with mortar lines
        row = wp.floor(uv[1] * 2.0)
        off = 0.5 * float(int(row) & 1)
        fu = fract(uv[0] + off)
        fv = fract(uv[1] * 2.0)
        if fu < 0.06 or fv < 0.1:
            w = 1.0
        else:
            w = 0.25 * (0.5 + 0.5 * wp.noise(state, wp.vec3(wp.floor(uv[0] + off), row, 3.7)))
    elif kind == 3:  # marble veins
        w = 0.5 + 0.5 * wp.sin(6.0 * uv[0] + 8.0 * fbm(state, p / s, 4))
    c = a * (1.0 - w) + b * w
    # fine detail everywhere, so that every surface has photometric texture
    detail = 0.82 + 0.36 * (0.5 + 0.5 * fbm(state, p * (9.0 / s), 3))
    return c * detail


@wp.func
def shade(
    mesh: wp.uint64,
    p: wp.vec3,
    n: wp.vec3,
    base: wp.vec3,
    light_pos: wp.array(dtype=wp.vec3),
    light_power: wp.array(dtype=wp.vec3),
    sun_dir: wp.vec3,
    sun_color: wp.vec3,
    ambient: wp.vec3,
) -> wp.vec3:
    eps = 1.0e-3
    o = p + n * eps
    acc = ambient
    for k in range(light_pos.shape[0]):
        d = light_pos[k] - p
        dist2 = wp.dot(d, d)
        cosl = wp.dot(n, d) / wp.sqrt(dist2)
        if cosl > 0.0:
            if not wp.mesh_query_ray_anyhit(mesh, o, d, 0.999):
                acc = acc + light_power[k] * (cosl / (1.0 + dist2))
    cs = wp.dot(n, sun_dir)
    if cs > 0.0 and wp.length(sun_color) > 0.0:
        if not wp.mesh_query_ray_anyhit(mesh, o, sun_dir, 1.0e6):
            acc = acc + sun_color * cs
    return wp.cw_mul(base, acc)


@wp.kernel
def render_mesh(
    mesh: wp.uint64,
    face_material: wp.array(dtype=wp.int32),
    color_a: wp.array(dtype=wp.vec3),
    color_b: wp.array(dtype=wp.vec3),
    pattern: wp.array(dtype=wp.int32),
    scale: wp.array(dtype=float),
    light_pos: wp.array(dtype=wp.vec3),
    light_power: wp.array(dtype=wp.vec3),
    sun_dir: wp.vec3,
    sun_color: wp.vec3,
    ambient: wp.vec3,
    sky_zenith: wp.vec3,
    sky_horizon: wp.vec3,
    c2w_rot: wp.array(dtype=wp.mat33),
    c2w_pos: wp.array(dtype=wp.vec3),
    intrinsics: wp.array(dtype=wp.vec4),  # fx, fy, cx, cy
    samples_per_side: int,
    seed: int,
    max_depth: float,
    rgb: wp.array3d(dtype=wp.vec3),
    depth: wp.array3d(dtype=float),
):
    cam, i, j = wp.tid()
    R = c2w_rot[cam]
    o = c2w_pos[cam]
    K = intrinsics[cam]
    state = wp.rand_init(seed)

    # depth from the pixel centre's ray
    dc = R @ wp.vec3((float(j) + 0.5 - K[2]) / K[0], (float(i) + 0.5 - K[3]) / K[1], 1.0)
    hc = wp.mesh_query_ray(mesh, o, dc, max_depth)
    z = float(0.0)
    if hc.result:
        z = hc.t
    depth[cam, i, j] = z

    # colour: mean of a regular grid of sub-pixel rays
    acc = wp.vec3(0.0)
    ns = samples_per_side
    for sy in range(ns):
        for sx in range(ns):
            u = float(j) + (float(sx) + 0.5) / float(ns)
            v = float(i) + (float(sy) + 0.5) / float(ns)
            d = R @ wp.vec3((u - K[2]) / K[0], (v - K[3]) / K[1], 1.0)
            h = wp.mesh_query_ray(mesh, o, d, max_depth)
            if h.result:
                p = o + d * h.t
                n = h.normal
                if wp.dot(n, d) > 0.0:
                    n = -n
                m = face_material[h.face]
                base = albedo(m, p, n, color_a, color_b, pattern, scale, state)
                acc = acc + shade(mesh, p, n, base, light_pos, light_power, sun_dir, sun_color, ambient)
            else:
                up = wp.normalize(d)[2]
                t = wp.clamp(up, 0.0, 1.0)
                acc = acc + sky_horizon * (1.0 - t) + sky_zenith * t
    c = acc / float(ns * ns)
    # simple tone curve: gamma 1/2.2 after clamping
    c = wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))
    rgb[cam, i, j] = wp.vec3(wp.pow(c[0], 1.0 / 2.2), wp.pow(c[1], 1.0 / 2.2), wp.pow(c[2], 1.0 / 2.2))
