"""Pseudo views (paper Sec. 3.2-3.3): camera trajectories between the inputs, warped guidance,
cross-view uncertainty, and the uncertainty-modulated video diffusion sampler.

    from warpgs.pseudo import PseudoConfig, generate_pseudo_views, model_renderer
    seqs = generate_pseudo_views(model_renderer(model), scene.train, PseudoConfig.load(), out_dir="outputs/pseudo")
    seqs[0].frames, seqs[0].guidance, seqs[0].uncertainty     # [N, H, W, 3], [N, H, W, 3], [N, H, W]
    seqs[0].pseudo_cameras()                                  # the interior frames as training views

or ``python -m warpgs.pipelines.pseudo --model point_cloud.ply --data synthetic --views 3``. Settings:
``PseudoConfig`` (a run's ``pseudo:`` section).

Pieces, each usable alone:

- ``trajectory``: inputs ordered as a nearest-neighbour path, N poses between neighbours (slerp, natural
  cubic spline), optional perturbation towards the most uncertain candidate.
- ``guidance`` (Warp kernels in ``warpgs/kernels/warping.py``, CPU and CUDA): ``warp_guidance``
  (q = K P_inp P_guid^-1 D_guid(p) K^-1 p), ``uncertainty_map`` (backward projection with the input's
  depth, U = 1 - exp(-|p - p'|^2/s1 - |I_gs(p) - I_inp(q)|^2/s2), U = 1 without a correspondence), both
  between two ``PosedViews`` (the inputs and the guidance frames: poses, intrinsics, images, depths).
- ``sampler``: ``sample_video``, EDM Euler steps with per-pixel fusion of x0_hat and the encoded guidance
  (gamma = 1/(U + eps) where U < delta, until the frame's tau = k mean(U) + b), forward and reversed
  backward passes blended with beta_i = (N - 1 - i)/(N - 1). Backend-agnostic.
- ``backends``: ``svd`` (Stable Video Diffusion img2vid(-xt) through diffusers: ``huggingface-cli download
  stabilityai/stable-video-diffusion-img2vid-xt`` puts it where it is found without flags, or pass ``--svd-path``
  or set ``WARPGS_SVD_PATH``; ``pseudo.svd.offload`` trades time for GPU memory) and ``default``, which needs no
  weights. ``auto`` (the default) takes svd when its weights are found, else default, and says which.

What the default backend is, plainly: an exact MMSE denoiser for a Gaussian video prior centred on the
3D-GS renders (a residual that is smooth in space and time, plus per-pixel detail). Run through the
same sampler it keeps the warped inputs where they are reliable and fills the rest with the render,
corrected by the guidance-minus-render residual spread smoothly from nearby reliable pixels and frames.
It cannot invent what neither the inputs nor the render show: the paper's gains come from a learned
video prior (SVD), which completes such regions with plausible content.
"""

from .backends import (
    DefaultBackendConfig,
    GaussianVideoBackend,
    SVDBackend,
    SVDConfig,
    SVDWeightsNotFound,
    choose_backend,
    find_svd_weights,
    make_backend,
)
from .guidance import PosedViews, UncertaintyConfig, WarpResult, guidance_and_uncertainty, uncertainty_map, warp_guidance
from .sampler import SampleResult, SamplerConfig, VideoBackend, sample_video
from .trajectory import (
    Trajectory,
    TrajectoryConfig,
    guidance_sources,
    nearest_neighbour_path,
    path_trajectories,
    perturb_trajectory,
)

_VIEWS = ("PseudoConfig", "PseudoSequence", "generate_pseudo_views", "model_renderer", "save_image", "save_sequence")


def __getattr__(name):  # views (and torch) are imported on first use
    if name in _VIEWS:
        from . import views

        return getattr(views, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "DefaultBackendConfig",
    "GaussianVideoBackend",
    "PosedViews",
    "PseudoConfig",
    "PseudoSequence",
    "SVDBackend",
    "SVDConfig",
    "SVDWeightsNotFound",
    "SampleResult",
    "SamplerConfig",
    "Trajectory",
    "TrajectoryConfig",
    "UncertaintyConfig",
    "VideoBackend",
    "WarpResult",
    "choose_backend",
    "find_svd_weights",
    "generate_pseudo_views",
    "guidance_and_uncertainty",
    "guidance_sources",
    "make_backend",
    "model_renderer",
    "nearest_neighbour_path",
    "path_trajectories",
    "perturb_trajectory",
    "sample_video",
    "save_image",
    "save_sequence",
    "uncertainty_map",
    "warp_guidance",
]
