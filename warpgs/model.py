"""The Gaussian model: raw parameters as torch ``nn.Parameter``s, their activations, initialisation, PLY I/O.

Raw parameters (gsplat's names; what the optimiser sees and what a 3D-GS PLY stores):

    means      [N, 3]      world positions
    quats      [N, 4]      rotations (w, x, y, z), not necessarily normalised
    scales     [N, 3]      log standard deviations            -> ``exp``
    opacities  [N]         logit opacities                    -> ``sigmoid``
    sh0        [N, 1, 3]   SH DC coefficients (colour = SH * C0 + 0.5)
    shN        [N, K-1, 3] higher SH bands, K = (max_sh_degree + 1)^2

``active_sh_degree`` is the degree rendered now (3D-GS raises it by one every 1000 iterations up to
``max_sh_degree``; the trainer does that). ``render`` applies the activations and calls
``warpgs.render.rasterize``.

PLY files follow the 3D-GS layout that splat viewers read: ``x y z nx ny nz f_dc_0..2 f_rest_0..M
opacity scale_0..2 rot_0..3`` as little-endian float32, with ``f_rest`` stored channel-major
(all coefficients of red, then green, then blue), as the reference implementation writes them.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

from warpgs import ply

SH_C0 = 0.28209479177387814
PARAM_NAMES = ("means", "quats", "scales", "opacities", "sh0", "shN")


def rgb_to_sh(rgb: torch.Tensor) -> torch.Tensor:
    return (rgb - 0.5) / SH_C0


def sh_to_rgb(sh: torch.Tensor) -> torch.Tensor:
    return sh * SH_C0 + 0.5


def num_sh_coeffs(degree: int) -> int:
    return (degree + 1) ** 2


def knn_mean_distance(points: torch.Tensor, k: int = 3, chunk_elems: int = 1 << 25) -> torch.Tensor:
    """sqrt of the mean squared distance of each point to its ``k`` nearest other points (3D-GS's
    initial scale). Exact, chunked brute force: fine for ~1e5 points on a GPU, ~1e4 on a CPU."""
    n = points.shape[0]
    if n < 2:
        return torch.ones(n, device=points.device)
    k = min(k, n - 1)
    p = points.float()
    rows = max(1, chunk_elems // n)
    out = torch.empty(n, device=points.device)
    for s in range(0, n, rows):
        d2 = torch.cdist(p[s:s + rows], p).square_()
        # the k+1 smallest include the point itself (distance 0)
        vals = torch.topk(d2, k + 1, dim=1, largest=False).values[:, 1:]
        out[s:s + rows] = vals.mean(dim=1)
    return out.clamp_min(1e-7).sqrt()


class GaussianModel(nn.Module):
    """3D Gaussians with spherical-harmonic colour. Build with ``from_points``, ``random_box``,
    ``random_frustum`` or ``load_ply``; render with ``render``; save with ``save_ply``."""

    alpha_max = 0.99  # the rasterizer's alpha cap in ``render`` (``model.alpha_max``: the trainer sets its model's)

    def __init__(self, means, quats, scales, opacities, sh0, shN, max_sh_degree: int = 3):
        super().__init__()
        if shN.shape[1] != num_sh_coeffs(max_sh_degree) - 1:
            raise ValueError(f"shN has {shN.shape[1]} coefficients, degree {max_sh_degree} needs "
                             f"{num_sh_coeffs(max_sh_degree) - 1}")
        self.params = nn.ParameterDict({
            name: nn.Parameter(t.detach().float().contiguous().clone())
            for name, t in zip(PARAM_NAMES, (means, quats, scales, opacities, sh0, shN))
        })
        self.max_sh_degree = int(max_sh_degree)
        self.active_sh_degree = 0

    # ------------------------------------------------------------------------------------------
    # construction

    @classmethod
    def from_points(cls, points, colors=None, *, sh_degree: int = 3, init_opacity: float = 0.1,
                    init_scale: float = 1.0, device=None) -> "GaussianModel":
        """One isotropic Gaussian per point: scale = ``init_scale`` x the 3-nearest-neighbour distance,
        identity rotation, opacity ``init_opacity``, DC colour from ``colors`` (RGB in [0, 1]; grey if None)."""
        pts = torch.as_tensor(np.asarray(points) if not torch.is_tensor(points) else points,
                              dtype=torch.float32, device=device)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
            raise ValueError(f"from_points: points must be a non-empty [N, 3] array, got {tuple(pts.shape)}")
        if not bool(torch.isfinite(pts).all()):
            raise ValueError("from_points: points contain NaN or Inf")
        n = pts.shape[0]
        if colors is None:
            rgb = torch.full((n, 3), 0.5, device=pts.device)
        else:
            rgb = torch.as_tensor(np.asarray(colors) if not torch.is_tensor(colors) else colors,
                                  dtype=torch.float32, device=pts.device)
            if rgb.shape != (n, 3):
                raise ValueError(f"from_points: colors must be [{n}, 3], got {tuple(rgb.shape)}")
            if rgb.max() > 1.0 + 1e-6:  # 8-bit colours
                rgb = rgb / 255.0
        dist = knn_mean_distance(pts)
        scales = torch.log(dist * init_scale)[:, None].repeat(1, 3)
        quats = torch.zeros(n, 4, device=pts.device)
        quats[:, 0] = 1.0
        opac = torch.full((n,), math.log(init_opacity / (1 - init_opacity)), device=pts.device)
        sh0 = rgb_to_sh(rgb.clamp(0, 1))[:, None, :]
        shN = torch.zeros(n, num_sh_coeffs(sh_degree) - 1, 3, device=pts.device)
        return cls(pts, quats, scales, opac, sh0, shN, max_sh_degree=sh_degree)

    @classmethod
    def random_box(cls, num: int, lo, hi, *, generator: torch.Generator | None = None, **kw) -> "GaussianModel":
        """``num`` Gaussians uniform in the axis-aligned box [lo, hi] with random colours (3D-GS's
        initialisation when there are no points)."""
        lo = torch.as_tensor(lo, dtype=torch.float32).reshape(3)
        hi = torch.as_tensor(hi, dtype=torch.float32).reshape(3)
        if not bool((hi > lo).all()):
            raise ValueError(f"random_box: need hi > lo, got lo={lo.tolist()} hi={hi.tolist()}")
        pts = lo + (hi - lo) * torch.rand(num, 3, generator=generator)
        rgb = torch.rand(num, 3, generator=generator)
        return cls.from_points(pts, rgb, **kw)

    @classmethod
    def random_hull(cls, num: int, lo, hi, viewmats, Ks, alphas, *, threshold: float = 0.5, dilate: int = 2,
                    generator: torch.Generator | None = None, **kw) -> "GaussianModel":
        """``num`` Gaussians uniform in the visual hull of the views' silhouettes inside the box [lo, hi]:
        box samples kept when every view they project into (in front of it, inside the image) has
        alpha > ``threshold`` within ``dilate`` pixels there. For object captures with an alpha channel
        (Blender): the Gaussians start where the inputs say the object can be, not in empty space."""
        lo = torch.as_tensor(lo, dtype=torch.float32).reshape(3)
        hi = torch.as_tensor(hi, dtype=torch.float32).reshape(3)
        if not bool((hi > lo).all()):
            raise ValueError(f"random_hull: need hi > lo, got lo={lo.tolist()} hi={hi.tolist()}")
        masks = []
        for a in alphas:
            m = torch.as_tensor(np.asarray(a), dtype=torch.float32)[None, None] > threshold
            if dilate > 0:
                m = torch.nn.functional.max_pool2d(m.float(), 2 * dilate + 1, stride=1, padding=dilate) > 0
            masks.append(m[0, 0])
        Vs = [torch.as_tensor(v, dtype=torch.float32) for v in viewmats]
        Ks_t = [torch.as_tensor(k, dtype=torch.float32) for k in Ks]
        kept, have = [], 0
        for _ in range(200):
            pts = lo + (hi - lo) * torch.rand(max(4 * num, 4096), 3, generator=generator)
            ok = torch.ones(len(pts), dtype=torch.bool)
            for V, K, m in zip(Vs, Ks_t, masks):
                pc = pts @ V[:3, :3].T + V[:3, 3]
                z = pc[:, 2]
                uv = (pc @ K.T)[:, :2] / z.clamp_min(1e-9)[:, None]
                u, v = uv[:, 0].floor().long(), uv[:, 1].floor().long()
                seen = (z > 0) & (u >= 0) & (v >= 0) & (u < m.shape[1]) & (v < m.shape[0])
                inside = torch.zeros_like(ok)
                inside[seen] = m[v[seen], u[seen]]
                ok &= ~seen | inside
            kept.append(pts[ok])
            have += int(ok.sum())
            if have >= num:
                break
        if have == 0:
            raise ValueError("random_hull: no point of the box lies inside every silhouette; check the alpha "
                             "channels, the cameras and model.init_box")
        pts = torch.cat(kept)[:num]
        if len(pts) < num:
            _warn(f"random_hull: the visual hull is a small part of the box; {len(pts)} of {num} points found")
        rgb = torch.rand(len(pts), 3, generator=generator)
        return cls.from_points(pts, rgb, **kw)

    @classmethod
    def random_frustum(cls, num: int, viewmats, Ks, sizes, near: float, far: float, *,
                       generator: torch.Generator | None = None, **kw) -> "GaussianModel":
        """``num`` Gaussians inside the cameras' view frusta between depths ``near`` and ``far``: a random
        camera, a random pixel and a depth uniform in [near, far] each (so every depth layer gets the
        same number of points, i.e. the same screen-space density), with random colours."""
        if not (0 < near < far):
            raise ValueError(f"random_frustum: need 0 < near < far, got {near}, {far}")
        cam = torch.randint(len(viewmats), (num,), generator=generator)
        uv = torch.rand(num, 2, generator=generator)
        z = near + (far - near) * torch.rand(num, generator=generator)
        pts = torch.empty(num, 3)
        for c in range(len(viewmats)):
            sel = cam == c
            w, h = sizes[c]
            K = torch.as_tensor(Ks[c], dtype=torch.float64)
            V = torch.as_tensor(viewmats[c], dtype=torch.float64)
            pix = torch.stack([uv[sel, 0] * w, uv[sel, 1] * h, torch.ones(int(sel.sum()))], 1).double()
            pc = (pix @ torch.linalg.inv(K).T) * z[sel, None].double()
            c2w = torch.linalg.inv(V)
            pts[sel] = (pc @ c2w[:3, :3].T + c2w[:3, 3]).float()
        rgb = torch.rand(num, 3, generator=generator)
        return cls.from_points(pts, rgb, **kw)

    @classmethod
    def load_ply(cls, path: str | Path, device=None, drop_invalid: bool = False) -> "GaussianModel":
        """Reads a 3D-GS PLY (the layout ``save_ply`` writes, and what 3D-GS / gsplat export). Gaussians with
        non-finite values make it a ``ValueError`` with their count, or with ``drop_invalid`` are dropped
        with one warning line."""
        v = ply.read_vertices(path)
        need = [k for k in ply.gaussian_fields(0) if k not in ("nx", "ny", "nz")]  # normals are not read
        missing = [k for k in need if k not in v]
        if missing:
            raise ValueError(f"{path}: not a 3D Gaussian Splatting PLY (missing properties {missing}); "
                             "to start from a plain point cloud use the 'ply' initialisation instead")
        n_rest = len([k for k in v if k.startswith("f_rest_")])
        if n_rest % 3:
            raise ValueError(f"{path}: {n_rest} f_rest properties, not a multiple of 3")
        per_channel = n_rest // 3
        degree = int(round(math.sqrt(per_channel + 1))) - 1
        if num_sh_coeffs(degree) - 1 != per_channel or degree > 3:
            raise ValueError(f"{path}: {per_channel} f_rest coefficients per channel match no SH degree 0..3")
        v = ply.keep_finite(v, need + [f"f_rest_{i}" for i in range(n_rest)], path, drop_invalid)

        def col(*names):
            return torch.from_numpy(np.stack([np.asarray(v[k], np.float32) for k in names], axis=1))

        means = col("x", "y", "z")
        sh0 = col("f_dc_0", "f_dc_1", "f_dc_2")[:, None, :]
        rest = col(*[f"f_rest_{i}" for i in range(n_rest)]) if n_rest else torch.zeros(means.shape[0], 0)
        shN = rest.reshape(means.shape[0], 3, per_channel).transpose(1, 2)  # channel-major on disk -> [N, K-1, 3]
        opac = torch.from_numpy(np.asarray(v["opacity"], np.float32))
        scales = col("scale_0", "scale_1", "scale_2")
        quats = col("rot_0", "rot_1", "rot_2", "rot_3")
        m = cls(means, quats, scales, opac, sh0, shN, max_sh_degree=degree)
        m.active_sh_degree = degree
        return m.to(device) if device is not None else m

    # ------------------------------------------------------------------------------------------
    # access

    def __len__(self) -> int:
        return self.params["means"].shape[0]

    @property
    def num_gaussians(self) -> int:
        return len(self)

    @property
    def device(self) -> torch.device:
        return self.params["means"].device

    @property
    def means(self) -> torch.Tensor:
        return self.params["means"]

    @property
    def quats(self) -> torch.Tensor:
        return self.params["quats"]

    @property
    def scales(self) -> torch.Tensor:
        """Standard deviations (activated)."""
        return torch.exp(self.params["scales"])

    @property
    def opacities(self) -> torch.Tensor:
        """Opacities in (0, 1) (activated)."""
        return torch.sigmoid(self.params["opacities"])

    @property
    def sh(self) -> torch.Tensor:
        """All SH coefficients [N, K, 3]."""
        return torch.cat([self.params["sh0"], self.params["shN"]], dim=1)

    def render(self, viewmat, K, width: int, height: int, *, background=None, sh_degree: int | None = None,
               opacity_scale=None, **kwargs):
        """``warpgs.render.rasterize`` of this model (activations applied) -> ``RenderOutput``.
        ``opacity_scale``: (N,) factors on the opacities (DropGaussian's mask and opacity noise,
        ``Trainer.opacity_scale``)."""
        from warpgs.render import rasterize

        deg = self.active_sh_degree if sh_degree is None else min(sh_degree, self.max_sh_degree)
        opac = self.opacities if opacity_scale is None else self.opacities * opacity_scale
        kwargs.setdefault("alpha_max", self.alpha_max)
        return rasterize(self.means, self.quats, self.scales, opac, self.sh, viewmat, K, width, height,
                         sh_degree=deg, background=background, **kwargs)

    # ------------------------------------------------------------------------------------------
    # PLY

    def save_ply(self, path: str | Path) -> Path:
        """Writes the 3D-GS PLY (binary little-endian float32) atomically."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with torch.no_grad():
            p = {k: v.detach().float().cpu().numpy() for k, v in self.params.items()}
        n = p["means"].shape[0]
        rest = np.ascontiguousarray(p["shN"].transpose(0, 2, 1)).reshape(n, -1)  # channel-major
        cols = ([p["means"], np.zeros((n, 3), np.float32), p["sh0"].reshape(n, 3), rest,
                 p["opacities"].reshape(n, 1), p["scales"], p["quats"]])
        data = np.ascontiguousarray(np.concatenate(cols, axis=1).astype("<f4"))
        return ply.write_vertices(path, data.view(ply.float_fields(ply.gaussian_fields(rest.shape[1]))).reshape(n))


def read_point_cloud(path: str | Path, drop_invalid: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Points (N, 3) float32 and colours (N, 3) in [0, 1] (or None) from any vertex PLY: plain
    ``red/green/blue`` (8-bit or float) or a 3D-GS file's DC colour. Points with non-finite coordinates or
    colours are refused with their count, or dropped with one warning line (``drop_invalid``)."""
    v = ply.read_vertices(path)
    if not all(k in v for k in ("x", "y", "z")):
        raise ValueError(f"{path}: PLY vertices have no x, y, z")
    colour_fields = ["red", "green", "blue", "r", "g", "b", "diffuse_red", "diffuse_green", "diffuse_blue",
                     "f_dc_0", "f_dc_1", "f_dc_2"]
    v = ply.keep_finite(v, ["x", "y", "z"] + colour_fields, path, drop_invalid, what="points")
    xyz = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float32)
    rgb = None
    for names in (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
        if all(k in v for k in names):
            a = np.stack([v[k] for k in names], 1)
            rgb = (a.astype(np.float32) / 255.0) if a.dtype.kind in "ui" else a.astype(np.float32)
            break
    if rgb is None and all(f"f_dc_{i}" in v for i in range(3)):
        rgb = np.clip(np.stack([v[f"f_dc_{i}"] for i in range(3)], 1) * SH_C0 + 0.5, 0, 1).astype(np.float32)
    return xyz, rgb


def _warn(msg: str) -> None:
    print(f"warpgs: {msg}", file=sys.stderr)


# sizes: what a model stores and what its PLY takes


def floats_per_gaussian(sh_degree: int) -> int:
    """means 3 + quats 4 + scales 3 + opacity 1 + SH 3 (d + 1)^2."""
    return 3 + 4 + 3 + 1 + 3 * num_sh_coeffs(sh_degree)


def param_bytes(num: int, sh_degree: int) -> int:
    return 4 * num * floats_per_gaussian(sh_degree)


def ply_bytes(num: int, sh_degree: int) -> int:
    """Size of the file ``GaussianModel.save_ply`` writes (header + float32 rows with three normals)."""
    names = ply.gaussian_fields(3 * (num_sh_coeffs(sh_degree) - 1))
    return len(ply.header(num, ply.float_fields(names))) + 4 * num * len(names)


def size_report(model: GaussianModel) -> dict:
    n, d = len(model), model.max_sh_degree
    return {"num_gaussians": n, "sh_degree": d, "param_bytes": param_bytes(n, d), "ply_bytes": ply_bytes(n, d)}
