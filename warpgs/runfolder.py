"""Run folders: one run at a time in an output folder, and no earlier run replaced unasked.

    folder = open_run_folder(out, resume=False, overwrite=False)   # RunFolderError (one line) when it cannot
    try:
        ...                                                         # the run writes into out
    finally:
        folder.release()

- ``open_run_folder`` first checks that the folder can be created and written (a path below a file, a
  read-only or virtual file system like /proc: one line naming the path and the reason).
- It then takes the folder's lock, ``.warpgs.lock``: JSON with the owner's pid, host, process start time
  and command line, created atomically (a hard link of a complete file, so no reader ever sees half of
  one). A second run into a locked folder stops with ``RunFolderError`` naming the owner. A lock whose
  process is gone from this host (a run killed with SIGKILL, a machine that rebooted) is stale: it is
  taken over with a one-line note. A lock written on another host cannot be checked from here; the
  message says to delete the file once that run is known to be over.
- A folder holding an earlier run (``metrics.json``, ``checkpoint.pt`` or ``config.yaml``, in the folder or
  in a compare run's ``baseline/`` and ``full/``) is only written with ``resume`` (continue it) or
  ``overwrite`` (its outputs, the names and patterns in ``RUN_OUTPUTS``, are deleted first; nothing else
  in the folder is touched).
"""

from __future__ import annotations

import errno
import json
import os
import secrets
import shutil
import socket
import sys
import time
from pathlib import Path

LOCK = ".warpgs.lock"
# a run's checkpoint and the one it replaced (warpgs.train's CHECKPOINT and PREVIOUS_CHECKPOINT), newest first
CHECKPOINT_FILES = ("checkpoint.pt", "checkpoint.prev.pt")
# what a run writes into its folder (a compare run: these, and the same in baseline/ and full/)
RUN_OUTPUTS = (*CHECKPOINT_FILES, "metrics.json", "comparison.json", "config.yaml",
               "point_cloud.ply", "init_points.ply", "report.md", "flythrough.gif", "baseline.log", "test", "charts",
               "cycle_*")
METHOD_DIRS = ("baseline", "full")


class RunFolderError(RuntimeError):
    """The output folder cannot take this run (locked by another run, holding an earlier one, not
    writable); the message is one line naming the folder and what to do."""


def _boot_id() -> str | None:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return None


def _process_start(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot, Linux), or None where it is unknown:
    with the boot id it tells a live owner from a new process that got the same pid."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[-1].split()[19]  # field 22 (starttime), counted after the command name


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs. A zombie does not: a run killed with its parent (a batch worker that died) is
    reparented, and where nothing reaps it, it stays in the process table with its pid."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    except OSError:
        return False
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[0] != "Z"  # field 3, the state
    except (OSError, IndexError):
        return True


def _describe_owner(info: dict) -> str:
    started = info.get("started")
    when = time.strftime(" since %Y-%m-%d %H:%M:%S", time.localtime(started)) if isinstance(started, (int, float)) else ""
    return f"pid {info.get('pid', '?')} on {info.get('host', '?')}{when}"


def lock_is_stale(info: dict) -> bool:
    """Whether the run that wrote the lock ``info`` is certainly gone (only decidable on this host)."""
    if info.get("host") != socket.gethostname() or not isinstance(info.get("pid"), int):
        return False
    if info.get("boot_id") and _boot_id() and info["boot_id"] != _boot_id():
        return True  # written before the last reboot
    pid = info["pid"]
    if not _alive(pid):
        return True
    start = _process_start(pid)
    return bool(info.get("start") and start and start != info["start"])  # the pid now belongs to another process


def read_lock(folder: str | Path) -> dict | None:
    """The lock's content, None when there is none, ``{}`` when it cannot be read."""
    p = Path(folder) / LOCK
    try:
        info = json.loads(p.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def checkpoint_file(folder: str | Path) -> Path | None:
    """The newest checkpoint file in ``folder`` (``CHECKPOINT_FILES``), or None."""
    return next((Path(folder) / n for n in CHECKPOINT_FILES if (Path(folder) / n).is_file()), None)


def read_metrics(folder: str | Path) -> dict | None:
    """The run folder ``folder``'s metrics.json as a dict, or None (missing, unreadable, not an object)."""
    try:
        m = json.loads((Path(folder) / "metrics.json").read_text())
    except (OSError, ValueError):
        return None
    return m if isinstance(m, dict) else None


def stopped_early(metrics: dict | None) -> dict | None:
    """The ``stopped_early`` record of a run's metrics (``{"reason": "out_of_memory" | "diverged", "step": ...}``:
    the metrics are the last good state's), or None (finished, or no metrics)."""
    stop = (metrics or {}).get("stopped_early")
    return stop if isinstance(stop, dict) else None


def earlier_run(folder: str | Path) -> str | None:
    """What earlier run ``folder`` holds ("a finished run (metrics.json)", ...), or None."""
    folder = Path(folder)
    for d in (folder, *(folder / m for m in METHOD_DIRS)):
        if (d / "metrics.json").is_file() or (d / "comparison.json").is_file():
            stop = stopped_early(read_metrics(d))
            if stop:  # the last good state's metrics (out of memory, divergence): --resume continues the run
                at = f" at step {stop['step']}" if "step" in stop else ""
                return f"a run that stopped early ({stop.get('reason', 'stopped')}{at}; {d / 'metrics.json'})"
            return f"a finished run ({d / 'metrics.json'})"
    for d in (folder, *(folder / m for m in METHOD_DIRS)):
        found = checkpoint_file(d)
        if found is not None:
            return f"an unfinished run ({found})"
    if (folder / "config.yaml").is_file():
        return f"a run that stopped before its first checkpoint ({folder / 'config.yaml'})"
    return None


def _reason(e: OSError) -> str:
    return {errno.ENOTDIR: "a part of the path is a file, not a folder", errno.EEXIST: "it exists and is not a folder",
            errno.EROFS: "the file system is read-only", errno.EACCES: "permission denied",
            errno.EPERM: "permission denied", errno.ENOSPC: "no space left on the device",
            errno.EDQUOT: "the disk quota is used up", errno.EFBIG: "the file is larger than this process may write",
            errno.ENAMETOOLONG: "a name in the path is longer than the file system allows (255 bytes): "
                                "choose a shorter --out"}.get(e.errno, e.strerror or str(e))


def atomic_write(path: str | Path, write) -> Path:
    """Writes a file through ``write(tmp)`` into a temporary name beside ``path``, then renames it into place: a
    reader never sees half a file, and when writing fails (a full disk) the temporary file is removed and the
    ``OSError`` goes on, leaving ``path`` as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def check_writable(folder: str | Path) -> Path:
    """Creates ``folder`` (and its parents) if needed and checks that a file can be written in it;
    ``RunFolderError`` in one line otherwise. Returns the folder."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise RunFolderError(f"output folder {folder}: it exists and is a file, not a folder")
    blocker = next((p for p in folder.parents if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise RunFolderError(f"output folder {folder}: {blocker} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".warpgs-write-test-{os.getpid()}"
        with open(probe, "wb") as f:
            f.write(b"ok")
        probe.unlink()
    except OSError as e:
        where = f" ({e.filename})" if e.filename and str(e.filename) != str(folder) else ""
        raise RunFolderError(f"output folder {folder}: cannot be created or written: {_reason(e)}{where}") from None
    return folder


class RunFolder:
    """A run's hold on its output folder (``open_run_folder``); ``release()`` gives the lock back."""

    def __init__(self, path: Path, token: str, notes: list[str]):
        self.path, self.token, self.notes = path, token, notes
        self.held = True
        self.created = False  # made by this run: removed again if the run leaves it empty (it stopped early)

    def release(self) -> None:
        """Removes the lock if it is still this run's (a lock taken over by someone else stays), and the
        folder if this run created it and wrote nothing into it."""
        if not self.held:
            return
        self.held = False
        info = read_lock(self.path)
        if info and info.get("token") == self.token:
            try:
                (self.path / LOCK).unlink()
                if self.created and not any(self.path.iterdir()):
                    self.path.rmdir()
            except OSError:
                pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _create_lock(folder: Path, info: dict) -> bool:
    """Writes the lock atomically; False when one exists already."""
    tmp = folder / f"{LOCK}.{os.getpid()}.{info['token'][:8]}"
    tmp.write_text(json.dumps(info, indent=1))
    try:
        os.link(tmp, folder / LOCK)
        return True
    except FileExistsError:
        return False
    except OSError:  # a file system without hard links: exclusive create (a reader may see it empty briefly)
        try:
            fd = os.open(folder / LOCK, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            return False
        with os.fdopen(fd, "w") as f:
            f.write(json.dumps(info, indent=1))
        return True
    finally:
        tmp.unlink(missing_ok=True)


def take_lock(folder: str | Path, log=None) -> RunFolder:
    """Takes ``folder``'s lock (``RunFolderError`` when a live run holds it); a stale one is taken over
    with a note through ``log``."""
    folder = Path(folder)
    log = log or (lambda msg: print(msg, file=sys.stderr))
    token = secrets.token_hex(8)
    info = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time(), "start": _process_start(os.getpid()),
            "boot_id": _boot_id(), "argv": sys.argv, "token": token}
    notes: list[str] = []
    for _ in range(5):
        if _create_lock(folder, info):
            return RunFolder(folder, token, notes)
        held = read_lock(folder)
        if held is None:
            continue  # released meanwhile: try again
        if not held:
            age = time.time() - (folder / LOCK).stat().st_mtime if (folder / LOCK).exists() else 0
            if age < 10:  # being written right now
                time.sleep(0.2)
                continue
        elif not lock_is_stale(held):
            where = "" if held.get("host") == socket.gethostname() else (
                f"; it was written on another host, so warpgs cannot check it: if that run is over, delete {folder / LOCK}")
            raise RunFolderError(f"output folder {folder} is in use by another warpgs run ({_describe_owner(held)}){where}; "
                                 "wait for it to finish or choose another --out")
        # stale: move it aside (one of several racing runs wins the rename) and try again
        aside = folder / f"{LOCK}.stale-{os.getpid()}"
        try:
            os.replace(folder / LOCK, aside)
        except FileNotFoundError:
            continue
        aside.unlink(missing_ok=True)
        note = (f"warpgs: note: took over the lock of {folder}: its run ({_describe_owner(held)}) is gone"
                if held else f"warpgs: note: took over the unreadable lock file {folder / LOCK}")
        log(note)
        notes.append(note)
    raise RunFolderError(f"output folder {folder}: could not take its lock {folder / LOCK} (other runs keep taking it)")


def remove_outputs(folder: str | Path) -> list[Path]:
    """Deletes an earlier run's outputs (the names in ``RUN_OUTPUTS``, also in ``baseline/`` and ``full/``,
    which go when nothing else is left in them); returns what was deleted."""
    folder = Path(folder)
    gone = []
    for d in (*(folder / m for m in METHOD_DIRS), folder):
        for p in (p for name in RUN_OUTPUTS for p in (sorted(d.glob(name)) if "*" in name else [d / name])):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            elif p.exists() or p.is_symlink():
                p.unlink()
            else:
                continue
            gone.append(p)
        if d != folder and d.is_dir() and not any(d.iterdir()):
            d.rmdir()
    return gone


def open_run_folder(folder: str | Path, *, resume: bool = False, overwrite: bool = False, log=None) -> RunFolder:
    """The checks and the lock of a run's output folder (module docstring), before any work starts; an OS error on
    the way (a name too long, no permission) is a ``RunFolderError`` naming the folder."""
    try:
        return _open_run_folder(Path(folder), resume, overwrite, log)
    except OSError as e:
        raise RunFolderError(f"output folder {folder}: cannot be used: {_reason(e)}") from None


def _open_run_folder(folder: Path, resume: bool, overwrite: bool, log) -> RunFolder:
    created = not folder.exists()
    folder = check_writable(folder)
    held = take_lock(folder, log)
    held.created = created
    try:
        before = earlier_run(folder)
        if before and not resume:
            if not overwrite:
                raise RunFolderError(f"output folder {folder} holds {before}; continue it with --resume, replace it "
                                     "with --overwrite, or choose another --out")
            remove_outputs(folder)
            (log or (lambda msg: print(msg, file=sys.stderr)))(
                f"warpgs: --overwrite: deleted the earlier run's outputs in {folder}")
    except BaseException:
        held.release()
        raise
    return held


__all__ = ["LOCK", "RUN_OUTPUTS", "RunFolder", "RunFolderError", "atomic_write", "check_writable", "earlier_run", "lock_is_stale",
           "open_run_folder", "read_lock", "remove_outputs", "take_lock"]
