"""Video backends for the pseudo-view sampler (``warpgs.pseudo.sampler.VideoBackend``).

``GaussianVideoBackend`` ("default", no weights)
    A Gaussian video prior centred on the 3D-GS renders: the true video is ``x0 = m + r`` with ``m``
    the renders (frame 0 replaced by the conditioning image, which is the truth there) and ``r`` a
    zero-mean Gaussian residual, smooth in space and time (squared-exponential correlation with
    lengths ``length`` x image width and ``length_frames``) plus a pixel-independent part for detail
    the render lacks. Its covariance is diagonal in the 3-D DCT-II basis (stationary with reflecting
    boundaries), so the optimal (MMSE) denoiser is exact and cheap, a Wiener filter:
    ``x0_hat = m + D^T [S / (S + sigma^2)] D (x - m)``. Run through the same modulated sampler, the
    reliable guidance is fused in and the prior spreads the guidance-minus-render residual smoothly
    into the unreliable pixels, across neighbouring frames too: a temporally consistent fill of the
    render. By default sampling starts from zero noise (``noise_scale = 0``), the deterministic path
    whose result is the smooth fill rather than a random draw. It is not a learned video model: it
    cannot invent content that neither the inputs nor the 3D-GS render show, which is where the
    paper's gains come from.

``SVDBackend`` ("svd")
    Stable Video Diffusion img2vid / img2vid-xt through diffusers, loaded from a local folder in the
    Hugging Face layout (``load_svd``): UNetSpatioTemporalConditionModel (v-prediction, EDM
    preconditioning), AutoencoderKLTemporalDecoder, CLIPVisionModelWithProjection, the scheduler's
    Karras sigmas, classifier-free guidance ramped over frames as ``StableVideoDiffusionPipeline``
    does it (unconditional branch with zero image embedding and zero image latents), fps - 1,
    motion bucket and noise augmentation as added time ids. fp16 on CUDA, fp32 on the CPU.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F

from .sampler import karras_sigmas

SVD_REPO = "stabilityai/stable-video-diffusion-img2vid-xt"
SVD_ENV = "WARPGS_SVD_PATH"
# The scheduler facts of SVD's EulerDiscreteScheduler (METHOD_NOTES); without timestep_type and
# steps_offset the scheduler's step indexing breaks, so they are enforced whatever the file says.
SVD_SCHEDULER = dict(
    prediction_type="v_prediction", beta_schedule="scaled_linear", beta_start=0.00085, beta_end=0.012,
    use_karras_sigmas=True, sigma_min=0.002, sigma_max=700.0, timestep_spacing="leading",
    timestep_type="continuous", steps_offset=1, interpolation_type="linear", num_train_timesteps=1000,
)
CLIP_MEAN = (0.48145466, 0.4578275, 0.40821073)
CLIP_STD = (0.26862954, 0.26130258, 0.27577711)


def _to_chw(frames: torch.Tensor) -> torch.Tensor:
    return frames.permute(0, 3, 1, 2)


def _to_hwc(frames: torch.Tensor) -> torch.Tensor:
    return frames.permute(0, 2, 3, 1)


# ----------------------------------------------------------------------------------------------
# the weight-free default


@dataclass
class DefaultBackendConfig:
    prior_std: float = 0.15  # std of the smooth residual between the 3D-GS render and the truth
    detail_std: float = 0.05  # std of the pixel-independent residual (detail the render lacks)
    length: float = 0.04  # spatial correlation length, x image width
    length_frames: float = 3.0  # temporal correlation length, frames
    sigma_min: float = 0.002
    sigma_max: float = 4.0  # colours are in [0, 1]; well above the prior's spread
    noise_scale: float = 0.0  # 0: the deterministic path (smooth fill); 1: a random draw from the prior


def dct_matrix(n: int, device=None, dtype=torch.float64) -> torch.Tensor:
    """Orthonormal DCT-II matrix [n, n]: rows are the basis vectors (D @ x transforms x)."""
    k = torch.arange(n, dtype=torch.float64)[:, None]
    i = torch.arange(n, dtype=torch.float64)[None]
    D = torch.cos(math.pi * (i + 0.5) * k / n) * math.sqrt(2.0 / n)
    D[0] /= math.sqrt(2.0)
    return D.to(device=device, dtype=dtype)


def gaussian_spectrum(n: int, length: float, device=None) -> torch.Tensor:
    """Squared-exponential correlation of ``length`` samples in the DCT-II basis, normalised to mean 1
    (so the residual's variance per sample is its std^2 on average)."""
    w = math.pi * torch.arange(n, dtype=torch.float64) / n
    g = torch.exp(-0.5 * (length * w) ** 2)
    return (g * n / g.sum()).to(device)


class GaussianVideoBackend:
    """The weight-free default backend: an exact MMSE denoiser for a Gaussian video prior (see module doc)."""

    name = "default"

    def __init__(self, cfg: DefaultBackendConfig | None = None):
        self.cfg = cfg or DefaultBackendConfig()
        self.default_noise_scale = self.cfg.noise_scale
        self._cache: dict = {}

    def sigmas(self, steps: int, device) -> torch.Tensor:
        return karras_sigmas(steps, self.cfg.sigma_min, self.cfg.sigma_max).to(device)

    def init_noise_sigma(self, sigmas: torch.Tensor) -> float:
        return float(sigmas[0])

    def prior_mean(self, cond: torch.Tensor) -> torch.Tensor:
        return cond

    def latent_shape(self, height: int, width: int) -> tuple[int, int, int]:
        return 3, height, width

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        return _to_chw(frames).contiguous()

    def decode(self, latents: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
        x = latents.clamp(0.0, 1.0)
        if tuple(x.shape[-2:]) != tuple(size):
            x = F.interpolate(x, size=size, mode="bilinear", align_corners=False, antialias=True)
        return _to_hwc(x).contiguous()

    def basis(self, n: int, h: int, w: int, device) -> tuple:
        """(D_t, D_y, D_x, S) with S [n, h, w] the smooth part's spectrum (variance per DCT coefficient)."""
        key = (n, h, w, str(device))
        if key not in self._cache:
            c = self.cfg
            St = gaussian_spectrum(n, c.length_frames)
            Sy = gaussian_spectrum(h, c.length * w)
            Sx = gaussian_spectrum(w, c.length * w)
            S = c.prior_std**2 * St[:, None, None] * Sy[None, :, None] * Sx[None, None, :]
            f32 = dict(device=device, dtype=torch.float32)
            self._cache = {key: (dct_matrix(n, **f32), dct_matrix(h, **f32), dct_matrix(w, **f32), S.to(**f32))}
        return self._cache[key]

    def condition(self, image: torch.Tensor, n_frames: int, prior: torch.Tensor | None = None,
                  generator: torch.Generator | None = None) -> torch.Tensor:
        """The prior mean [N, 3, H, W]: the renders with frame 0 set to the conditioning image
        (a constant mid-grey where no renders are given)."""
        if prior is None:
            m = torch.full((n_frames, *image.shape), 0.5, device=image.device)
        else:
            m = prior.clone()
        m[0] = image
        return _to_chw(m).contiguous()

    def transform(self, r: torch.Tensor, inverse: bool = False) -> torch.Tensor:
        """3-D DCT-II over (frame, row, column) of r [N, C, H, W] (or its inverse), as three matmuls."""
        n, c, h, w = r.shape
        Dt, Dy, Dx, _ = self.basis(n, h, w, r.device)
        if inverse:
            Dt, Dy, Dx = Dt.T, Dy.T, Dx.T
        r = torch.matmul(r, Dx.T)  # columns
        r = torch.matmul(Dy, r)  # rows
        return (Dt @ r.reshape(n, -1)).reshape(n, c, h, w)  # frames

    def spectrum(self, n: int, h: int, w: int, device) -> torch.Tensor:
        """Total prior variance per DCT coefficient [n, 1, h, w] (smooth part + detail)."""
        S = self.basis(n, h, w, device)[3]
        return (S + self.cfg.detail_std**2)[:, None]

    def denoise(self, x: torch.Tensor, sigma: float, cond: torch.Tensor) -> torch.Tensor:
        n, _, h, w = x.shape
        S = self.spectrum(n, h, w, x.device)
        R = self.transform(x - cond)
        return cond + self.transform(R * (S / (S + sigma * sigma)), inverse=True)


# ----------------------------------------------------------------------------------------------
# Stable Video Diffusion


@dataclass
class SVDConfig:
    path: str | None = None  # local folder with the HF layout; None: $WARPGS_SVD_PATH
    width: int | None = None  # model resolution; None: the frames' aspect at about 1024 x 576, multiples of 64
    height: int | None = None
    fps: int = 7
    motion_bucket_id: int = 127
    noise_aug_strength: float = 0.02
    min_guidance_scale: float = 1.0  # classifier-free guidance ramps from min (frame 0) to max (frame N-1)
    max_guidance_scale: float = 3.0
    decode_chunk_size: int = 8
    dtype: str = "auto"  # auto: float16 on CUDA, float32 on the CPU


class SVDWeightsNotFound(FileNotFoundError):
    pass


def svd_missing_message(path: str | None, problem: str) -> str:
    where = path or "<folder>"
    return (
        f"Stable Video Diffusion weights: {problem}.\n"
        f"Download {SVD_REPO} from Hugging Face into a local folder, e.g.\n"
        f"    huggingface-cli download {SVD_REPO} --local-dir {where}\n"
        f"(it must hold model_index.json and the folders unet/, vae/, image_encoder/, scheduler/, "
        f"feature_extractor/), then pass --svd-path {where} or set {SVD_ENV}={where}. "
        f"The weight-free default backend (--pseudo-backend default) needs nothing."
    )


def resolve_svd_path(path: str | os.PathLike | None = None) -> Path:
    p = path if path is not None else os.environ.get(SVD_ENV)
    if not p:
        raise SVDWeightsNotFound(svd_missing_message(None, f"no folder given (--svd-path or ${SVD_ENV})"))
    p = Path(p).expanduser()
    if not p.is_dir():
        raise SVDWeightsNotFound(svd_missing_message(str(p), f"{p} is not a folder"))
    missing = [s for s in ("model_index.json", "unet", "vae", "image_encoder", "scheduler") if not (p / s).exists()]
    if missing:
        raise SVDWeightsNotFound(svd_missing_message(str(p), f"{p} lacks {', '.join(missing)}"))
    return p


def _import_diffusers():
    try:
        import diffusers  # noqa: F401
        import transformers  # noqa: F401
    except ImportError as e:
        raise ImportError("the svd backend needs diffusers and transformers: pip install 'warpgs[svd]' "
                          f"({e})") from e
    import diffusers

    return diffusers


def _auto_size(height: int, width: int, area: int = 576 * 1024, multiple: int = 64) -> tuple[int, int]:
    s = math.sqrt(area / (height * width))
    return (max(multiple, int(round(height * s / multiple)) * multiple),
            max(multiple, int(round(width * s / multiple)) * multiple))


@dataclass
class SVDCondition:
    embeddings: torch.Tensor  # [B, 1, D] CLIP image embedding (B = 2 with classifier-free guidance)
    image_latents: torch.Tensor  # [B, N, C, h, w] conditioning latents (not scaled), per frame
    time_ids: torch.Tensor  # [B, 3] (fps - 1, motion bucket, noise augmentation)
    guidance_scale: torch.Tensor | None  # [1, N, 1, 1, 1] or None without CFG


class SVDBackend:
    """Stable Video Diffusion (img2vid / img2vid-xt) as a sampler backend (see module doc)."""

    name = "svd"
    default_noise_scale = 1.0

    def __init__(self, unet, vae, image_encoder, scheduler, cfg: SVDConfig | None = None, image_mean=CLIP_MEAN,
                 image_std=CLIP_STD):
        self.unet, self.vae, self.image_encoder, self.scheduler = unet, vae, image_encoder, scheduler
        self.cfg = cfg or SVDConfig()
        self.device = unet.device
        self.dtype = unet.dtype
        self.vae_scale = 2 ** (len(vae.config.block_out_channels) - 1)
        self.clip_size = int(image_encoder.config.image_size)
        self.image_mean = torch.tensor(image_mean, dtype=torch.float32).view(1, 3, 1, 1)
        self.image_std = torch.tensor(image_std, dtype=torch.float32).view(1, 3, 1, 1)
        self._size: tuple[int, int] | None = None

    # -- loading ---------------------------------------------------------------------------------

    @classmethod
    def from_pretrained(cls, path=None, device="cpu", cfg: SVDConfig | None = None) -> "SVDBackend":
        """Loads the pipeline's components from a local folder (``path``, else ``cfg.path``, else
        ``$WARPGS_SVD_PATH``); a clear error names what to download when they are absent."""
        cfg = cfg or SVDConfig()
        root = resolve_svd_path(path if path is not None else cfg.path)
        diffusers = _import_diffusers()
        device = torch.device(device)
        if cfg.dtype == "auto":
            dtype = torch.float16 if device.type == "cuda" else torch.float32
        else:
            dtype = getattr(torch, cfg.dtype)
        variant = "fp16" if dtype == torch.float16 and any((root / "unet").glob("*.fp16.*")) else None
        with warnings.catch_warnings():  # newer diffusers rename torch_dtype to dtype; both accept torch_dtype
            warnings.filterwarnings("ignore", message=".*torch_dtype.*", category=FutureWarning)
            pipe = diffusers.StableVideoDiffusionPipeline.from_pretrained(root, torch_dtype=dtype, variant=variant)
        pipe.to(device)
        sched_cfg = dict(pipe.scheduler.config)
        sched_cfg.update({k: v for k, v in SVD_SCHEDULER.items() if k not in ("sigma_min", "sigma_max")})
        sched_cfg["sigma_min"] = pipe.scheduler.config.get("sigma_min") or SVD_SCHEDULER["sigma_min"]
        sched_cfg["sigma_max"] = pipe.scheduler.config.get("sigma_max") or SVD_SCHEDULER["sigma_max"]
        scheduler = diffusers.EulerDiscreteScheduler.from_config(sched_cfg)
        fe = getattr(pipe, "feature_extractor", None)
        mean = tuple(getattr(fe, "image_mean", None) or CLIP_MEAN)
        std = tuple(getattr(fe, "image_std", None) or CLIP_STD)
        return cls(pipe.unet, pipe.vae, pipe.image_encoder, scheduler, cfg, mean, std)

    # -- geometry --------------------------------------------------------------------------------

    def model_size(self, height: int, width: int) -> tuple[int, int]:
        if self.cfg.height and self.cfg.width:
            return int(self.cfg.height), int(self.cfg.width)
        return _auto_size(height, width, multiple=max(8, self.vae_scale * 8))

    def latent_shape(self, height: int, width: int) -> tuple[int, int, int]:
        mh, mw = self.model_size(height, width)
        return int(self.vae.config.latent_channels), mh // self.vae_scale, mw // self.vae_scale

    def _resize(self, x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
        if tuple(x.shape[-2:]) == tuple(size):
            return x
        return F.interpolate(x, size=size, mode="bilinear", align_corners=False, antialias=True)

    # -- schedule ------------------------------------------------------------------------------

    def sigmas(self, steps: int, device) -> torch.Tensor:
        self.scheduler.set_timesteps(steps, device="cpu")
        return self.scheduler.sigmas.float().to(device)

    def prior_mean(self, cond: SVDCondition) -> float:
        return 0.0

    def init_noise_sigma(self, sigmas: torch.Tensor) -> float:
        if self.scheduler.config.timestep_spacing in ("linspace", "trailing"):
            return float(sigmas.max())
        return float((sigmas.max() ** 2 + 1) ** 0.5)

    # -- VAE -------------------------------------------------------------------------------------

    def _vae_encode(self, images: torch.Tensor) -> torch.Tensor:
        """images [B, 3, h, w] in [-1, 1] -> latent mode, the VAE upcast to float32 where its config asks."""
        upcast = self.vae.dtype == torch.float16 and getattr(self.vae.config, "force_upcast", False)
        if upcast:
            self._vae_dtype(torch.float32)
        try:
            with torch.no_grad():
                return self.vae.encode(images.to(self.device, self.vae.dtype)).latent_dist.mode().float()
        finally:
            if upcast:
                self._vae_dtype(torch.float16)

    def _vae_dtype(self, dtype) -> None:
        """Casts the VAE as the pipeline does around encoding, without diffusers' warning about ``to()``."""
        from diffusers.utils import logging as dlog

        level = dlog.get_verbosity()
        dlog.set_verbosity_error()
        try:
            self.vae.to(dtype=dtype)
        finally:
            dlog.set_verbosity(level)

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        size = self.model_size(*frames.shape[1:3])
        x = self._resize(_to_chw(frames.float()), size) * 2.0 - 1.0
        chunk = max(1, self.cfg.decode_chunk_size)
        lat = torch.cat([self._vae_encode(x[i:i + chunk]) for i in range(0, len(x), chunk)])
        return lat * float(self.vae.config.scaling_factor)

    def decode(self, latents: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
        z = latents / float(self.vae.config.scaling_factor)
        chunk = max(1, self.cfg.decode_chunk_size)
        out = []
        with torch.no_grad():
            for i in range(0, len(z), chunk):
                zi = z[i:i + chunk].to(self.device, self.vae.dtype)
                out.append(self.vae.decode(zi, num_frames=len(zi)).sample.float())
        x = (torch.cat(out) / 2.0 + 0.5).clamp(0.0, 1.0)
        return _to_hwc(self._resize(x, size).clamp(0.0, 1.0)).contiguous()

    # -- conditioning and the denoiser ------------------------------------------------------------

    def clip_embedding(self, image: torch.Tensor) -> torch.Tensor:
        """CLIP image embedding [1, 1, D] of image [H, W, 3] in [0, 1], preprocessed as the pipeline does
        for PIL input (antialiased resize to 224 in [-1, 1], then CLIP normalisation)."""
        x = _to_chw(image[None].float().cpu()) * 2.0 - 1.0
        try:
            from diffusers.pipelines.stable_video_diffusion.pipeline_stable_video_diffusion import (
                _resize_with_antialiasing,
            )
            x = _resize_with_antialiasing(x, (self.clip_size, self.clip_size))
        except ImportError:  # pragma: no cover - other diffusers versions
            x = F.interpolate(x, size=(self.clip_size, self.clip_size), mode="bicubic", antialias=True)
        x = ((x + 1.0) / 2.0 - self.image_mean) / self.image_std
        with torch.no_grad():
            emb = self.image_encoder(x.to(self.device, self.image_encoder.dtype)).image_embeds
        return emb[:, None]

    @property
    def uses_cfg(self) -> bool:
        return max(self.cfg.min_guidance_scale, self.cfg.max_guidance_scale) > 1.0

    def condition(self, image: torch.Tensor, n_frames: int, prior: torch.Tensor | None = None,
                  generator: torch.Generator | None = None) -> SVDCondition:
        c = self.cfg
        emb = self.clip_embedding(image)
        size = self.model_size(*image.shape[:2])
        x = self._resize(_to_chw(image[None].float()), size) * 2.0 - 1.0
        noise = torch.randn(x.shape, generator=generator, device="cpu", dtype=x.dtype).to(x.device)
        lat = self._vae_encode(x + c.noise_aug_strength * noise)  # not scaled, as the pipeline does
        lat = lat[:, None].repeat(1, n_frames, 1, 1, 1)
        ids = torch.tensor([[c.fps - 1, c.motion_bucket_id, c.noise_aug_strength]], dtype=torch.float32)
        scale = None
        if self.uses_cfg:
            emb = torch.cat([torch.zeros_like(emb), emb])
            lat = torch.cat([torch.zeros_like(lat), lat])
            ids = torch.cat([ids, ids])
            scale = torch.linspace(c.min_guidance_scale, c.max_guidance_scale, n_frames).view(1, n_frames, 1, 1, 1)
            scale = scale.to(self.device)
        return SVDCondition(emb.to(self.device, self.dtype), lat.to(self.device, self.dtype),
                            ids.to(self.device, self.dtype), scale)

    def denoise(self, x: torch.Tensor, sigma: float, cond: SVDCondition) -> torch.Tensor:
        """x0_hat = c_skip x + c_out v(c_in x, c_noise), v-prediction with EDM preconditioning:
        c_in = 1/sqrt(sigma^2 + 1), c_noise = log(sigma)/4, c_skip = 1/(sigma^2 + 1), c_out = -sigma/sqrt(sigma^2 + 1)."""
        s = torch.tensor(sigma, dtype=torch.float32)
        x = x.float()
        inp = (x / (s**2 + 1) ** 0.5)[None]
        if cond.guidance_scale is not None:
            inp = torch.cat([inp, inp])
        inp = torch.cat([inp.to(self.dtype), cond.image_latents], dim=2)
        t = (0.25 * s.log()).to(self.device)
        with torch.no_grad():
            v = self.unet(inp, t, encoder_hidden_states=cond.embeddings, added_time_ids=cond.time_ids,
                          return_dict=False)[0]
        if cond.guidance_scale is not None:
            v_unc, v_cond = v.chunk(2)
            v = v_unc + cond.guidance_scale.to(v.dtype) * (v_cond - v_unc)
        v = v[0].float()
        s = s.to(x.device)
        return v * (-s / (s**2 + 1) ** 0.5) + x / (s**2 + 1)


# ----------------------------------------------------------------------------------------------


def make_backend(name: str, device="cpu", *, default: DefaultBackendConfig | None = None,
                 svd: SVDConfig | None = None, svd_path=None) -> Any:
    """A backend by name: ``default`` (weight-free Gaussian video prior) or ``svd``."""
    if name == "default":
        return GaussianVideoBackend(default)
    if name == "svd":
        return SVDBackend.from_pretrained(svd_path, device=device, cfg=svd)
    raise ValueError(f"pseudo-view backend must be 'default' or 'svd', got {name!r}")
