"""The settings of the strategy package's stages that are not the strategy itself (``DefaultStrategy`` is its own
dataclass, gsplat's way): the capture path's pruning (``clearance``) and compact mode (``compact``). A leaf:
``warpgs.config`` imports it, and the modules that act on these settings (``warpgs.strategy.clearance``,
``warpgs.strategy.compact``) get them passed in, never the run's config module."""

from __future__ import annotations

from dataclasses import dataclass, field

from warpgs.configio import ConfigError, check_limits

IMPORTANCE_VIEWS = ("train", "virtual", "pseudo")


@dataclass
class ClearanceConfig:
    """The pruning on the capture path after the strategy's densification (``clearance``;
    warpgs/strategy/clearance.py). Keys of ``train`` before this section existed (``train.path_clearance``,
    ``train.path_floaters``, ...) load through ``MOVED``."""

    path: float = 0.0  # > 0: every strategy.refine_every steps, remove the Gaussians whose centre lies within this x
    #   the scene's near depth of the camera path (the photographer's space, where floaters in front of novel views
    #   sit); 0: off
    view: float = 0.0  # > 0: with the path clearance's schedule, also remove the Gaussians nearer than this x the near
    #   depth in front of any pose of the camera path (the inputs and the poses between them), inside its image; 0: off
    floaters: float = 0.0  # > 0: every floaters_every steps and before the final evaluation, remove the Gaussians that
    #   a pose of the camera path between neighbouring inputs sees with more than this x their blending weight in all
    #   the inputs together (and with at least 0.1% of that pose's weight): floaters no input constrains, in front of
    #   novel views taken from the path (``PathFloaters``; bench/diagnostics/floaters.py's test, which used 10 with
    #   the test views); 0: off
    floaters_every: int = 500
    floaters_final: bool = True  # also the pass before the final evaluation (no training after it)
    floaters_poses: int = 3  # poses of the path between each pair of neighbouring inputs
    floaters_paths: str = "spline"  # spline: those poses on the pseudo views' path | both: also as many on the
    #   straight line between the two inputs (bench/diagnostics/plant_floaters.py: castle_p30 9 views' test frame 16
    #   stands 1.5 m from that line and 4.4 m from the spline, which bulges across the 22.6 m gap between its inputs)

    LIMITS = {"path": ">= 0", "view": ">= 0", "floaters": ">= 0", "floaters_every": ">= 1", "floaters_poses": ">= 1",
              "floaters_paths": "{spline, both}"}
    LEGACY = {"path_clearance": "path", "view_clearance": "view", "path_floaters": "floaters",
              "path_floaters_every": "floaters_every", "path_floaters_final": "floaters_final",
              "path_floaters_poses": "floaters_poses", "path_floaters_paths": "floaters_paths"}  # train.<key> (MOVED)


@dataclass
class CompactConfig:
    """Compact mode (``--compact``, warpgs/strategy/compact.py): importance pruning during training and a search for
    the smallest model within a tolerance of the best training-view PSNR."""

    enabled: bool = False
    importance: str = "weight"  # weight (total blending weight) | weight_volume (x volume^volume_power, LightGaussian)
    volume_power: float = 0.1
    importance_views: list = field(default_factory=lambda: ["train", "pseudo"])  # of train, virtual, pseudo
    virtual_frames: int = 3  # virtual: poses interpolated between each pair of neighbouring training views
    prune_at: list = field(default_factory=lambda: [0.5, 0.65, 0.8])  # fractions of the run; [] = none
    prune_ratio: float = 0.3  # share of the Gaussians pruned at each of prune_at
    cap_after_prune: bool = False  # densification may not grow the count back above what each pruning left
    stop_densify_at: float | None = None  # fraction of train.iterations after which densification stops (None: the strategy's)
    tolerance_db: float = 0.1  # training-view PSNR the final model may lose against the best evaluated
    ratios: list = field(default_factory=lambda: [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9])  # searched; [] = no search
    finetune_steps: int = 300  # per point of the search
    sh_search: bool = True  # try lower SH degrees (0 first)
    report_test: bool = True  # record each point's test PSNR (reported only; never used to choose)
    seed: int = 0

    LIMITS = {"importance": "{weight, weight_volume}", "volume_power": ">= 0",
              "importance_views": "{" + ", ".join(IMPORTANCE_VIEWS) + "}", "virtual_frames": ">= 0",
              "prune_at": "(0, 1)", "prune_ratio": "[0, 1)", "stop_densify_at": "(0, 1]", "tolerance_db": ">= 0",
              "ratios": "(0, 1)", "finetune_steps": ">= 0", "seed": ">= 0"}


def check_compact_config(c: CompactConfig) -> CompactConfig:
    """The ranges of ``CompactConfig.LIMITS`` (for options built in code) and a non-empty list of views."""
    check_limits(c, "compact mode's options", "compact.")
    if not c.importance_views:
        raise ConfigError("compact.importance_views is empty: a non-empty list of " + ", ".join(IMPORTANCE_VIEWS))
    return c


__all__ = ["ClearanceConfig", "CompactConfig", "IMPORTANCE_VIEWS", "check_compact_config"]
