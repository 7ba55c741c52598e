"""A slow, obviously-correct torch rasterizer used only as the tests' oracle.

No tiles lists, no sorting kernels, no hand-written gradients: every Gaussian is evaluated at every
pixel, Gaussians are composited front to back in depth order with a plain Python loop, and torch's
autograd gives the gradients. It applies the same rules as the kernels (gsplat 1.5 / 3D-GS): near/far
culling, 0.3 px dilation, opacity-aware screen box rounded out to 16 px tiles, alpha < 1/255 skipped,
alpha clamp, stop before T <= 1e-4. One rule is the kernels' own: a pair past the Mahalanobis half-distance
SIGMA_SKIP is skipped whatever the opacity (it is gsplat's alpha < 1/255 test for opacities up to 1; DropGaussian's
compensated opacities exceed 1).
"""

from __future__ import annotations

import math

import torch

TILE = 16
SIGMA_SKIP = 5.55  # warpgs.kernels.rasterize.SIGMA_SKIP
SH_C = [
    0.28209479177387814,
    0.4886025119029199,
    [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396],
    [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
     1.445305721320277, -0.5900435899266435],
]


def quat_to_rotmat(q):
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(*q.shape[:-1], 3, 3)


def sh_colors(coeffs, dirs, degree):
    d = dirs / dirs.norm(dim=-1, keepdim=True)
    x, y, z = d[:, 0:1], d[:, 1:2], d[:, 2:3]
    c = SH_C[0] * coeffs[:, 0]
    if degree > 0:
        c = c - SH_C[1] * y * coeffs[:, 1] + SH_C[1] * z * coeffs[:, 2] - SH_C[1] * x * coeffs[:, 3]
    if degree > 1:
        C2 = SH_C[2]
        c = (c + C2[0] * x * y * coeffs[:, 4] + C2[1] * y * z * coeffs[:, 5]
             + C2[2] * (2 * z * z - x * x - y * y) * coeffs[:, 6] + C2[3] * x * z * coeffs[:, 7]
             + C2[4] * (x * x - y * y) * coeffs[:, 8])
    if degree > 2:
        C3 = SH_C[3]
        c = (c + C3[0] * y * (3 * x * x - y * y) * coeffs[:, 9] + C3[1] * x * y * z * coeffs[:, 10]
             + C3[2] * y * (4 * z * z - x * x - y * y) * coeffs[:, 11]
             + C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y) * coeffs[:, 12]
             + C3[4] * x * (4 * z * z - x * x - y * y) * coeffs[:, 13]
             + C3[5] * z * (x * x - y * y) * coeffs[:, 14] + C3[6] * x * (x * x - 3 * y * y) * coeffs[:, 15])
    return torch.clamp_min(c + 0.5, 0.0)


def project(means, quats, scales, opacities, viewmat, K, width, height, eps2d=0.3, near=0.01, far=1e10,
            antialiased=False):
    """Returns means2d [N,2], conics [N,3], depths [N], effective opacities [N], radii [N,2] (0 = culled)."""
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    p = means @ R.T + t
    Rq = quat_to_rotmat(quats)
    M = Rq * scales[:, None, :]
    cov_c = R @ (M @ M.transpose(1, 2)) @ R.T
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x, y, z = p.unbind(-1)
    tanx, tany = 0.5 * width / fx, 0.5 * height / fy
    tx = z * torch.clamp(x / z, min=-(cx / fx + 0.3 * tanx), max=(width - cx) / fx + 0.3 * tanx)
    ty = z * torch.clamp(y / z, min=-(cy / fy + 0.3 * tany), max=(height - cy) / fy + 0.3 * tany)
    zero = torch.zeros_like(z)
    J = torch.stack([fx / z, zero, -fx * tx / z**2, zero, fy / z, -fy * ty / z**2], -1).reshape(-1, 2, 3)
    cov2 = J @ cov_c @ J.transpose(1, 2)
    eye = torch.eye(2, dtype=means.dtype, device=means.device)
    cov2b = cov2 + eps2d * eye
    det_b = torch.linalg.det(cov2b)
    conic_m = torch.linalg.inv(cov2b)
    conics = torch.stack([conic_m[:, 0, 0], conic_m[:, 0, 1], conic_m[:, 1, 1]], -1)
    o = opacities
    if antialiased:
        o = o * torch.sqrt(torch.clamp_min(torch.linalg.det(cov2) / det_b, 0.0))
    means2d = torch.stack([fx * x / z + cx, fy * y / z + cy], -1)

    with torch.no_grad():
        keep = (z >= near) & (z <= far) & (det_b > 0) & (o >= 1 / 255)
        extent = torch.clamp(torch.sqrt(2 * torch.log(torch.clamp_min(o, 1e-30) * 255)), max=3.33)
        rx = torch.ceil(extent * torch.sqrt(cov2b[:, 0, 0].clamp_min(0)))
        ry = torch.ceil(extent * torch.sqrt(cov2b[:, 1, 1].clamp_min(0)))
        keep &= (rx > 0) | (ry > 0)
        m = means2d
        keep &= ~((m[:, 0] + rx <= 0) | (m[:, 0] - rx >= width) | (m[:, 1] + ry <= 0) | (m[:, 1] - ry >= height))
        radii = torch.where(keep[:, None], torch.stack([rx, ry], -1), torch.zeros_like(means2d)).to(torch.int32)
    return means2d, conics, z, o, radii


def tile_mask(means2d, radii, width, height):
    """[N, H, W] bool: pixel lies in a 16x16 tile touched by the Gaussian's screen box."""
    tiles_x, tiles_y = math.ceil(width / TILE), math.ceil(height / TILE)
    m = means2d.detach().double()
    r = radii.double()
    tx0 = torch.clamp(torch.floor((m[:, 0] - r[:, 0]) / TILE), 0, tiles_x)
    ty0 = torch.clamp(torch.floor((m[:, 1] - r[:, 1]) / TILE), 0, tiles_y)
    tx1 = torch.clamp(torch.ceil((m[:, 0] + r[:, 0]) / TILE), 0, tiles_x)
    ty1 = torch.clamp(torch.ceil((m[:, 1] + r[:, 1]) / TILE), 0, tiles_y)
    jt = (torch.arange(width, device=m.device) // TILE).double()
    it = (torch.arange(height, device=m.device) // TILE).double()
    in_x = (jt[None] >= tx0[:, None]) & (jt[None] < tx1[:, None])
    in_y = (it[None] >= ty0[:, None]) & (it[None] < ty1[:, None])
    visible = (radii[:, 0] > 0) | (radii[:, 1] > 0)
    return in_y[:, :, None] & in_x[:, None, :] & visible[:, None, None]


def render(means, quats, scales, opacities, colors, viewmat, K, width, height, *, sh_degree=None,
           background=None, eps2d=0.3, near=0.01, far=1e10, antialiased=False, alpha_max=0.99):
    """Returns image [H,W,3], expected depth [H,W], alpha [H,W], means2d [N,2] (an autograd node)."""
    dt, dev = means.dtype, means.device
    means2d, conics, depths, o, radii = project(means, quats, scales, opacities, viewmat, K, width, height,
                                                eps2d, near, far, antialiased)
    if sh_degree is not None:
        campos = -(viewmat[:3, :3].T @ viewmat[:3, 3])
        rgb = sh_colors(colors, means - campos, sh_degree)
    else:
        rgb = colors
    if background is None:
        background = torch.zeros(3, dtype=dt, device=dev)
    py, px = torch.meshgrid(torch.arange(height, dtype=dt, device=dev) + 0.5,
                            torch.arange(width, dtype=dt, device=dev) + 0.5, indexing="ij")
    mask = tile_mask(means2d, radii, width, height)
    image = torch.zeros(height, width, 3, dtype=dt, device=dev)
    dsum = torch.zeros(height, width, dtype=dt, device=dev)
    T = torch.ones(height, width, dtype=dt, device=dev)
    done = torch.zeros(height, width, dtype=torch.bool, device=dev)
    for g in torch.argsort(depths.detach(), stable=True).tolist():
        dx = means2d[g, 0] - px
        dy = means2d[g, 1] - py
        sigma = 0.5 * (conics[g, 0] * dx * dx + conics[g, 2] * dy * dy) + conics[g, 1] * dx * dy
        alpha = torch.clamp(o[g] * torch.exp(-sigma), max=alpha_max)
        # past SIGMA_SKIP (5.55: alpha < 1/255 for any opacity up to 1) a pair is skipped whatever its opacity
        use = mask[g] & (sigma >= 0) & (sigma <= SIGMA_SKIP) & (alpha >= 1 / 255) & ~done
        next_T = T * (1 - alpha)
        stop = use & (next_T <= 1e-4)
        done = done | stop
        use = use & ~stop
        w = torch.where(use, alpha * T, torch.zeros_like(T))
        image = image + w[..., None] * rgb[g]
        dsum = dsum + w * depths[g]
        T = torch.where(use, next_T, T)
    image = image + T[..., None] * background
    alpha_img = 1 - T
    depth = torch.where(alpha_img > 1e-6, dsum / alpha_img.clamp_min(1e-6), torch.zeros_like(dsum))
    return image, depth, alpha_img, means2d
