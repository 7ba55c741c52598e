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

import contextlib
import math
import os
import threading
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
# Stable Video Diffusion: where the weights are


@dataclass
class SVDConfig:
    path: str | None = None  # local folder with the HF layout; None: $WARPGS_SVD_PATH, then the Hugging Face cache
    width: int | None = None  # model resolution; None: the frames' aspect at about ``area`` pixels, multiples of 64
    height: int | None = None
    area: int = 576 * 1024  # the most model pixels when width and height are not given (SVD-xt's 1024 x 576)
    match_frames: bool = True  # true: the frames' own pixels when they have fewer than ``area`` (at least
    #   ``min_area``): the model makes no pixels the training views cannot use (a 768x512 capture runs at 768x512,
    #   0.64x the UNet's work at 1024x576's area); false: always about ``area`` pixels
    min_area: int = 320 * 576  # the fewest model pixels with match_frames (SVD's first training resolution)
    fps: int = 7
    motion_bucket_id: int = 127
    noise_aug_strength: float = 0.02
    min_guidance_scale: float = 1.0  # classifier-free guidance ramps from min (frame 0) to max (frame N-1)
    max_guidance_scale: float = 3.0
    encode_chunk_size: int = 4  # frames per VAE encoder call (the guidance frames)
    decode_chunk_size: int = 4  # most frames per VAE decoder call, in chunks of even length (the temporal decoder
    #   sees a chunk's frames together: unlike the other memory settings this one changes the frames a little)
    vae_upcast: bool = False  # true: the VAE encoder in float32 as diffusers' pipeline runs it (force_upcast);
    #   false: in the model's dtype, a chunk whose latents come out non-finite is redone in float32
    unet_batch_frames: int = 50  # most frames in one UNet call: the classifier-free-guidance halves and the
    #   sampler's forward and backward passes go into one call while they fit (2 x 25 frames: one pass a call)
    offload: str = "none"  # none: all on the device | model: each component (image encoder, VAE, UNet) on the
    #   device only for its stage | sequential: as model, plus one UNet half a call, the spatial blocks' feed-forward
    #   one frame at a time, VAE encoder chunks of 1
    channels_last: bool = True  # the UNet's convolutions in channels-last layout on CUDA
    compile: bool = False  # torch.compile the UNet on CUDA (a first call that compiles; for measurements)
    dtype: str = "auto"  # auto: float16 on CUDA, float32 on the CPU

    LIMITS = {"encode_chunk_size": ">= 1", "decode_chunk_size": ">= 1", "unet_batch_frames": ">= 1",
              "offload": "{none, model, sequential}", "dtype": "{auto, float16, bfloat16, float32}",
              "noise_aug_strength": ">= 0", "area": ">= 4096",
              "min_area": ">= 4096"}


class SVDWeightsNotFound(FileNotFoundError):
    """The svd backend was asked for and its weights are absent or incomplete (one line: what and how to get them)."""


SVD_HF_FOLDER = "models--" + SVD_REPO.replace("/", "--")
# what StableVideoDiffusionPipeline loads: (part, a file that must be in it; None: the part is a file)
SVD_PARTS = (("model_index.json", None), ("unet", "config.json"), ("vae", "config.json"),
             ("image_encoder", "config.json"), ("scheduler", "scheduler_config.json"),
             ("feature_extractor", "preprocessor_config.json"))
SVD_WEIGHTED = ("unet", "vae", "image_encoder")


def hf_hub_cache() -> Path:
    """Where ``huggingface-cli download`` puts models: $HF_HUB_CACHE, else $HF_HOME/hub, else
    $XDG_CACHE_HOME/huggingface/hub, else ~/.cache/huggingface/hub."""
    if os.environ.get("HF_HUB_CACHE"):
        return Path(os.environ["HF_HUB_CACHE"]).expanduser()
    if os.environ.get("HF_HOME"):
        return Path(os.environ["HF_HOME"]).expanduser() / "hub"
    base = os.environ.get("XDG_CACHE_HOME") or "~/.cache"
    return Path(base).expanduser() / "huggingface" / "hub"


def svd_missing_parts(folder: Path) -> list[str]:
    """What of the pipeline's files ``folder`` lacks (empty: complete). A weights file that is a broken link
    (an interrupted download into the cache) counts as missing."""
    missing = []
    for part, inner in SVD_PARTS:
        p = folder / part
        if inner is None:
            if not p.is_file():
                missing.append(part)
        elif not (p / inner).is_file():
            missing.append(f"{part}/")
        elif part in SVD_WEIGHTED and not any(f.is_file() for e in ("safetensors", "bin") for f in p.glob(f"*.{e}")):
            missing.append(f"{part}/ weights")
    return missing


def hf_snapshots(cache: Path | None = None) -> list[Path]:
    """The cache's snapshots of SVD img2vid-xt, the one ``refs/main`` names first, then the newest first."""
    root = (cache or hf_hub_cache()) / SVD_HF_FOLDER
    snaps = [p for p in (root / "snapshots").glob("*") if p.is_dir()]
    ref = root / "refs" / "main"
    main = ref.read_text().strip() if ref.is_file() else None
    return sorted(snaps, key=lambda p: (p.name != main, -p.stat().st_mtime))


def find_svd_weights(path: str | os.PathLike | None = None) -> tuple[Path | None, str, str | None]:
    """Looks for the weights -> (folder or None, where it looked or found them, what is wrong or None).

    ``path`` (--svd-path, ``pseudo.svd.path``) when given, else $WARPGS_SVD_PATH when set: that folder decides.
    Else the Hugging Face cache's snapshots of img2vid-xt: the first complete one."""
    for given, where in ((path, "--svd-path"), (os.environ.get(SVD_ENV), f"${SVD_ENV}")):
        if given:
            p = Path(given).expanduser()
            if not p.is_dir():
                return None, where, f"{p} ({where}) is not a folder"
            missing = svd_missing_parts(p)
            return (p, where, None) if not missing else (None, where, f"{p} ({where}) lacks {', '.join(missing)}")
    cache = hf_hub_cache()
    snaps = hf_snapshots(cache)
    problems = []
    for s in snaps:
        missing = svd_missing_parts(s)
        if not missing:
            return s, "the Hugging Face cache", None
        problems.append(f"{s} lacks {', '.join(missing)}")
    if problems:
        return None, "the Hugging Face cache", problems[0]
    return None, "", (f"none found (--svd-path, ${SVD_ENV}, or the Hugging Face cache "
                      f"{cache / SVD_HF_FOLDER / 'snapshots'})")


def svd_missing_message(problem: str) -> str:
    """One line: what is wrong and how to get the weights, naming flags the commands accept."""
    return (f"Stable Video Diffusion weights: {problem}. Get them with `huggingface-cli download {SVD_REPO}` "
            f"(the Hugging Face cache is searched without flags) or download them into a folder and pass "
            f"--svd-path DIR (or set {SVD_ENV}=DIR); --pseudo-backend default needs no weights")


def resolve_svd_path(path: str | os.PathLike | None = None) -> Path:
    """The weights' folder (``find_svd_weights``), or ``SVDWeightsNotFound`` saying what is missing."""
    found, _, problem = find_svd_weights(path)
    if found is None:
        raise SVDWeightsNotFound(svd_missing_message(problem))
    return found


BACKENDS = ("auto", "default", "svd")
# the weight-free full method against the baseline on real captures (issue 60's measurement): the one line that
# says so when it runs there
WEIGHT_FREE_NOTE = ("warpgs: without a learned video prior the full method's pseudo views come from the weight-free "
                    "prior: on six held-out real captures (3-9 views, H200, medians of seeds 0-2) its mean gain over "
                    "the baseline was -0.09 dB, at more time and up to 2.5x the Gaussians; with Stable Video "
                    "Diffusion weights (--svd-path DIR) it runs the paper's prior")


def choose_backend(name: str, svd_path=None) -> tuple[str, Path | None, str]:
    """-> (``default`` or ``svd``, the weights' folder or None, one line saying which and why; empty for an
    explicit ``default``). ``auto`` takes svd when its weights are found, else the weight-free prior;
    ``svd`` without them, or a folder given (--svd-path, $WARPGS_SVD_PATH) that is not usable, raises
    ``SVDWeightsNotFound``."""
    if name not in BACKENDS:
        raise ValueError(f"pseudo.backend must be one of {', '.join(BACKENDS)}, got {name!r}")
    if name == "default":
        return "default", None, ""
    found, where, problem = find_svd_weights(svd_path)
    if found is not None:
        return "svd", found, f"warpgs: pseudo views from Stable Video Diffusion in {found} (from {where})"
    if name == "svd" or where in ("--svd-path", f"${SVD_ENV}"):  # a folder named but unusable is an error
        raise SVDWeightsNotFound(svd_missing_message(problem))
    return "default", None, (f"warpgs: pseudo views from the weight-free prior (Stable Video Diffusion weights: "
                             f"{problem}; --svd-path DIR uses them)")


SVD_WEIGHT_PARTS = ("unet", "vae", "image_encoder")  # the folders whose weight files a load reads


def svd_dtype(cfg: SVDConfig, device) -> torch.dtype:
    """The dtype the svd backend loads in: ``cfg.dtype``, or with ``auto`` float16 on CUDA, float32 on the CPU."""
    if cfg.dtype == "auto":
        return torch.float16 if torch.device(device).type == "cuda" else torch.float32
    return getattr(torch, cfg.dtype)


def svd_variant(root: Path, dtype: torch.dtype) -> str | None:
    """The weights' variant a load in ``dtype`` takes: ``fp16`` for float16 where the folder has it, else None."""
    return "fp16" if dtype == torch.float16 and any((Path(root) / "unet").glob("*.fp16.*")) else None


def svd_weight_files(root: Path, dtype: torch.dtype) -> list[Path]:
    """The weight files (``.safetensors``, ``.bin``) a load of the folder ``root`` in ``dtype`` reads."""
    fp16 = svd_variant(root, dtype) is not None
    files = []
    for part in SVD_WEIGHT_PARTS:
        folder = Path(root) / part
        if folder.is_dir():
            files += sorted(f for f in folder.iterdir() if f.suffix in (".safetensors", ".bin")
                            and (".fp16." in f.name) == fp16)
    return files


@contextlib.contextmanager
def warnings_hidden_here():
    """The warnings this thread raises inside are not shown. In the main thread ``catch_warnings`` with an ignore
    filter. In another (a load beside the training) not that: it swaps the process's
    one filter list, hiding the training thread's warnings for the load's length, and an exit interleaved with a
    ``catch_warnings`` of that thread (Warp's logger wraps each warning in one) would leave every warning ignored
    for good. There ``showwarning`` is wrapped instead, to drop this thread's warnings only: a wrapper that such an
    interleaving leaves in place passes the other threads' through."""
    if threading.current_thread() is threading.main_thread():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
        return
    me, show = threading.get_ident(), warnings.showwarning

    def elsewhere(message, category, filename, lineno, file=None, line=None):
        if threading.get_ident() != me:
            show(message, category, filename, lineno, file, line)

    warnings.showwarning = elsewhere
    try:
        yield
    finally:
        if warnings.showwarning is elsewhere:
            warnings.showwarning = show


@contextlib.contextmanager
def quiet_loading():
    """diffusers' and transformers' loaders say nothing but errors inside: their loggers at error level,
    their progress bars off, their warnings (accelerate / torchvision advice) ignored; restored after."""
    from diffusers.utils import logging as dlog
    from transformers.utils import logging as tlog

    levels = dlog.get_verbosity(), tlog.get_verbosity()
    bars = dlog.is_progress_bar_enabled(), tlog.is_progress_bar_enabled()
    dlog.set_verbosity_error()
    tlog.set_verbosity_error()
    dlog.disable_progress_bar()
    tlog.disable_progress_bar()
    try:
        with warnings_hidden_here():
            yield
    finally:
        dlog.set_verbosity(levels[0])
        tlog.set_verbosity(levels[1])
        for mod, on in ((dlog, bars[0]), (tlog, bars[1])):
            (mod.enable_progress_bar if on else mod.disable_progress_bar)()


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


# ----------------------------------------------------------------------------------------------
# Stable Video Diffusion: the backend


@dataclass
class SVDCondition:
    embeddings: torch.Tensor  # [B, 1, D] CLIP image embedding (B = 2 with classifier-free guidance: zero, image)
    image_latents: torch.Tensor  # [B, N, C, h, w] conditioning latents (not scaled), per frame
    time_ids: torch.Tensor  # [B, 3] (fps - 1, motion bucket, noise augmentation)
    guidance_scale: torch.Tensor | None  # [1, N, 1, 1, 1] or None without CFG


COMPONENTS = ("image_encoder", "vae", "unet")


def even_chunks(n: int, size: int) -> list[slice]:
    """``n`` items in ceil(n / size) chunks of at most ``size`` whose lengths differ by one at most (9 frames in
    chunks of 4: 3, 3, 3, not 4, 4, 1: the temporal decoder sees no lone frame)."""
    k = max(1, -(-n // max(1, size)))
    edges = [round(i * n / k) for i in range(k + 1)]
    return [slice(a, b) for a, b in zip(edges, edges[1:]) if b > a]


def channels_last_convs(module: torch.nn.Module) -> int:
    """The 2-D convolutions' weights in channels-last layout (cuDNN's fast path for float16); the temporal
    layers' 5-D weights stay as they are (``module.to(memory_format=...)`` refuses them). -> how many."""
    n = 0
    for m in module.modules():
        if isinstance(m, torch.nn.Conv2d):
            m.weight.data = m.weight.data.contiguous(memory_format=torch.channels_last)
            n += 1
    return n


class SVDBackend:
    """Stable Video Diffusion (img2vid / img2vid-xt) as a sampler backend (see module doc)."""

    name = "svd"
    default_noise_scale = 1.0

    def __init__(self, unet, vae, image_encoder, scheduler, cfg: SVDConfig | None = None, image_mean=CLIP_MEAN,
                 image_std=CLIP_STD, device=None):
        self.unet, self.vae, self.image_encoder, self.scheduler = unet, vae, image_encoder, scheduler
        self.cfg = cfg or SVDConfig()
        if self.cfg.offload not in ("none", "model", "sequential"):
            raise ValueError(f"pseudo.svd.offload must be none, model or sequential, got {self.cfg.offload!r}")
        self.device = torch.device(device) if device is not None else unet.device
        self.dtype = unet.dtype
        self.vae_scale = 2 ** (len(vae.config.block_out_channels) - 1)
        self.clip_size = int(image_encoder.config.image_size)
        self.image_mean = torch.tensor(image_mean, dtype=torch.float32).view(1, 3, 1, 1)
        self.image_std = torch.tensor(image_std, dtype=torch.float32).view(1, 3, 1, 1)
        self.active: set[str] = set(COMPONENTS)  # the components on self.device (offload: one at a time)
        for m in (unet, vae, image_encoder):  # offload: all on the CPU until their stage
            m.to("cpu" if self.offloading else self.device)
        if self.offloading:
            self.active = set()
        if self.cfg.offload == "sequential":
            self._chunk_feed_forward()
        if self.cfg.channels_last and self.device.type == "cuda":
            channels_last_convs(self.unet)
        if self.cfg.compile and self.device.type == "cuda":
            self.unet = torch.compile(self.unet)

    @property
    def offloading(self) -> bool:
        return self.cfg.offload in ("model", "sequential")

    # -- loading ---------------------------------------------------------------------------------

    @classmethod
    def from_pretrained(cls, path=None, device="cpu", cfg: SVDConfig | None = None) -> "SVDBackend":
        """Loads the pipeline's components from a local folder (``path``, else ``cfg.path``, else
        $WARPGS_SVD_PATH, else the Hugging Face cache), quietly; a clear error names what to download
        when they are absent or incomplete."""
        cfg = cfg or SVDConfig()
        root = resolve_svd_path(path if path is not None else cfg.path)
        diffusers = _import_diffusers()
        device = torch.device(device)
        dtype = svd_dtype(cfg, device)
        variant = svd_variant(root, dtype)
        with quiet_loading():
            pipe = diffusers.StableVideoDiffusionPipeline.from_pretrained(root, torch_dtype=dtype, variant=variant)
        sched_cfg = dict(pipe.scheduler.config)
        sched_cfg.update({k: v for k, v in SVD_SCHEDULER.items() if k not in ("sigma_min", "sigma_max")})
        sched_cfg["sigma_min"] = pipe.scheduler.config.get("sigma_min") or SVD_SCHEDULER["sigma_min"]
        sched_cfg["sigma_max"] = pipe.scheduler.config.get("sigma_max") or SVD_SCHEDULER["sigma_max"]
        scheduler = diffusers.EulerDiscreteScheduler.from_config(sched_cfg)
        fe = getattr(pipe, "feature_extractor", None)
        mean = tuple(getattr(fe, "image_mean", None) or CLIP_MEAN)
        std = tuple(getattr(fe, "image_std", None) or CLIP_STD)
        return cls(pipe.unet, pipe.vae, pipe.image_encoder, scheduler, cfg, mean, std, device=device)

    # -- where the components are ------------------------------------------------------------------

    def _use(self, *names: str) -> None:
        """Offload: ``names`` on the device for the coming stage, the others back on the CPU (plain ``.to()``
        moves; a component already in place is not moved). Without offload everything stays on the device."""
        if not self.offloading:
            return
        want = set(names)
        for n in COMPONENTS:
            if (n in want) != (n in self.active):
                getattr(self, n).to(self.device if n in want else "cpu")
        if self.device.type == "cuda" and self.active - want:
            torch.cuda.empty_cache()  # what the parked component held goes back to the device
        self.active = want

    def _chunk_feed_forward(self) -> None:
        """The spatial transformer blocks' feed-forward one frame at a time (``enable_forward_chunking``'s
        switch, on the blocks whose batch is frames; the temporal blocks' batch is pixels, thousands of
        chunks, so they are left whole)."""
        from diffusers.models.attention import BasicTransformerBlock

        for m in self.unet.modules():
            if type(m) is BasicTransformerBlock:
                m.set_chunk_feed_forward(1, 0)

    @property
    def encode_chunk(self) -> int:
        return 1 if self.cfg.offload == "sequential" else max(1, self.cfg.encode_chunk_size)

    @property
    def decode_chunk(self) -> int:  # the temporal decoder mixes the frames of a chunk: its size changes the output
        return max(1, self.cfg.decode_chunk_size)

    # -- geometry --------------------------------------------------------------------------------

    def model_size(self, height: int, width: int) -> tuple[int, int]:
        if self.cfg.height and self.cfg.width:
            return int(self.cfg.height), int(self.cfg.width)
        area = self.cfg.area
        if self.cfg.match_frames:
            area = min(area, max(height * width, self.cfg.min_area))
        return _auto_size(height, width, area=area, multiple=max(8, self.vae_scale * 8))

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
        """images [B, 3, h, w] in [-1, 1] -> latent mode (float32), ``encode_chunk`` images a call. The encoder
        runs in the model's dtype unless ``vae_upcast`` (or a chunk's latents overflow there: that chunk again
        in float32)."""
        self._use("vae")
        half = self.vae.dtype != torch.float32
        out = []
        with torch.no_grad():
            for part in even_chunks(len(images), self.encode_chunk):
                x = images[part].to(self.device)
                lat = None
                if not (half and self.cfg.vae_upcast):
                    lat = self.vae.encode(x.to(self.vae.dtype)).latent_dist.mode().float()
                if lat is None or not torch.isfinite(lat).all():
                    lat = self._encode_float32(x)
                out.append(lat)
        return torch.cat(out)

    def _encode_float32(self, x: torch.Tensor) -> torch.Tensor:
        dtype = self.vae.dtype
        if dtype == torch.float32:
            return self.vae.encode(x.float()).latent_dist.mode().float()
        self._vae_dtype(torch.float32)
        try:
            return self.vae.encode(x.float()).latent_dist.mode().float()
        finally:
            self._vae_dtype(dtype)

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
        return self._vae_encode(x) * float(self.vae.config.scaling_factor)

    def decode(self, latents: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
        self._use("vae")
        z = latents / float(self.vae.config.scaling_factor)
        out = []
        with torch.no_grad():
            for part in even_chunks(len(z), self.decode_chunk):
                zi = z[part].to(self.device, self.vae.dtype)
                xi = (self.vae.decode(zi, num_frames=len(zi)).sample.float() / 2.0 + 0.5).clamp(0.0, 1.0)
                out.append(self._resize(xi, size).clamp(0.0, 1.0))  # resized per chunk: one full-size copy less
        return _to_hwc(torch.cat(out)).contiguous()

    # -- conditioning and the denoiser ------------------------------------------------------------

    def clip_embedding(self, image: torch.Tensor) -> torch.Tensor:
        """CLIP image embeddings [B, 1, D] of images [B, H, W, 3] (or one [H, W, 3]) in [0, 1], preprocessed as
        the pipeline does for PIL input (antialiased resize to 224 in [-1, 1], then CLIP normalisation)."""
        images = image[None] if image.dim() == 3 else image
        x = _to_chw(images.float().cpu()) * 2.0 - 1.0
        try:
            from diffusers.pipelines.stable_video_diffusion.pipeline_stable_video_diffusion import (
                _resize_with_antialiasing,
            )
            x = _resize_with_antialiasing(x, (self.clip_size, self.clip_size))
        except ImportError:  # pragma: no cover - other diffusers versions
            x = F.interpolate(x, size=(self.clip_size, self.clip_size), mode="bicubic", antialias=True)
        x = ((x + 1.0) / 2.0 - self.image_mean) / self.image_std
        self._use("image_encoder")
        with torch.no_grad():
            emb = self.image_encoder(x.to(self.device, self.image_encoder.dtype)).image_embeds
        return emb[:, None]

    @property
    def uses_cfg(self) -> bool:
        return max(self.cfg.min_guidance_scale, self.cfg.max_guidance_scale) > 1.0

    def condition(self, image: torch.Tensor, n_frames: int, prior: torch.Tensor | None = None,
                  generator: torch.Generator | None = None) -> SVDCondition:
        return self.condition_batch([image], n_frames, [prior], generator)[0]

    def condition_batch(self, images, n_frames: int, priors=None,
                        generator: torch.Generator | None = None) -> list[SVDCondition]:
        """The conditioning of several passes at once (each component moved once under offload): as
        ``condition`` on each image in turn, the noise augmentation drawn in that order."""
        c = self.cfg
        embs = self.clip_embedding(torch.stack([im.float() for im in images]))
        size = self.model_size(*images[0].shape[:2])
        x = self._resize(_to_chw(torch.stack([im.float() for im in images])), size) * 2.0 - 1.0
        noise = torch.cat([torch.randn((1, *x.shape[1:]), generator=generator, device="cpu", dtype=x.dtype)
                           for _ in images]).to(x.device)
        lats = self._vae_encode(x + c.noise_aug_strength * noise)  # not scaled, as the pipeline does
        ids = torch.tensor([[c.fps - 1, c.motion_bucket_id, c.noise_aug_strength]], dtype=torch.float32)
        scale = None
        if self.uses_cfg:
            scale = torch.linspace(c.min_guidance_scale, c.max_guidance_scale, n_frames).view(1, n_frames, 1, 1, 1)
            scale = scale.to(self.device)
        out = []
        for emb, lat in zip(embs, lats):
            emb, lat, ids_i = emb[None], lat[None, None].repeat(1, n_frames, 1, 1, 1), ids
            if self.uses_cfg:
                emb, lat, ids_i = torch.cat([torch.zeros_like(emb), emb]), torch.cat([torch.zeros_like(lat), lat]), \
                    torch.cat([ids, ids])
            out.append(SVDCondition(emb.to(self.device, self.dtype), lat.to(self.device, self.dtype),
                                    ids_i.to(self.device, self.dtype), scale))
        return out

    def denoise(self, x: torch.Tensor, sigma: float, cond: SVDCondition) -> torch.Tensor:
        return self.denoise_batch([x], sigma, [cond])[0]

    def denoise_batch(self, xs, sigma: float, conds) -> list[torch.Tensor]:
        """x0_hat of each pass's latents ``xs[k]`` [N, C, h, w] under ``conds[k]``, the passes' UNet inputs
        (both halves of classifier-free guidance each) batched into as few calls as ``unet_batch_frames``
        allows. v-prediction with EDM preconditioning: x0_hat = c_skip x + c_out v(c_in x, c_noise),
        c_in = 1/sqrt(sigma^2 + 1), c_noise = log(sigma)/4, c_skip = 1/(sigma^2 + 1), c_out = -sigma/sqrt(sigma^2 + 1)."""
        self._use("unet")
        s = torch.tensor(sigma, dtype=torch.float32)
        c_in = float(1 / (s**2 + 1) ** 0.5)
        rows = []  # one UNet batch row each: (latents, embedding, image latents, time ids)
        for x, cond in zip(xs, conds):
            inp = (x.float() * c_in).to(self.device, self.dtype)
            for b in range(cond.embeddings.shape[0]):
                rows.append((inp, cond.embeddings[b], cond.image_latents[b], cond.time_ids[b]))
        n = max(1, xs[0].shape[0])
        per_call = 1 if self.cfg.offload == "sequential" else max(1, self.cfg.unet_batch_frames // n)
        t = (0.25 * s.log()).to(self.device)
        v = []
        with torch.no_grad():
            for i in range(0, len(rows), per_call):
                part = rows[i:i + per_call]
                inp = torch.stack([torch.cat([r[0], r[2]], dim=1) for r in part])
                v += list(self.unet(inp, t, encoder_hidden_states=torch.stack([r[1] for r in part]),
                                    added_time_ids=torch.stack([r[3] for r in part]), return_dict=False)[0])
        out, k = [], 0
        for x, cond in zip(xs, conds):
            if cond.guidance_scale is not None:
                v_unc, v_cond = v[k], v[k + 1]
                vk = v_unc + cond.guidance_scale[0].to(v_unc.dtype) * (v_cond - v_unc)
                k += 2
            else:
                vk = v[k]
                k += 1
            xf = x.float()
            sd = s.to(xf.device)
            out.append(vk.float().to(xf.device) * (-sd / (sd**2 + 1) ** 0.5) + xf / (sd**2 + 1))
        return out


# ----------------------------------------------------------------------------------------------


def make_backend(name: str, device="cpu", *, default: DefaultBackendConfig | None = None,
                 svd: SVDConfig | None = None, svd_path=None) -> Any:
    """A backend by name: ``default`` (weight-free Gaussian video prior), ``svd``, or ``auto`` (svd when its
    weights are found, else default; ``choose_backend``)."""
    if name == "auto":
        name, svd_path, _ = choose_backend("auto", svd_path if svd_path is not None else (svd.path if svd else None))
    if name == "default":
        return GaussianVideoBackend(default)
    if name == "svd":
        return SVDBackend.from_pretrained(svd_path, device=device, cfg=svd)
    raise ValueError(f"pseudo-view backend must be one of {', '.join(BACKENDS)}, got {name!r}")
