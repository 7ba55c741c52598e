"""Run configuration: dataclasses with the published defaults, read from ``configs/``, overridable.

A run's config is built in layers, later ones winning:

1. the dataclass defaults below (3D-GS / gsplat numbers);
2. the method's file ``configs/methods/<method>.yaml`` (only the run's method's: ``full.yaml`` names
   ``baseline.yaml`` as its base; a compare run reads ``full.yaml``);
3. the dataset's file ``configs/datasets/<dataset>.yaml`` if there is one (``blender``, ``llff``, ``dtu``,
   ``nerfstudio``, ``synthetic``), which may name shared blocks of ``configs/presets/`` as its base;
4. files given with ``--config`` (a file may name another with ``base: other.yaml``, or a list of them, read
   first);
5. ``--set section.key=value`` overrides (values parsed as YAML: ``--set strategy.max_gaussians=20000``);
6. explicit flags (``--iterations``, ``--views``, ``--device``, ...).

Unknown keys are errors that list the valid ones, and so are values of the wrong type or outside a field's
range: each option class lists its ranges in a ``LIMITS`` table next to its fields (learning rates > 0,
iterations >= 1, weights >= 0, fractions in [0, 1], the words a field takes; ``warpgs.configio``). Every
layer is checked on its own, so the error names the file, ``--set`` or flag a bad value came from, even
where a later layer sets the key again. The config used is written to the output folder.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from warpgs.configio import (  # noqa: F401  (re-exported: the config API in one place)
    CONFIG_DIR, REPO_ROOT, ConfigError, apply_values, check_limits, merge, parse_override, read_yaml)
from warpgs.backgrounds import LEGACY_TRAIN_KEYS as BACKGROUND_KEYS, BackgroundsConfig
from warpgs.backgrounds.far_field import FAR_FIELD_RULE
from warpgs.densify import DensifyConfig
from warpgs.points import GeometryConfig
from warpgs.pseudo.views import PseudoConfig
from warpgs.runfolder import atomic_write
from warpgs.regularizers import LEGACY_TRAIN_KEYS as REGULARIZER_KEYS, RegularizersConfig
from warpgs.strategy.config import ClearanceConfig, CompactConfig
from warpgs.strategy.default import DefaultStrategy



@dataclass
class DataConfig:
    name: str = "synthetic"  # dataset name (configs/data/<name>.yaml) or a scene folder
    scene: str | None = None  # scene of a named dataset (fern, scan65, lego, ...); None = its default
    views: int | str | None = None  # training views; None = the dataset's default; "all"
    downscale: int | None = None  # images_N; None = the dataset's default
    root: str | None = None  # dataset root (replaces the dataset config's roots)
    options: dict = field(default_factory=dict)  # loader keyword arguments

    LIMITS = {"views": ">= 1 or {all}", "downscale": ">= 1"}


@dataclass
class ModelConfig:
    sh_degree: int = 3
    init: str = "frustum"  # sfm | stereo | sfm+stereo (points found between the training views, warpgs/points)
    #   | box | hull | frustum | points | ply (hull: the box carved by the inputs' alpha)
    init_num: int = 100_000  # random Gaussians for box / frustum
    init_fill: int = 0  # sfm / stereo: also a point per empty init_fill x init_fill pixel block of each training view
    #   (no point projects there: what only that view sees), at the nearest point's depth (warpgs/points/fill.py); 0: off
    init_random: int = 0  # sfm / stereo: this many random Gaussians in the training frusta besides the points
    init_box: list | None = None  # [xmin, ymin, zmin, xmax, ymax, zmax]; None: the training frusta's bounding box
    init_depth: list | None = None  # [near, far] for frustum / the automatic box; None: the scene's bounds
    init_ply: str | None = None  # point cloud (any vertex PLY) for init: ply
    init_opacity: float = 0.1
    init_scale: float = 1.0  # x the 3-nearest-neighbour distance
    drop_invalid: bool = False  # init ply: drop points with non-finite values (one warning) instead of refusing the file
    alpha_max: float = 0.99  # the rasterizer's cap on one Gaussian's alpha at a pixel (3D-GS's 0.99; gsplat's kernels
    #   cap at 0.999): every render of the model, training and evaluation

    LIMITS = {"sh_degree": "[0, 3]", "init": "{sfm, stereo, sfm+stereo, box, hull, frustum, points, ply}",
              "init_num": ">= 1", "init_random": ">= 0", "init_fill": ">= 0", "init_depth": "> 0", "init_opacity": "(0, 1)",
              "init_scale": "> 0", "alpha_max": "(0, 1)"}


@dataclass
class OptimConfig:
    means_lr: float = 1.6e-4  # x scene scale, decays exponentially to means_lr_final
    means_lr_final: float = 1.6e-6
    means_lr_decay_steps: int | None = None  # None = the run's iterations
    scales_lr: float = 5e-3
    quats_lr: float = 1e-3
    opacities_lr: float = 5e-2
    sh0_lr: float = 2.5e-3
    shN_lr: float = 2.5e-3 / 20
    eps: float = 1e-15
    scene_scale: float | None = None  # None: 1.1 x the training cameras' largest distance from their centre

    LIMITS = {"means_lr": "> 0", "means_lr_final": "> 0", "means_lr_decay_steps": ">= 1", "scales_lr": "> 0",
              "quats_lr": "> 0", "opacities_lr": "> 0", "sh0_lr": "> 0", "shN_lr": "> 0", "eps": "> 0",
              "scene_scale": "> 0"}


@dataclass
class LossConfig:
    l1_weight: float = 0.8
    ssim_weight: float = 0.2  # D-SSIM = 1 - SSIM
    depth_weight: float = 0.0  # Pearson depth term against the views' depth prior (0 = off)
    depth_prior: str = "scene"  # scene: Camera.depth from the loader
    alpha_weight: float = 0.0  # L1 between rendered and input alpha, for inputs with an alpha channel (0 = off)

    LIMITS = {"l1_weight": ">= 0", "ssim_weight": ">= 0", "depth_weight": ">= 0", "depth_prior": "{scene}",
              "alpha_weight": ">= 0"}


@dataclass
class TrainConfig:
    iterations: int = 7000
    seed: int = 0
    device: str = "auto"  # auto | cpu | cuda | cuda:N
    sh_degree_interval: int = 1000  # raise the rendered SH degree every this many steps
    checkpoint_every: int = 1000  # 0 = only at the end (and on Ctrl-C)
    eval_every: int = 0  # test PSNR/SSIM every this many steps into metrics.json's curve (0 = off)
    background: list | None = None  # [r, g, b]; None: white if the scene says so, else black
    random_background: bool = False  # views with an alpha channel: a random background each step (no floaters
                                     # that mimic the background colour); evaluation keeps ``background``
    progress: bool = True

    def __post_init__(self):
        # the sections keys of earlier versions moved to, defaults for a TrainConfig of its own (a Config links its
        # own: link_sections); cfg.train.<old key> reads and sets them there (_moved_key)
        self.link_sections({name: cls() for name, cls in MOVED_SECTIONS.items()})

    def link_sections(self, sections: dict) -> None:
        """The sections (by name) that ``train.<key>`` of an earlier version reads and sets (``TRAIN_MOVED``)."""
        self._sections = dict(sections)

    def moved_section(self, name: str):
        return self._sections[name]

    LIMITS = {"iterations": ">= 1", "seed": ">= 0", "sh_degree_interval": ">= 0", "checkpoint_every": ">= 0",
              "eval_every": ">= 0", "background": "[0, 1]"}


@dataclass
class HoldConfig:
    """Holding the initial geometry (``hold``; warpgs.engine.init.hold_geometry): the colours and opacities train
    at full rate, the geometry slowly and without densification."""

    geometry: str = "off"  # off | on | stereo: train the colours and opacities at full rate and hold the initial
    #   geometry: no densification or pruning by the strategy (strategy.refine_stop_iter 0) and the means', scales'
    #   and rotations' learning rates x the factors below; stereo: only when the initial points came from
    #   plane-sweep stereo alone (model.init sfm falling back to stereo on wide baselines, or stereo): a dense
    #   cloud that growth would only bend towards the few inputs
    means_lr: float = 0.1
    scales_lr: float = 0.2
    quats_lr: float = 0.1

    LIMITS = {"geometry": "{off, on, stereo}", "means_lr": "> 0", "scales_lr": "> 0", "quats_lr": "> 0"}
    LEGACY = {"hold_geometry": "geometry", "hold_means_lr": "means_lr", "hold_scales_lr": "scales_lr",
              "hold_quats_lr": "quats_lr"}  # train.<key> of earlier versions (MOVED)


@dataclass
class GuardConfig:
    """The step guard and the performance of the loop (``guard``; warpgs/engine/stepguard.py). Keys of
    ``train`` before this section existed load through ``MOVED``, and ``cfg.train.<key>`` still reads and
    sets them."""

    # divergence: a non-finite loss or gradient, or a loss above explode_factor x the median of the phase's last
    # explode_window finite losses, skips the step; max_nan_steps skipped steps in a row, explode_patience
    # exploding ones in a row, or non-finite parameters after the optimiser step roll back to the last good
    # in-memory snapshot with the learning rates scaled by recovery_lr_factor; after max_recoveries rollbacks the
    # run stops (TrainingDiverged), and the checkpoint on disk stays the last good one
    max_nan_steps: int = 20  # consecutive skipped steps that count as a divergence
    explode_factor: float = 10.0  # 0 = no exploding-loss check; healthy runs stayed below 6x (bench/quality/stability.py)
    explode_window: int = 100  # recent finite losses (of this phase) in the running median
    explode_patience: int = 3  # consecutive exploding steps that count as a divergence (fewer are only skipped)
    snapshot_every: int = 100  # steps between snapshots of the last good state (and one at each train() call)
    snapshot_on_device: bool = True  # CUDA: the snapshot stays in GPU memory (one more copy of the training
    #   state there) instead of a copy to the CPU that stops the host; false: on the CPU
    max_recoveries: int = 3  # rollbacks before the run stops; 0 = stop at the first divergence
    recovery_lr_factor: float = 0.5  # learning-rate scale applied at each rollback (recorded in metrics.json)
    cpu_threads: int = 1  # torch threads on the CPU (0: torch's default); Warp's CPU kernels use one anyway
    guard_kernels: bool = True  # a deferred step's verdict in two Warp launches (DivergenceGuard.step_on_device)
    #   instead of two dozen small torch ops: the same arithmetic (bit-identical runs); false: the torch ops. H100,
    #   fern 3 views (git show e26aeea:bench/results/train_speed_cuda_kernels.json): the trainer 8% faster, the same model
    sync_every: int | None = None  # steps between host reads of the losses and the guard's verdicts (a read
    #   waits for the device); in between, a step with a non-finite or exploding loss skips its update on the
    #   device and a divergence is acted on at the next read, up to this many steps late. The progress bar's
    #   loss and PSNR are read at the same steps. None: 10 on CUDA, 1 (every step) on the CPU
    cuda_graph: bool = True  # CUDA: a deferred step that holds nothing a graph cannot (no densification or
    #   pruning at that step, no Pearson depth term, no co-regularised pair, the baseline's loss; dropout, opacity
    #   noise, a random background and the far field are held) is recorded once as a CUDA graph and replayed
    #   (warpgs/engine/graphstep.py): the same numbers, a fraction of the host time; false: every step launches its
    #   kernels one by one

    LIMITS = {"max_nan_steps": ">= 1", "explode_factor": ">= 0", "explode_window": ">= 1", "explode_patience": ">= 1",
              "snapshot_every": ">= 0", "max_recoveries": ">= 0", "recovery_lr_factor": "(0, 1]", "cpu_threads": ">= 0",
              "sync_every": ">= 1"}


@dataclass
class EvalConfig:
    lpips_weights: str | None = None  # AlexNet weights; None: $WARPGS_LPIPS_WEIGHTS or the default location
    save_images: bool = True
    fps_repeats: int = 3

    LIMITS = {"fps_repeats": ">= 1"}


@dataclass
class FullConfig:
    """The generation-guided method (``method: full``; warpgs/methods/full.py). Loss weights are the
    paper's (w4 LPIPS 1.0, w5 D-SSIM 0.2, w6 depth 1.0 on pseudo views, scaled by pseudo_weight)."""

    cycles: int = 2  # pseudo-view updates (the paper: refinement cycles of 10K iterations)
    baseline_fraction: float = 0.4  # share of train.iterations before the first pseudo-view update
    cycle_iterations: int = 0  # 0: the cycles share train.iterations with the baseline phase (baseline_fraction), so the
    #   two methods train equally long | > 0: the paper's schedule: the baseline phase is the whole baseline run (every
    #   schedule as the baseline's; baseline_fraction unused), then each cycle trains this many more steps, so a run
    #   takes train.iterations + cycles x cycle_iterations steps in all
    pseudo_weight: float = 1.0  # scale of the pseudo-view loss: 1 = the paper's weights (SYN3R code: 0.05 LLFF/DTU, 0.2 DL3DV)
    lpips_weight: float = 1.0  # w4
    ssim_weight: float = 0.2  # w5
    depth_weight: float = 1.0  # w6, Pearson against the plane-sweep depth where it is confident
    input_depth_weight: float = 1.0  # w3 on the inputs, against their plane-sweep depth (never the loader's)
    early_depth: bool = False  # the inputs' depth prior from plane-sweep stereo between them before the first step
    #   (the paper's input loss has its depth term throughout); false: from the first cycle's stereo on. On the
    #   captures (384x256, seeds 0-2) it cost 0.97 dB on average, castle 6 / 9 views 2.0 / 3.6
    pseudo_loss: str = "lpips"  # lpips | l1 (ablation; also the fallback when LPIPS weights are absent)
    guidance: str = "warped"  # warped | render (ablation: 3D-GS renders instead of warped guidance)
    densify: bool = True  # densification from pseudo views (ablation: false)
    point_filter: bool = True  # statistical outlier removal of the stereo cloud (ablation: false)
    stereo_sources: str = "inputs"  # inputs: every stereo reference (input or pseudo view) is matched against the
    #   input views only | all: against its nearest views, pseudo views included (SYN3R)
    init_opacity: float = 0.1  # opacity of the Gaussians densification adds
    max_new: int = 0  # cap on Gaussians added per cycle (0: none)
    restart_lr: bool = True  # the means' learning-rate schedule restarts at each pseudo-view update (the paper);
    #   false: one schedule over the whole run, as the baseline's
    pseudo_mask: str = "seen"  # pixels of a pseudo view that supervise: seen (U < 1: an input sees them) |
    #   reliable (U < the sampler's delta: where guidance was fused) | all (every pixel: what no input sees
    #   is held to the render the pseudo view was made from)
    growth_budget: float = 0.0  # > 0: at most this x the baseline phase's Gaussians during the cycles (0: no cap)
    drop_rate: float | None = None  # DropGaussian's final rate for this method (train.drop_rate); None: train's
    pseudo_depth_smooth: float = 0.0  # weight of an edge-aware smoothness of the pseudo views' rendered depth
    #   (Monodepth's, Godard et al. CVPR 2017, on depth / its mean; edges from the pseudo view's image); 0: off
    far_field: str | None = None  # the far field for this method (backgrounds.far_field.kind: none | elevation |
    #   sky); None: that one
    refine_stop_fraction: float | None = None  # strategy.refine_stop_fraction for this method; None: the strategy's
    path_consistency: float = 0.0  # weight of the two inputs' agreement at each pseudo view trained on: the photos of
    #   the inputs it lies between, warped into it with its rendered depth (warpgs.regularizers.binocular.pose_warp), compared
    #   (L1 where both land); its gradient reaches the depth each step, unlike the pseudo view's fixed image. 0: off
    reliable_weight: float = 1.0  # weight of a pseudo view's reliable pixels (U < pseudo.sampler.delta: where the
    #   warped inputs were kept) in its L1 and D-SSIM, the other pixels' being 1 (the render they were filled from,
    #   made at the cycle's start). With pseudo_weight 0.2 and 5 the warped inputs weigh 1, the paper's weight, and
    #   the render 0.2. An LPIPS term, when its weights are there, stays unweighted. 1: every pixel alike
    flythrough_frames: int = 24  # frames per trajectory in flythrough.gif

    LIMITS = {"cycles": ">= 0", "baseline_fraction": "[0, 1)", "cycle_iterations": ">= 0", "pseudo_weight": ">= 0",
              "lpips_weight": ">= 0", "ssim_weight": ">= 0", "depth_weight": ">= 0", "input_depth_weight": ">= 0",
              "pseudo_loss": "{lpips, l1}", "guidance": "{warped, render}", "stereo_sources": "{inputs, all}",
              "init_opacity": "(0, 1)", "max_new": ">= 0", "pseudo_mask": "{seen, reliable, all}", "growth_budget": ">= 0",
              "drop_rate": "[0, 1)", "pseudo_depth_smooth": ">= 0", "far_field": FAR_FIELD_RULE, "refine_stop_fraction": "[0, 1]",
              "path_consistency": ">= 0", "reliable_weight": "> 0", "flythrough_frames": ">= 0"}


@dataclass
class CoRGSConfig:
    """CoR-GS (Zhang et al., ECCV 2024; ``method: corgs``, warpgs/coreg.py): a second model trained beside the first
    from the same initial Gaussians, on the same views, with its own random streams; twice the training cost. The
    first model is the one evaluated and exported. Keys of ``train`` before this section existed (``train.co_reg``,
    ``train.co_prune_every``, ...) load through ``MOVED``."""

    pair: bool = False  # the co-regularised pair with any method (--method corgs: always)
    prune_every: int = 500  # co-pruning every this many steps after strategy.refine_start_iter (CoR-GS: 500, at a
    #   densification step); 0: no co-pruning
    prune_dist: float = 0.75  # co-pruning drops a Gaussian with no centre of the other model within this x the
    #   scene scale (optim.scene_scale: the training cameras' extent). CoR-GS's tau = 5 on LLFF 3 views is in
    #   COLMAP's units, where the middle 80% of the 20 camera centres span 10: the 3 training views, at both ends
    #   and the middle, have an extent of about 6.5, so tau is about 0.75 of it
    weight: float = 1.0  # x (l1_weight L1 + ssim_weight D-SSIM) between the two models' renders of a pose between
    #   two neighbouring training views, each against the other's detached render (CoR-GS: 1); 0: off
    start: int = 500  # first step of the co-regularisation (CoR-GS's LLFF script: 500)
    frames: int = 24  # pseudo poses between each pair of neighbouring training views, drawn in turn

    LIMITS = {"prune_every": ">= 0", "prune_dist": "> 0", "weight": ">= 0", "start": ">= 0", "frames": ">= 1"}
    LEGACY = {"co_reg": "pair", "co_prune_every": "prune_every", "co_prune_dist": "prune_dist",
              "co_reg_weight": "weight", "co_reg_start": "start", "co_reg_frames": "frames"}  # train.<key> (MOVED)


GUARD_KEYS = tuple(f.name for f in dataclasses.fields(GuardConfig))
# the sections that took keys of ``train``, each with its ``LEGACY`` {old train key: its key}
LEGACY_SECTIONS = {"clearance": ClearanceConfig, "hold": HoldConfig, "strategy": DefaultStrategy,
                   "corgs": CoRGSConfig}
# the registries' sections, each with the keys of ``train`` its modules took {old: (module's name, its key)}
REGISTRY_KEYS = {"regularizers": REGULARIZER_KEYS, "backgrounds": BACKGROUND_KEYS}
MOVED_SECTIONS = {"guard": GuardConfig, "regularizers": RegularizersConfig, "backgrounds": BackgroundsConfig,
                  **LEGACY_SECTIONS}
# keys of ``train`` before the sections existed -> where they live now (MOVED; TrainConfig reads and sets them)
TRAIN_MOVED = {**{k: ("guard", k) for k in GUARD_KEYS},
               **{old: (section, name, new) for section, keys in REGISTRY_KEYS.items()
                  for old, (name, new) in keys.items()},
               **{old: (section, new) for section, cls in LEGACY_SECTIONS.items() for old, new in cls.LEGACY.items()}}


def _moved_key(path: tuple) -> property:
    """``TrainConfig.<old key>``: the key at ``path`` (a section, its subsections, the key), for scripts that set
    it on ``cfg.train`` as before the sections existed."""
    def owner(train):
        node = train.moved_section(path[0])
        for name in path[1:-1]:
            node = getattr(node, name)
        return node

    return property(lambda self: getattr(owner(self), path[-1]), lambda self, v: setattr(owner(self), path[-1], v),
                    doc=f"{'.'.join(path)} (read and set through train as before)")


for _old, _path in TRAIN_MOVED.items():
    setattr(TrainConfig, _old, _moved_key(_path))


@dataclass
class Config:
    method: str = "baseline"  # baseline | full | corgs (warpgs.methods); the command's compare runs baseline and full
    out: str = "outputs/sparse"  # the run folder
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    strategy: DefaultStrategy = field(default_factory=DefaultStrategy)
    train: TrainConfig = field(default_factory=TrainConfig)
    guard: GuardConfig = field(default_factory=GuardConfig)  # the step guard and the loop's performance
    regularizers: RegularizersConfig = field(default_factory=RegularizersConfig)  # warpgs/regularizers, one each
    backgrounds: BackgroundsConfig = field(default_factory=BackgroundsConfig)  # warpgs/backgrounds, one each
    clearance: ClearanceConfig = field(default_factory=ClearanceConfig)  # the capture path's pruning
    hold: HoldConfig = field(default_factory=HoldConfig)  # holding the initial geometry
    eval: EvalConfig = field(default_factory=EvalConfig)
    full: FullConfig = field(default_factory=FullConfig)
    corgs: CoRGSConfig = field(default_factory=CoRGSConfig)  # CoR-GS's co-regularised pair (warpgs/coreg.py)
    compact: CompactConfig = field(default_factory=CompactConfig)  # compact mode (warpgs/strategy/compact.py)
    geometry: GeometryConfig = field(default_factory=GeometryConfig)  # model.init sfm / stereo (warpgs/points)
    pseudo: PseudoConfig = field(default_factory=PseudoConfig)  # the full method's pseudo views (warpgs/pseudo)
    densify: DensifyConfig = field(default_factory=DensifyConfig)  # its densification from them (warpgs/densify)

    def __post_init__(self):
        self.train.link_sections({name: getattr(self, name) for name in MOVED_SECTIONS})  # (TrainConfig.__post_init__)


# ----------------------------------------------------------------------------------------------


def to_dict(cfg) -> dict:
    return dataclasses.asdict(cfg)


# keys of earlier versions -> where they live now (read from old config.yaml files and checkpoints)
MOVED = {("full", "n_frames"): ("pseudo", "trajectory", "n_frames"),
         ("full", "geometric"): ("pseudo", "uncertainty", "geometric"),
         ("full", "photometric"): ("pseudo", "uncertainty", "photometric"),
         ("full", "pseudo"): ("pseudo",),
         ("full", "densify_config"): ("densify",),
         ("train", "compact"): ("strategy", "prune_unseen_at_end"),
         ("strategy", "compact_when_full"): ("strategy", "prune_unseen_when_full"),
         ("strategy", "compact_min_weight"): ("strategy", "unseen_min_weight"),
         **{("train", old): new for old, new in TRAIN_MOVED.items()}}


def upgrade(layer: dict) -> dict:
    """A config layer with the keys of earlier versions moved to where they live now (``MOVED``)."""
    if not isinstance(layer, dict):
        return layer
    for (section, key), new in MOVED.items():
        if isinstance(layer.get(section), dict) and key in layer[section]:
            value = layer[section][key]
            layer = {**layer, section: {k: v for k, v in layer[section].items() if k != key}}
            for name in reversed(new):
                value = {name: value}
            layer = merge(layer, value)
    return layer


def build_config(layers: list) -> Config:
    """Defaults, then each layer in order (nested dicts, later ones winning). Every layer is checked on
    its own (keys, types, ``LIMITS`` ranges), so a bad value is an error even where a later layer sets the
    key again, and the error names the layer: each is a dict or a ``(where, dict)`` pair."""
    merged: dict = {}
    for k, layer in enumerate(layers):
        where, values = layer if isinstance(layer, tuple) else (f"config layer {k + 1}", layer)
        values = upgrade(values)
        apply_values(Config(), values, where)
        merged = merge(merged, values)
    cfg = Config()
    apply_values(cfg, merged, "the merged config")
    return cfg


def load_config(files: list[str | Path] = (), overrides: list[str] = ()) -> Config:
    """Defaults, then ``files`` in order, then ``key=value`` overrides."""
    layers = [(str(f), read_yaml(f)) for f in files] + [(f"--set {o}", parse_override(o)) for o in overrides]
    return build_config(layers)


def config_from_dict(d: dict, where: str = "a saved config") -> Config:
    return build_config([(where, d)])


def save_config(cfg: Config, path: str | Path) -> None:
    text = yaml.safe_dump(to_dict(cfg), sort_keys=False)
    atomic_write(path, lambda tmp: tmp.write_text(text))
