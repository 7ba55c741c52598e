"""Checkpoint files and the errors that end training.

Checkpoints (``checkpoint.pt`` in the output folder) are written every ``train.checkpoint_every``
steps through a temporary file (flushed to disk) and a rename, so an interruption never leaves a broken
one, and the one they replace is kept beside them as ``checkpoint.prev.pt``. A checkpoint that cannot be
read is a ``CheckpointError`` in one line; resuming (``Trainer.load_checkpoint()`` without a path) then
falls back to the previous one with a note. A write that fails (a full disk) leaves both files as they were
and raises ``CheckpointError`` naming the last good one. A stop request (Ctrl-C, SIGTERM;
``warpgs.engine.signals``) finishes the current step, writes a checkpoint and stops (``TrainingInterrupted``).
"""

from __future__ import annotations

import errno
import os
import shutil
from pathlib import Path

import torch

from warpgs.console import warn_once
from warpgs.model import GaussianModel

CHECKPOINT = "checkpoint.pt"
PREVIOUS_CHECKPOINT = "checkpoint.prev.pt"  # the one checkpoint.pt replaced, kept until the next write


class CheckpointError(RuntimeError):
    """A checkpoint cannot be read or written; the message is one line naming the file."""


def previous_checkpoint(path: str | Path) -> Path:
    """Where the checkpoint ``path`` replaced is kept (``checkpoint.pt`` -> ``checkpoint.prev.pt``)."""
    path = Path(path)
    return path.with_name(f"{path.stem}.prev{path.suffix}")


def read_checkpoint(path: str | Path) -> dict:
    """A checkpoint's content; ``CheckpointError`` in one line when it is missing, truncated, corrupt or not
    a warpgs checkpoint."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # zip reader, unpickler, EOF: a truncated or overwritten file
        why = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__).split(". ")[0]
        raise CheckpointError(f"{path}: cannot be read, it is truncated or corrupt ({type(e).__name__}: "
                              f"{why[:120]})") from None
    missing = [k for k in ("config", "params") if not isinstance(ck, dict) or k not in ck]
    if missing:
        raise CheckpointError(f"{path}: not a warpgs checkpoint (no {', '.join(missing)})")
    return ck


def resumable_checkpoint(folder: str | Path, log=None) -> tuple[Path, dict] | None:
    """The checkpoint to resume ``folder``'s run from, read: ``checkpoint.pt``, or when that cannot be read
    (or is missing) the previous one, ``checkpoint.prev.pt``, with a one-line note through ``log`` (default
    ``warn_once``: once per process). None when the folder holds neither; ``CheckpointError`` when no file
    there can be read."""
    current = Path(folder) / CHECKPOINT
    prev = previous_checkpoint(current)
    if not current.is_file() and not prev.is_file():
        return None
    try:
        return current, read_checkpoint(current)
    except CheckpointError as e:
        if not prev.is_file():
            raise
        try:
            ck = read_checkpoint(prev)
        except CheckpointError as e2:
            raise CheckpointError(f"{e}; the previous one cannot be read either ({e2})") from None
        msg = f"warpgs: {e}; resuming from the previous checkpoint {prev.name} (step {ck.get('step')})"
        (log or warn_once)(msg)
        return prev, ck


class TrainingInterrupted(Exception):
    """Training stopped on request (Ctrl-C, SIGTERM) after saving a checkpoint."""

    def __init__(self, step: int, checkpoint: Path | None, signum: int | None = None):
        super().__init__(f"interrupted at step {step}" + (f"; checkpoint {checkpoint}" if checkpoint else ""))
        self.step, self.checkpoint = step, checkpoint
        self.signum = signum  # the signal that asked for the stop (None: a request in code, as Ctrl-C's)


class TrainingDiverged(RuntimeError):
    """Training stopped because it diverged and the recoveries did not help (``warpgs.engine.stepguard``).

    ``step``: where the last divergence was found; ``cause``: what it was; ``checkpoint``: the last good
    checkpoint on disk (None when none was written)."""

    def __init__(self, message: str, step: int | None = None, cause: str | None = None,
                 checkpoint: Path | None = None):
        super().__init__(message)
        self.step, self.cause, self.checkpoint = step, cause, checkpoint


def atomic_torch_save(obj, path: Path, keep_previous: bool = True) -> None:
    """Writes ``obj`` to a temporary file beside ``path``, flushes it to disk and renames it into place;
    with ``keep_previous`` the file it replaces becomes ``previous_checkpoint(path)``. When writing fails
    (``OSError``, e.g. a full disk) the temporary file goes and ``path`` and its previous one stay as they were."""
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            torch.save(obj, f)
            f.flush()
            os.fsync(f.fileno())
    except RuntimeError as e:  # torch's zip writer reports a failed write (a full disk) as a RuntimeError
        tmp.unlink(missing_ok=True)
        full = shutil.disk_usage(path.parent).free < (64 << 20)
        raise OSError(errno.ENOSPC if full else errno.EIO,
                      "no space left on the device" if full else f"the write failed ({str(e).splitlines()[0]})",
                      str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if keep_previous and path.is_file():
        prev = previous_checkpoint(path)
        try:  # a second name for the current file, then renamed over the previous one: path exists throughout
            link = prev.with_name(prev.name + f".tmp{os.getpid()}")
            link.unlink(missing_ok=True)
            os.link(path, link)
            os.replace(link, prev)
        except OSError:  # no hard links here: the current one moves
            os.replace(path, prev)
    os.replace(tmp, path)


def upgrade_format_1(ck: dict, sh_degree_interval: int) -> dict:
    """A checkpoint of format 1 (the same keys; the full method's under ``full``, no SH degree in use) as
    ``Trainer.state_dict`` writes it."""
    ck = dict(ck)
    full = ck.pop("full", None)
    ck["active_sh_degree"] = min(int(ck["step"]) // max(sh_degree_interval, 1), ck["max_sh_degree"])
    ck["method"] = {"cycle": full} if full is not None else {}
    if full is not None:
        ck["phase"] = tuple(full["phase"])
    return ck


def load_trained(path: str | Path, device="cpu", drop_invalid: bool = False) -> GaussianModel:
    """A model from a checkpoint (``checkpoint.pt``) or a 3D-GS PLY (``drop_invalid``: ``load_ply``'s)."""
    path = Path(path)
    if path.suffix == ".ply":
        return GaussianModel.load_ply(path, device=device, drop_invalid=drop_invalid)
    ck = read_checkpoint(path)
    p = ck["params"]
    m = GaussianModel(p["means"], p["quats"], p["scales"], p["opacities"], p["sh0"], p["shN"],
                      max_sh_degree=ck["max_sh_degree"])
    m.active_sh_degree = m.max_sh_degree
    return m.to(device)
