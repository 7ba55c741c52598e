"""The training state and its files: one serialisation, ``state_dict(trainer, parts)`` / ``load_state_dict``,
in three parts: ``model`` (parameters, Adam's moments, densification statistics), ``progress`` (step, RNGs,
view order) and ``history`` (times, losses, recoveries, curve). Checkpoints hold all three, the in-memory
snapshot of a divergence rollback (``warpgs.engine.stepguard``) ``model`` and ``progress``, compact mode's
search (``warpgs.strategy.compact``) ``model``. A checkpoint of format 1 (the layout before the method's share moved
under ``method``) is upgraded when read (``upgrade_format_1``)."""

from __future__ import annotations

import copy
from pathlib import Path

import torch

from warpgs.config import config_from_dict, to_dict
from warpgs.engine.checkpoint import (CHECKPOINT, CheckpointError, atomic_torch_save, read_checkpoint,
                                      resumable_checkpoint, upgrade_format_1)
from warpgs.optim import STATE_PARTS, load_model_state, model_state

FORMAT = 2  # the layout state_dict writes


def state_dict(tr, parts=STATE_PARTS, device="cpu") -> dict:
    """A copy of ``tr``'s training state (its tensors on ``device``: the CPU but for the rollback snapshots),
    in ``parts`` (module docstring):

    - ``model``: the parameters (and SH degrees), Adam's moments, the densification statistics;
    - ``progress``: the step, the RNGs (the regularisers' too), the view order, where the guard's statistic
      starts, whether this is the middle of a phase (a resume continues that phase's statistic);
    - ``history``: training time, losses, learning-rate scale, recoveries, curve, initial metrics,
      the running learning-rate schedule, the guard's largest loss ratio (metrics.json's ``max_loss_ratio``);

    and the method's share of each (``Method.state_dict``) under ``method``, the co-regularised pair's second
    model's (``warpgs.coreg.CoRegPair.state_dict``) under ``pair``."""
    st: dict = {"parts": list(parts)}
    if "model" in parts:
        st.update(model_state(tr.model, tr.optimizer, tr.state, device))
    if "progress" in parts:
        st.update(tr.regularizers.state_dict())
        st.update(step=tr.step, split_gen=tr.split_gen.get_state(), drop_gen=tr.drop_gen.get_state(),
                  view_rng=copy.deepcopy(tr.view_rng.bit_generator.state), order=list(tr.order),
                  torch_rng=torch.get_rng_state(), stat_start=tr.guard.stat_start, in_phase=tr.in_phase)
    if "history" in parts:
        st.update(train_time=tr.train_time, losses=list(tr.losses), lr_scale=tr.lr_scale,
                  recoveries=copy.deepcopy(tr.recoveries), curve=copy.deepcopy(tr.curve),
                  initial=copy.deepcopy(tr.initial), n_before_compaction=tr.n_before_compaction,
                  phase=(tr.phase_start, tr.phase_len), max_loss_ratio=tr.guard.max_loss_ratio)
    st["method"] = tr.method.state_dict(parts)
    if tr.pair is not None:
        st["pair"] = tr.pair.state_dict(parts, device)
    return st


def load_state_dict(tr, st: dict) -> None:
    """Puts back the parts ``st`` holds into ``tr`` (copies of them: ``st`` stays usable). The model object
    stays (the strategy may hold it); with ``progress`` the learning rates are set for the restored step and
    learning-rate scale, else they are as saved in the optimiser's state."""
    parts = st.get("parts", STATE_PARTS)
    tr.stepguard.window = None  # the guard's statistic on the device: rebuilt from the restored losses
    if "model" in parts:
        tr.optimizer, tr.state = load_model_state(st, tr.model, tr.cfg, tr.scene_scale, tr.device)
    if "history" in parts:
        tr.train_time = float(st["train_time"])
        tr.losses = list(st["losses"])
        tr.lr_scale = float(st.get("lr_scale", 1.0))
        tr.recoveries = copy.deepcopy(st.get("recoveries", []))
        tr.curve = copy.deepcopy(st.get("curve", []))
        tr.initial = copy.deepcopy(st.get("initial"))
        tr.n_before_compaction = st.get("n_before_compaction")
        if "phase" in st:
            tr.phase_start, tr.phase_len = st["phase"]
        tr.guard.max_loss_ratio = float(st.get("max_loss_ratio", tr.guard.max_loss_ratio))
    if "progress" in parts:
        tr.step = int(st["step"])
        tr.split_gen.set_state(st["split_gen"])
        if "drop_gen" in st:
            tr.drop_gen.set_state(st["drop_gen"])
        tr.regularizers.load_state_dict(st)
        tr.view_rng.bit_generator.state = copy.deepcopy(st["view_rng"])
        tr.order = list(st["order"])
        torch.set_rng_state(st["torch_rng"])
        if "stat_start" in st:
            tr.guard.stat_start = st["stat_start"]
    if tr.pair is not None:
        tr.pair.load_state_dict(st.get("pair"), parts)
    if "progress" in parts:
        tr.apply_lr_scale()
    tr.method.load_state_dict(st.get("method", {}))


def save_checkpoint(tr, path: str | Path | None = None) -> Path | None:
    """Writes ``tr``'s checkpoint (atomically); returns its path, or None when there is no output folder or
    the state is not finite (a checkpoint is never written from a diverged state: the one on disk stays the
    last good one)."""
    if path is None:
        if tr.out is None:
            return None
        path = tr.out / CHECKPOINT
    path = Path(path)
    if not tr.stepguard.state_is_finite():
        tr.log(f"warpgs: step {tr.step}: the model or optimiser state is not finite; {path} is not written "
               "(the checkpoint there, if any, is the last good one)")
        return None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_torch_save({"format": FORMAT, "config": to_dict(tr.requested_cfg), "scene": tr.scene.name,
                           "method_name": tr.method.name, **tr.state_dict()}, path)
    except OSError as e:
        kept = (f"the last good checkpoint {path} (step {tr.saved_step}) is intact" if path.is_file()
                and tr.saved_step is not None else f"{path} as it was is left untouched" if path.is_file()
                else "no checkpoint was written before it")
        raise CheckpointError(f"{path}: cannot write the checkpoint of step {tr.step} "
                              f"({e.strerror or e}); {kept}") from None
    tr.saved_step = tr.step
    return path


def load_checkpoint(tr, path: str | Path | None = None) -> Path:
    """Restores ``tr``'s training state from ``path``, or (None) from the output folder's checkpoint, falling
    back to the previous one when it cannot be read (``resumable_checkpoint``); returns the file used.
    ``CheckpointError`` (one line) when there is none or none can be read."""
    if path is not None:
        path = Path(path)
        ck = read_checkpoint(path)
    else:
        found = resumable_checkpoint(tr.out) if tr.out is not None else None  # its note: once per process
        if found is None:
            raise CheckpointError(f"{tr.out / CHECKPOINT if tr.out else 'no output folder'}: "
                                  "no checkpoint to resume from")
        path, ck = found
    saved = config_from_dict(ck["config"], str(path))
    for section in ("model", "optim", "loss", "strategy"):
        if to_dict(getattr(saved, section)) != to_dict(getattr(tr.requested_cfg, section)):
            tr.log(f"warpgs: note: the checkpoint's {section} config differs from this run's; using this run's")
    if ck.get("format", 1) == 1:
        ck = upgrade_format_1(ck, tr.cfg.train.sh_degree_interval)
    if ck.get("pair") is not None and tr.pair is None:
        tr.log("warpgs: note: the checkpoint holds a co-regularised pair (corgs.pair); this run goes on with "
               "its first model alone")
    try:
        tr.load_state_dict(ck)
    except (KeyError, TypeError, ValueError, RuntimeError) as e:  # a file of another model or version
        raise CheckpointError(f"{path}: does not fit this run ({type(e).__name__}: "
                              f"{str(e).splitlines()[0][:120] if str(e) else ''})") from None
    tr.saved_step = tr.step
    tr.resumed = bool(ck.get("in_phase"))
    return path
