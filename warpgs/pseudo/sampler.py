"""The uncertainty-modulated video diffusion sampler (paper Sec. 3.3), independent of the video model.

    out = sample_video(backend, start, end, guidance=g, uncertainty=U, prior=renders, cfg=SamplerConfig())
    out.frames    [N, H, W, 3] in [0, 1]

The sampler works in the variance-exploding (EDM) form ``x = x0 + sigma * n``. A backend supplies the
video model: ``encode`` / ``decode`` between frames and latents, ``condition`` on one image, and
``denoise(x, sigma, cond) -> x0_hat`` (see ``VideoBackend``). Every step:

1. ``x0_hat = denoise(x_t, sigma_t, cond)``;
2. fusion with the encoded guidance ``g`` per latent pixel (the minimiser of
   ``|x - x0_hat|^2 + gamma |x - g|^2``): ``x0_hat <- (x0_hat + gamma g) / (1 + gamma)``, where
   ``gamma = 1 / (U + eps)`` for ``U < delta`` while the step comes before the frame's ``tau``, else 0;
   U is average-pooled to the latent resolution and ``tau = k * mean(U of the frame) + b``;
3. the Euler step ``x_{t-1} = x_t + (x_t - x0_hat) / sigma_t * (sigma_{t-1} - sigma_t)``.

Time is normalised: step ``i`` of ``S`` is at ``t_i = 1 - i / S`` (1 at pure noise, towards 0 at the
end), and guidance is on while ``t_i > tau``; a frame with more uncertainty stops earlier and leaves
more of the trajectory to the video prior. ``tau_mode="syn3r"`` uses the released code's curve
``tau = -0.157 u^2 + 0.377 u + 0.2`` with ``u = mean(U) / max(max(U), 0.5)`` instead of the paper's line.

Bidirectional view interpolation: a forward pass conditioned on the start image and a backward pass
conditioned on the end image over the reversed frames run side by side, and after each step both are
replaced by ``beta * x_fwd + (1 - beta) * R(x_bwd)``, ``beta[i] = (N - 1 - i) / (N - 1)`` for frame
``i = 0 .. N-1`` (the paper's ``(N - i) / (N - 1)`` with frames counted from 1), R reversing frames.
A backend with ``condition_batch`` / ``denoise_batch`` gets both passes in one call (SVD batches them into
one UNet call); otherwise they are called in turn. ``SampleResult.times`` has the seconds of each stage
(conditioning, encode, denoise, decode), measured by a ``StageClock``.
"""

from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

import torch
import torch.nn.functional as F


@dataclass
class SamplerConfig:
    steps: int = 25  # Euler steps (SYN3R runs SVD with 100)
    delta: float = 0.5  # guidance only where the pooled U is below delta
    eps: float = 1e-3  # gamma = 1 / (U + eps)
    k: float = 0.22  # tau = k * mean(U) + b (normalised time); the paper states no values: these are the
    b: float = 0.23  # least-squares line through SYN3R's curve -0.157 u^2 + 0.377 u + 0.2 on [0, 1]
    tau_mode: str = "linear"  # linear (paper) | syn3r (the released code's quadratic)
    guided: bool = True  # False: plain sampling, no fusion (the ablation "without guidance")
    bidirectional: bool = True  # forward + reversed backward pass, blended every step
    pin_end_frames: bool = False  # SYN3R: hold the end frames at the input images' latents
    noise_scale: float | None = None  # x the initial noise; None: the backend's default
    seed: int = 0

    LIMITS = {"steps": ">= 1", "delta": ">= 0", "eps": "> 0", "noise_scale": ">= 0", "seed": ">= 0"}


class VideoBackend(Protocol):
    """What the sampler needs from a video model. Frames are [N, H, W, 3] in [0, 1]; latents [N, C, h, w]."""

    default_noise_scale: float

    def sigmas(self, steps: int, device) -> torch.Tensor:
        """Noise levels [steps + 1], decreasing, the last 0 (float32)."""

    def init_noise_sigma(self, sigmas: torch.Tensor) -> float:
        """Standard deviation of the initial latents."""

    def prior_mean(self, cond: Any) -> torch.Tensor | float:
        """Mean of the clean latents under the model (0 for a diffusion model's normalised latents); the
        initial latents are ``prior_mean + init_noise_sigma * noise_scale * noise``."""

    def latent_shape(self, height: int, width: int) -> tuple[int, int, int]:
        """(C, h, w) of one frame's latent."""

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        """Clean frames -> latents (the space x0_hat and the guidance live in)."""

    def decode(self, latents: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
        """Latents -> frames [N, H, W, 3] at ``size`` = (H, W)."""

    def condition(self, image: torch.Tensor, n_frames: int, prior: torch.Tensor | None = None,
                  generator: torch.Generator | None = None) -> Any:
        """Conditioning of one pass on ``image`` [H, W, 3]; ``prior`` [N, H, W, 3] are frames the backend
        may use (the 3D-GS renders in the pass's frame order)."""

    def denoise(self, x: torch.Tensor, sigma: float, cond: Any) -> torch.Tensor:
        """x0_hat of the noisy latents ``x`` at noise level ``sigma``."""


@dataclass
class SampleResult:
    frames: torch.Tensor  # [N, H, W, 3] in [0, 1]
    latents: torch.Tensor  # [N, C, h, w] final latents
    tau: torch.Tensor  # [N] per-frame guidance stop time (normalised)
    gamma: torch.Tensor  # [N, 1, h, w] fusion weight while guidance is on (0 = never guided)
    guided_steps: torch.Tensor  # [N] steps on which each frame's guidance was on
    times: dict = field(default_factory=dict)  # seconds per stage: conditioning_s, encode_s, denoise_s, decode_s


STAGES = ("conditioning", "encode", "denoise", "decode")


class StageClock:
    """Wall-clock seconds per stage (the device synchronised at each stage's end, so the time is the stage's
    work), and with ``memory`` the peak CUDA memory allocated within each stage (the peak statistic is
    reset at each stage's start: for measurements, not inside a training run whose own peak it would hide)."""

    def __init__(self, device, memory: bool = False):
        self.device = torch.device(device)
        self.cuda = self.device.type == "cuda" and torch.cuda.is_available()
        self.memory = memory and self.cuda
        self.times: dict[str, float] = {}
        self.peaks: dict[str, float] = {}  # MB

    @contextmanager
    def stage(self, name: str):
        if self.cuda:
            torch.cuda.synchronize(self.device)
            if self.memory:
                torch.cuda.reset_peak_memory_stats(self.device)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            if self.cuda:
                torch.cuda.synchronize(self.device)
            key = f"{name}_s"
            self.times[key] = self.times.get(key, 0.0) + time.perf_counter() - t0
            if self.memory:
                mb = torch.cuda.max_memory_allocated(self.device) / 2**20
                self.peaks[f"{name}_peak_mb"] = max(self.peaks.get(f"{name}_peak_mb", 0.0), mb)


def condition_passes(backend, images, n: int, priors, generator):
    """``backend.condition`` of each pass (``condition_batch`` when the backend has it)."""
    if hasattr(backend, "condition_batch"):
        return backend.condition_batch(images, n, priors, generator)
    return [backend.condition(im, n, p, generator) for im, p in zip(images, priors)]


def denoise_passes(backend, xs, sigma: float, conds) -> list:
    """``backend.denoise`` of each pass (``denoise_batch``, one model call for all, when the backend has it)."""
    if hasattr(backend, "denoise_batch"):
        return backend.denoise_batch(xs, sigma, conds)
    return [backend.denoise(x, sigma, c) for x, c in zip(xs, conds)]


# ----------------------------------------------------------------------------------------------
# the equations, one function each


def karras_sigmas(steps: int, sigma_min: float, sigma_max: float, rho: float = 7.0) -> torch.Tensor:
    """EDM noise levels (Karras et al. 2022, eq. 5) followed by 0: [steps + 1] float32."""
    ramp = torch.linspace(0, 1, steps, dtype=torch.float64)
    lo, hi = sigma_min ** (1 / rho), sigma_max ** (1 / rho)
    s = (hi + ramp * (lo - hi)) ** rho
    return torch.cat([s, torch.zeros(1, dtype=torch.float64)]).float()


def euler_step(x: torch.Tensor, x0_hat: torch.Tensor, sigma: float, sigma_next: float) -> torch.Tensor:
    """x_{t-1} = x_t + (x_t - x0_hat) / sigma_t * (sigma_{t-1} - sigma_t)."""
    return x + (x - x0_hat) / sigma * (sigma_next - sigma)


def fuse(x0_hat: torch.Tensor, guidance: torch.Tensor, gamma: torch.Tensor) -> torch.Tensor:
    """argmin_x |x - x0_hat|^2 + gamma |x - g|^2 = (x0_hat + gamma g) / (1 + gamma), per pixel."""
    return (x0_hat + gamma * guidance) / (1.0 + gamma)


def guidance_weights(U_latent: torch.Tensor, delta: float, eps: float) -> torch.Tensor:
    """gamma = 1 / (U + eps) where U < delta, else 0."""
    return torch.where(U_latent < delta, 1.0 / (U_latent + eps), torch.zeros_like(U_latent))


def guidance_stop(U: torch.Tensor, k: float, b: float, mode: str = "linear") -> torch.Tensor:
    """Per-frame tau from U [N, H, W]: ``k * mean(U) + b`` (linear) or SYN3R's quadratic (syn3r)."""
    m = U.flatten(1).mean(1)
    if mode == "linear":
        return k * m + b
    if mode == "syn3r":
        u = m / torch.clamp(U.flatten(1).amax(1), min=0.5)
        return -0.157 * u * u + 0.377 * u + 0.2
    raise ValueError(f"tau_mode must be 'linear' or 'syn3r', got {mode!r}")


def step_time(i: int, steps: int) -> float:
    """Normalised time of step i: 1 at the first (pure noise) step, 1/steps at the last."""
    return 1.0 - i / steps


def blend_weights(n: int, device=None) -> torch.Tensor:
    """beta[i] = (N - 1 - i) / (N - 1): 1 at the start frame, 0 at the end frame."""
    if n == 1:
        return torch.ones(1, device=device)
    return (n - 1 - torch.arange(n, device=device, dtype=torch.float32)) / (n - 1)


def pool_uncertainty(U: torch.Tensor, latent_hw: tuple[int, int]) -> torch.Tensor:
    """U [N, H, W] average-pooled to the latent resolution -> [N, 1, h, w]."""
    return F.adaptive_avg_pool2d(U[:, None].float(), latent_hw)


# ----------------------------------------------------------------------------------------------


def _image_hw(t: torch.Tensor) -> tuple[int, int]:
    return int(t.shape[-3]), int(t.shape[-2])


def sample_video(
    backend: VideoBackend,
    start: torch.Tensor,
    end: torch.Tensor | None = None,
    *,
    guidance: torch.Tensor | None = None,
    uncertainty: torch.Tensor | None = None,
    prior: torch.Tensor | None = None,
    n_frames: int | None = None,
    cfg: SamplerConfig | None = None,
    noise: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
    clock: StageClock | None = None,
) -> SampleResult:
    """Samples a video of N frames from ``start`` (and ``end`` when bidirectional), guided where reliable.

    Args:
        start, end: conditioning images [H, W, 3] in [0, 1] (frame 0 and frame N-1).
        guidance: [N, H, W, 3] warped guidance in [0, 1]; uncertainty: [N, H, W] U (1 = unreliable).
            Without them (or with ``cfg.guided=False``) the sampler runs unguided.
        prior: [N, H, W, 3] frames the backend may use (3D-GS renders); reversed for the backward pass.
        n_frames: N when neither guidance nor prior gives it.
        noise: initial noise [N, C, h, w] (standard normal); default drawn from ``generator`` /
            ``cfg.seed``. The backward pass starts from the same noise, reversed.
        clock: times the stages (a new ``StageClock`` by default); its times end in ``SampleResult.times``.
    """
    cfg = cfg or SamplerConfig()
    dev = start.device
    H, W = _image_hw(start)
    n = next((t.shape[0] for t in (guidance, prior) if t is not None), n_frames)
    if n is None:
        raise ValueError("n_frames is needed when neither guidance nor prior is given")
    bidirectional = cfg.bidirectional and end is not None
    if cfg.bidirectional and end is None:
        raise ValueError("bidirectional sampling needs the end image (or set bidirectional=False)")
    if cfg.steps < 1:
        raise ValueError(f"steps must be >= 1, got {cfg.steps}")
    C, h, w = backend.latent_shape(H, W)
    clock = clock or StageClock(dev)
    if generator is None:
        generator = torch.Generator(device="cpu").manual_seed(cfg.seed)
    sigmas = backend.sigmas(cfg.steps, dev).float()
    sig = [float(s) for s in sigmas.cpu()]

    # guidance in latent space, fusion weights and stop times
    g_lat = torch.zeros(n, C, h, w, device=dev)
    gamma = torch.zeros(n, 1, h, w, device=dev)
    tau = torch.full((n,), math.inf, device=dev)
    if cfg.guided and guidance is not None:
        if uncertainty is None:
            raise ValueError("guidance needs its uncertainty map")
        if guidance.shape[:3] != uncertainty.shape or guidance.shape[0] != n:
            raise ValueError(f"guidance {tuple(guidance.shape)} and uncertainty {tuple(uncertainty.shape)} disagree")
        with clock.stage("encode"):
            g_lat = backend.encode(guidance.to(dev).float()).float()
        gamma = guidance_weights(pool_uncertainty(uncertainty.to(dev), (h, w)), cfg.delta, cfg.eps)
        tau = guidance_stop(uncertainty.to(dev).float(), cfg.k, cfg.b, cfg.tau_mode)
    if cfg.pin_end_frames:
        ends = [(0, start)] + ([(n - 1, end)] if end is not None else [])
        with clock.stage("encode"):
            lat = backend.encode(torch.stack([img.to(dev).float() for _, img in ends])).float()
        for (i, _), li in zip(ends, lat):
            g_lat[i] = li
            gamma[i] = 1.0 / cfg.eps
            tau[i] = -math.inf

    # conditioning of the passes
    prior_f = None if prior is None else prior.to(dev).float()
    images, priors = [start.to(dev).float()], [prior_f]
    if bidirectional:
        images.append(end.to(dev).float())
        priors.append(None if prior_f is None else prior_f.flip(0))
        beta = blend_weights(n, dev).view(n, 1, 1, 1)
    with clock.stage("conditioning"):
        conds = condition_passes(backend, images, n, priors, generator)
    cond_f = conds[0]

    scale = backend.default_noise_scale if cfg.noise_scale is None else cfg.noise_scale
    if noise is None:
        noise = torch.randn((n, C, h, w), generator=generator, device="cpu").to(dev)
    x = noise.to(dev).float() * (backend.init_noise_sigma(sigmas) * scale) + backend.prior_mean(cond_f)

    guided_steps = torch.zeros(n, device=dev, dtype=torch.int64)
    guided_any = (gamma.flatten(1).amax(1) > 0).long()
    with clock.stage("denoise"):
        for i in range(cfg.steps):
            s, s_next = sig[i], sig[i + 1]
            on = (step_time(i, cfg.steps) > tau).view(n, 1, 1, 1)
            gam = gamma * on
            guided_steps += on.view(n).long() * guided_any
            if bidirectional:  # the backward pass runs over the reversed frames, in the same model call
                x0, x0b = denoise_passes(backend, [x, x.flip(0)], s, conds)
                x_fwd = euler_step(x, fuse(x0.float(), g_lat, gam), s, s_next)
                x_bwd = euler_step(x.flip(0), fuse(x0b.float(), g_lat.flip(0), gam.flip(0)), s, s_next)
                x = beta * x_fwd + (1.0 - beta) * x_bwd.flip(0)
            else:
                x0 = denoise_passes(backend, [x], s, conds)[0]
                x = euler_step(x, fuse(x0.float(), g_lat, gam), s, s_next)

    with clock.stage("decode"):
        frames = backend.decode(x, (H, W)).float()
    return SampleResult(frames=frames, latents=x, tau=tau, gamma=gamma, guided_steps=guided_steps,
                        times=dict(clock.times))
