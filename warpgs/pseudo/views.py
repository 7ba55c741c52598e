"""Pseudo views along camera trajectories between the input views.

    from warpgs.pseudo.views import PseudoConfig, generate_pseudo_views, model_renderer
    cfg = PseudoConfig.load()                           # the defaults: the paper's settings (or Config.pseudo)
    seqs = generate_pseudo_views(model_renderer(model), scene.train, cfg)
    for s in seqs: save_sequence(s, "outputs/pseudo")   # PNGs: pseudo views, guidance, uncertainty, renders

For each pair of neighbouring inputs along the nearest-neighbour path: poses interpolated between them
(optionally perturbed towards the most uncertain), the trained 3D-GS rendered there (colour I_gs and
depth D_gs), the nearest input warped into each frame with D_gs, the cross-view uncertainty U with
the depth rendered at the input, and the video backend sampled with the uncertainty-modulated,
bidirectional sampler from the two inputs. ``render_fn(viewmat, K, width, height) -> (image [H, W, 3],
depth [H, W])`` is all this needs of the model; ``model_renderer`` adapts a ``GaussianModel``.

Command line (a trained model and its scene)::

    python -m warpgs.pipelines.pseudo --model outputs/sparse/point_cloud.ply --data synthetic --views 3 \
        --out outputs/pseudo [--pseudo-backend svd --svd-path /path/to/svd] [--set sampler.steps=50]
"""

from __future__ import annotations

import argparse
import atexit
import copy
import os
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Callable, Sequence

import numpy as np
import torch

from warpgs.configio import apply_values, parse_override, read_yaml
from warpgs.viz import save_image, to_uint8

from .backends import (BACKENDS, WEIGHT_FREE_NOTE, DefaultBackendConfig, SVDConfig, choose_backend, make_backend,
                       svd_dtype, svd_weight_files)
from .guidance import PosedViews, UncertaintyConfig, WarpResult, guidance_and_uncertainty, match_colour
from .sampler import SamplerConfig, sample_video
from .trajectory import (
    Trajectory,
    TrajectoryConfig,
    camera_centres,
    guidance_sources,
    offset_trajectories,
    path_trajectories,
    perturb_trajectory,
)

RenderFn = Callable[[torch.Tensor, torch.Tensor, int, int], tuple[torch.Tensor, torch.Tensor]]


# ----------------------------------------------------------------------------------------------
# configuration


@dataclass
class PseudoConfig:
    backend: str = "auto"  # auto: svd when its weights are found (--svd-path, $WARPGS_SVD_PATH, the Hugging Face
    #   cache), else default | default (the weight-free Gaussian video prior) | svd (an error without weights)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    default_backend: DefaultBackendConfig = field(default_factory=DefaultBackendConfig)
    svd: SVDConfig = field(default_factory=SVDConfig)

    LIMITS = {"backend": "{" + ", ".join(BACKENDS) + "}"}

    @classmethod
    def load(cls, path: str | Path | None = None, overrides: Sequence[str] | dict | None = None) -> "PseudoConfig":
        """Defaults, then the YAML file ``path`` (a missing one is an error), then overrides: ``section.key=value``
        strings (values as YAML) or one nested dict. Unknown keys are errors naming the valid ones."""
        cfg = cls()
        if path is not None:
            apply_values(cfg, read_yaml(path), str(path))
        if isinstance(overrides, dict):
            apply_values(cfg, overrides, "overrides")
        else:
            for item in overrides or ():
                apply_values(cfg, parse_override(item), f"--set {item}")
        return cfg


def resolve_backend(cfg: PseudoConfig, real_data: bool = False) -> str:
    """Turns ``auto`` into ``svd`` (its weights' folder set in ``cfg.svd.path``) or ``default`` in ``cfg`` and
    says which in one line (once per process); with ``real_data`` a run without the learned prior also says
    what that costs (``WEIGHT_FREE_NOTE``). ``svd`` without weights raises ``SVDWeightsNotFound``. -> the backend."""
    from warpgs.console import warn_once

    name, folder, line = choose_backend(cfg.backend, cfg.svd.path)
    if cfg.backend == "auto" and line:
        warn_once(line, key="pseudo-backend")
    if name == "default" and real_data:
        warn_once(WEIGHT_FREE_NOTE, key="pseudo-weight-free")
    cfg.backend = name
    if folder is not None:
        cfg.svd.path = str(folder)
    return name


_LOADED: dict = {}  # the last backend made: a run's cycles (and its videos) share one loaded model
_LOADING: dict = {}  # key -> Future of a load under way (another thread's, which a caller waits for)
_LOCK = threading.Lock()  # guards both: one load per key


def _backend_key(cfg: PseudoConfig, device) -> tuple[PseudoConfig, tuple]:
    """``cfg`` resolved (a copy) and the key its loaded backend is kept under: name, settings, device."""
    cfg = copy.deepcopy(cfg)
    resolve_backend(cfg)
    return cfg, (cfg.backend, repr(cfg.svd) if cfg.backend == "svd" else repr(cfg.default_backend), str(device))


def _claim(key) -> tuple[Future, bool]:
    """-> (the Future of ``key``'s backend, whether the caller is to load it). The first to ask a key that is
    neither loaded nor loading starts its load; the loaded model of another key is dropped then (one at a time)."""
    with _LOCK:
        job = Future()
        if key in _LOADED:
            job.set_result(_LOADED[key])
            return job, False
        if key in _LOADING:
            return _LOADING[key], False
        _LOADED.clear()
        _LOADING[key] = job
        return job, True


def _load(cfg: PseudoConfig, key, device, job: Future) -> None:
    """Makes the backend into ``job``: its result, or the exception a direct ``make_backend`` raises (the waiter
    re-raises it, with its message). A failed load is forgotten, so that a later call tries again."""
    try:
        backend = make_backend(cfg.backend, device, default=cfg.default_backend, svd=cfg.svd, svd_path=cfg.svd.path)
    except BaseException as e:  # KeyboardInterrupt included: the waiter must not wait for ever
        with _LOCK:
            _LOADING.pop(key, None)
        job.set_exception(e)
        return
    with _LOCK:
        _LOADING.pop(key, None)
        _LOADED.clear()  # (another key's, loaded meanwhile: the newest is kept)
        _LOADED[key] = backend
    job.set_result(backend)


def backend_from_config(cfg: PseudoConfig, device="cpu"):
    """The backend ``cfg`` names (``auto`` resolved by ``resolve_backend``), loaded once per process for the same
    settings and device: the cycles of a run reuse the loaded Stable Video Diffusion. A load another thread
    started is waited for (its error, if any, raised here)."""
    cfg, key = _backend_key(cfg, device)
    job, mine = _claim(key)
    if mine:
        _load(cfg, key, device, job)
    return job.result()


def prefetch_backend(cfg: PseudoConfig, device="cpu") -> threading.Thread | None:
    """Starts reading the weight files of the svd backend ``cfg`` names in a daemon thread, so that its load at the
    first cycle (``backend_from_config``, in the calling thread) finds them in the operating system's file cache:
    the full method starts it before its baseline phase, whose training hides a cold read of the 4.3 GB model.

    Only plain file reads, no torch: the model is not built in the thread. diffusers' and transformers' loaders
    change process-wide state while they build a model (torch's default dtype, ``nn.Module.register_parameter``
    under an empty-weights context, ``torch.nn.init``), and the training thread picks it up: on the H200 a load
    built beside the baseline phase left a densification's new parameters on the meta device.

    -> the thread, or None when there is nothing to read: the weight-free backend, a backend loaded already, or
    settings that do not resolve (their error is raised by the load). The read stops at the next chunk when the
    process ends (``_stop_prefetches``), so an exit, a SIGTERM's included, does not wait for it."""
    try:
        cfg, key = _backend_key(cfg, device)
    except Exception:  # no usable weights: backend_from_config says so when the pseudo views are made
        return None
    if cfg.backend != "svd":
        return None
    with _LOCK:
        if key in _LOADED or key in _LOADING:
            return None
    files = svd_weight_files(Path(cfg.svd.path), svd_dtype(cfg.svd, device))
    if not files:
        return None
    thread = threading.Thread(target=_read_files, args=(files,), name="warpgs-weights-read", daemon=True)
    with _LOCK:
        if not _PREFETCHES:
            atexit.register(_stop_prefetches)
        _PREFETCHES.append(thread)
    thread.start()
    return thread


READ_CHUNK = 16 << 20  # bytes a prefetch reads at a time (it checks for the process's end between them)
_PREFETCHES: list[threading.Thread] = []
_STOP = threading.Event()


def _read_files(files: list[Path]) -> None:
    """Reads ``files`` to their end (into the file cache), stopping early when the process ends; a file that cannot
    be read is skipped (the load reports it)."""
    buf = bytearray(READ_CHUNK)
    for f in files:
        try:
            with open(f, "rb", buffering=0) as fh:
                while not _STOP.is_set() and fh.readinto(buf):
                    pass
        except OSError:
            pass
        if _STOP.is_set():
            return


def _stop_prefetches() -> None:
    """At exit: the reads ``prefetch_backend`` started stop at their next chunk."""
    _STOP.set()
    for thread in list(_PREFETCHES):
        thread.join(5.0)


# ----------------------------------------------------------------------------------------------
# results


@dataclass
class PseudoSequence:
    """One trajectory's frames. Frame 0 and N-1 sit at the start and end inputs; 1..N-2 are the pseudo views."""

    start: int  # input index (in the caller's list) of frame 0
    end: int  # input index of frame N-1
    viewmats: torch.Tensor  # [N, 4, 4] world -> camera
    K: torch.Tensor  # [3, 3]
    width: int
    height: int
    frames: torch.Tensor  # [N, H, W, 3] the completed video (pseudo views)
    guidance: torch.Tensor  # [N, H, W, 3] warped input where U < delta, the 3D-GS render elsewhere
    warped: torch.Tensor  # [N, H, W, 3] the raw warp I_inp(q) (0 where no correspondence)
    uncertainty: torch.Tensor  # [N, H, W] U
    renders: torch.Tensor  # [N, H, W, 3] I_gs
    depths: torch.Tensor  # [N, H, W] D_gs
    sources: torch.Tensor  # [N, H, W] input index each pixel's guidance was warped from
    tau: torch.Tensor  # [N] guidance stop time per frame
    offset: float = 0.0  # off the path (trajectory.offsets): frames 0 and N-1 are moved off the inputs too
    valid: torch.Tensor | None = None  # [N] bool: frames with finite values (None: all); the others are not trained on
    times: dict = field(default_factory=dict)  # seconds: the sampler's stages and the whole trajectory (trajectory_s)

    @property
    def tag(self) -> str:
        """``<start>_<end>`` on the path, ``o<offset>_<start>_<end>`` off it (in the names of files and views)."""
        pair = f"{self.start}_{self.end}"
        return pair if self.offset == 0 else f"o{self.offset:+g}_{pair}"

    def __len__(self) -> int:
        return int(self.frames.shape[0])

    def pseudo_cameras(self, prefix: str | None = None, max_uncertainty: float = 1.0):
        """The interior frames as ``CameraTensors`` (image = pseudo view, mask = U < ``max_uncertainty``;
        1: every pixel an input sees; infinite: no mask, every pixel) for training."""
        from warpgs.data.scene import CameraTensors

        prefix = prefix or f"pseudo_{self.tag}"
        frames = self.interior()
        masks = self.interior_below(max_uncertainty) if max_uncertainty != float("inf") else [None] * len(frames)
        return [
            CameraTensors(name=f"{prefix}_{i:03d}", viewmat=self.viewmats[i], K=self.K, width=self.width,
                          height=self.height, image=self.frames[i], mask=m)
            for i, m in zip(frames, masks, strict=True)
        ]

    def interior(self) -> list[int]:
        """The interior frames that are training views: 1..N-2, less those the model gave non-finite values."""
        return [i for i in range(1, len(self) - 1) if self.valid is None or bool(self.valid[i])]

    def interior_below(self, limit: float) -> list:
        """[H, W] bool per interior frame, in ``pseudo_cameras``' order: U < ``limit``."""
        return [self.uncertainty[i] < limit for i in self.interior()]


def model_renderer(model, background=None) -> RenderFn:
    """``render_fn`` of a ``GaussianModel`` (no gradients): colour and expected depth. ``background``: a
    colour, or a function of a view (viewmat, K, width, height attributes) giving its background
    (``Trainer.background_for``)."""

    def render(viewmat, K, width, height):
        with torch.no_grad():
            if callable(background):
                bg = background(SimpleNamespace(viewmat=viewmat.to(model.device), K=K.to(model.device),
                                                width=width, height=height))
            else:
                bg = background if background is None else torch.as_tensor(background, dtype=torch.float32,
                                                                           device=model.device)
            out = model.render(viewmat.to(model.device), K.to(model.device), width, height, background=bg)
        return out.image, out.depth

    return render


def traj_poses(viewmats: torch.Tensor) -> np.ndarray:
    return viewmats.detach().double().cpu().numpy()


def _camera_tensors(cams, device):
    from warpgs.data.scene import Camera

    return [c.to_torch(device) if isinstance(c, Camera) else c for c in cams]


# ----------------------------------------------------------------------------------------------


class GenerationStopped(Exception):
    """``generate_pseudo_views`` was asked to stop (``should_stop``) after ``done`` of ``total`` trajectories."""

    def __init__(self, done: int, total: int):
        super().__init__(f"pseudo-view generation stopped after {done} of {total} trajectories")
        self.done, self.total = done, total


def generate_pseudo_views(
    render_fn: RenderFn,
    inputs: Sequence,
    cfg: PseudoConfig | None = None,
    backend=None,
    *,
    device=None,
    input_depths: Sequence[torch.Tensor] | None = None,
    trajectories: Sequence[Trajectory] | None = None,
    out_dir: str | Path | None = None,
    generator: torch.Generator | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> list[PseudoSequence]:
    """Pseudo views between neighbouring inputs (see module doc).

    Args:
        render_fn: ``(viewmat [4,4], K [3,3], width, height) -> (image [H,W,3], depth [H,W])`` of the 3D-GS.
        inputs: the input views (``Camera`` or ``CameraTensors``) with their images.
        cfg: settings (``PseudoConfig()``: the paper's); backend: a sampler backend
            (default: the one ``cfg.backend`` names).
        input_depths: depth at each input; default: rendered by ``render_fn`` (as in the paper).
        trajectories: poses to use instead of the path through all inputs (indices into ``inputs``).
        out_dir: if given, every sequence's images are saved there (``save_sequence``).
        should_stop: asked before each trajectory; when it says True, ``GenerationStopped`` ends the generation
            (a stop asked for by Ctrl-C or SIGTERM takes effect within one trajectory, not after all of them).
    """
    cfg = cfg or PseudoConfig()
    cams = _camera_tensors(inputs, device or "cpu")
    dev = cams[0].image.device if device is None else torch.device(device)
    backend = backend or backend_from_config(cfg, dev)
    tc, uc = cfg.trajectory, cfg.uncertainty
    generator = generator or torch.Generator().manual_seed(cfg.sampler.seed)
    rng = np.random.default_rng(cfg.sampler.seed)

    src_images = torch.stack([c.image.to(dev).float() for c in cams])
    src_V = torch.stack([c.viewmat.to(dev).float() for c in cams])
    src_K = torch.stack([c.K.to(dev).float() for c in cams])
    if input_depths is None:
        input_depths = [render_fn(c.viewmat.to(dev), c.K.to(dev), c.width, c.height)[1] for c in cams]
    src_D = torch.stack([d.to(dev).float() for d in input_depths])
    src_views = PosedViews(src_V, src_K, src_images, src_D)  # what the warps read of the inputs
    poses = traj_poses(src_V)  # the inputs' poses for the trajectories (numpy, float64)
    centers = camera_centres(poses)

    if trajectories is None:
        trajectories = path_trajectories(poses, tc.n_frames, tc.order)
        moves = [e for e in tc.offsets if e != 0]  # (an offset of 0 is the path itself)
        if moves:
            trajectories = trajectories + offset_trajectories(trajectories, poses, moves)
    if tc.guidance_source not in ("nearest", "halves", "best"):
        raise ValueError(f"trajectory.guidance_source must be nearest, halves or best, got {tc.guidance_source!r}")
    if tc.guidance_colour not in ("raw", "affine"):
        raise ValueError(f"trajectory.guidance_colour must be raw or affine, got {tc.guidance_colour!r}")
    out = []
    for traj in trajectories:
        if should_stop is not None and should_stop():
            raise GenerationStopped(len(out), len(trajectories))
        K, W, H = src_K[traj.start], cams[traj.start].width, cams[traj.start].height

        def warp(viewmats: torch.Tensor, frames: np.ndarray):
            """Renders at the poses, warps their inputs in -> (WarpResult, sources [F,H,W], renders, depths)."""
            renders, depths = zip(*(render_fn(v, K, W, H) for v in viewmats))
            renders = torch.stack([r.float() for r in renders]).to(dev)
            depths = torch.stack([d.float() for d in depths]).to(dev)
            if tc.guidance_source == "best":
                choices = [np.full(len(frames), traj.start), np.full(len(frames), traj.end)]
            elif tc.guidance_source == "halves":
                choices = [guidance_sources(traj, centers, "halves")[frames]]
            else:  # nearest to the poses given (perturbed candidates included)
                choices = [guidance_sources(Trajectory(traj.start, traj.end, traj_poses(viewmats)), centers)]
            best = src_map = None
            for c in choices:
                idx = torch.as_tensor(c, device=dev)
                r = guidance_and_uncertainty(src_views, PosedViews(viewmats, K, renders, depths), idx, cfg=uc)
                m = idx.view(-1, 1, 1).expand(r.uncertainty.shape).contiguous()
                if best is None:
                    best, src_map = r, m
                    continue
                take = r.uncertainty < best.uncertainty  # ties keep the earlier (start) input
                best = WarpResult(*(torch.where(take.view(*take.shape, *([1] * (a.dim() - 3))), a, b)
                                    for a, b in zip(r, best)))
                src_map = torch.where(take, m, src_map)
            return best, src_map, renders, depths

        if tc.perturb_candidates > 0:
            def score(f: int, viewmat: np.ndarray) -> float:
                v = torch.as_tensor(viewmat, dtype=torch.float32, device=dev)[None]
                return float(warp(v, np.array([f]))[0].uncertainty.mean())

            traj = perturb_trajectory(traj, score, rng, tc.perturb_candidates, tc.perturb_translation,
                                      tc.perturb_rotation_deg)
        V = torch.as_tensor(traj.viewmats, dtype=torch.float32, device=dev)
        r, sources, renders, depths = warp(V, np.arange(len(traj)))
        reliable = r.uncertainty < cfg.sampler.delta
        warped = r.guidance
        if tc.guidance_colour == "affine":
            warped = match_colour(warped, renders, reliable, sources)
        guidance = torch.where(reliable[..., None], warped, renders)
        # the video is conditioned on its end frames: the inputs on the path, the guidance there off it
        first, last = (src_images[traj.start], src_images[traj.end]) if traj.offset == 0 else (guidance[0], guidance[-1])
        t0 = time.perf_counter()
        res = sample_video(backend, first, last, guidance=guidance,
                           uncertainty=r.uncertainty, prior=renders, cfg=cfg.sampler, generator=generator)
        times = {**res.times, "trajectory_s": time.perf_counter() - t0}
        frames, valid = finite_frames(res.frames.to(dev), renders, f"{traj.start} -> {traj.end}")
        seq = PseudoSequence(traj.start, traj.end, V, K, W, H, frames, guidance, r.guidance,
                             r.uncertainty, renders, depths, sources, res.tau, traj.offset, valid, times)
        if out_dir is not None:
            save_sequence(seq, out_dir)
        out.append(seq)
    return out


def finite_frames(frames: torch.Tensor, fallback: torch.Tensor, what: str) -> tuple[torch.Tensor, torch.Tensor | None]:
    """A model's frames [N, H, W, 3] with those holding a non-finite value replaced by ``fallback``'s (the
    renders, for the saved images) and marked invalid -> (frames in [0, 1], valid [N] or None when all are).
    Said in one line, once per process."""
    from warpgs.console import warn_once

    ok = torch.isfinite(frames).flatten(1).all(1)
    if bool(ok.all()):
        return frames.clamp(0.0, 1.0), None
    warn_once(f"warpgs: the video model gave non-finite values in {int((~ok).sum())} of {len(ok)} frames of the "
              f"trajectory {what}; those pseudo views are dropped (said once)", key="pseudo-nonfinite")
    frames = torch.where(ok.view(-1, 1, 1, 1), torch.nan_to_num(frames), fallback.to(frames.dtype))
    return frames.clamp(0.0, 1.0), ok


def pseudo_times(seqs: Sequence[PseudoSequence]) -> dict:
    """One cycle's video-model seconds for the run's records: per stage summed over its trajectories
    (``pseudo_<stage>_s``), the trajectories' count and mean seconds each (``pseudo_per_trajectory_s``)."""
    from .sampler import STAGES

    if not seqs:
        return {}
    out = {f"pseudo_{k}_s": sum(s.times.get(f"{k}_s", 0.0) for s in seqs) for k in STAGES}
    out["pseudo_trajectories"] = len(seqs)
    out["pseudo_frames_per_trajectory"] = len(seqs[0])
    out["pseudo_per_trajectory_s"] = sum(s.times.get("trajectory_s", 0.0) for s in seqs) / len(seqs)
    return out


# ----------------------------------------------------------------------------------------------
# images


SEQUENCE_IMAGES = ("pseudo", "guidance", "warped", "uncertainty", "render")  # save_sequence's PNGs per frame


def save_sequence(seq: PseudoSequence, out_dir: str | Path) -> Path:
    """``<out_dir>/seq_<start>_<end>/{pseudo,guidance,warped,uncertainty,render}_NNN.png`` plus poses.npz.
    Uncertainty is grey (white = 1, unreliable)."""
    return save_sequences([seq], out_dir)[0]


def save_sequences(seqs: Sequence[PseudoSequence], out_dir: str | Path, threads: int | None = None) -> list[Path]:
    """``save_sequence`` of each of ``seqs``, the PNGs written by ``threads`` threads (default: the CPU's cores,
    at most 8; zlib lets go of the interpreter while it compresses) at zlib's fastest level: a 9-view capture's
    cycle writes 360 PNGs of 768x512, 47 s one after the other at PIL's default level on the GPU machine."""
    from concurrent.futures import ThreadPoolExecutor

    jobs, folders = [], []
    for seq in seqs:
        d = Path(out_dir) / (f"seq_{seq.start:03d}_{seq.end:03d}" if seq.offset == 0 else
                             f"seq_o{seq.offset:+g}_{seq.start:03d}_{seq.end:03d}")
        d.mkdir(parents=True, exist_ok=True)
        stacks = (seq.frames, seq.guidance, seq.warped, seq.uncertainty, seq.renders)
        for kind, stack in zip(SEQUENCE_IMAGES, stacks, strict=True):
            pixels = to_uint8(stack[: len(seq)])  # one copy from the device per stack
            jobs += [(d / f"{kind}_{i:03d}.png", pixels[i]) for i in range(len(seq))]
        np.savez(d / "poses.npz", viewmats=seq.viewmats.cpu().numpy(), K=seq.K.cpu().numpy(),
                 sources=seq.sources.cpu().numpy().astype(np.int16), tau=seq.tau.cpu().numpy())
        folders.append(d)
    threads = threads or min(8, os.cpu_count() or 1)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(lambda job: save_image(*job, compress_level=1), jobs))  # list(): a failed write raises here
    return folders


# ----------------------------------------------------------------------------------------------
# command line


def add_pseudo_args(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    g = parser.add_argument_group("pseudo views")
    g.add_argument("--pseudo-config", default=None, help="a YAML file of PseudoConfig fields (default: none, the paper's settings)")
    add_backend_args(g)
    g.add_argument("--set", dest="pseudo_set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a setting, e.g. --set sampler.steps=50")
    return parser


def add_backend_args(group) -> None:
    """--pseudo-backend and --svd-path (pseudo.backend, pseudo.svd.path), in every command that makes pseudo views."""
    group.add_argument("--pseudo-backend", choices=list(BACKENDS), default=None,
                       help="video model of the pseudo views: auto (the default: svd when its weights are found, "
                            "else the weight-free prior), svd, or default (weight-free)")
    group.add_argument("--svd-path", default=None,
                       help="Stable Video Diffusion folder (default: $WARPGS_SVD_PATH, then the Hugging Face cache)")


def config_from_args(args: argparse.Namespace) -> PseudoConfig:
    cfg = PseudoConfig.load(args.pseudo_config, args.pseudo_set)
    if args.pseudo_backend:
        cfg.backend = args.pseudo_backend
    if args.svd_path:
        cfg.svd.path = args.svd_path
    return cfg
