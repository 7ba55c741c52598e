"""Many runs at once: scenes x view counts x methods x seeds on every GPU (or CPU core) of a machine or a Ray
cluster, ``python -m warpgs.pipelines.batch``. Needs Ray: ``pip install 'warpgs[ray]'``.

    python -m warpgs.pipelines.batch --data castle_p30,herz_jesus_p25 --views 3,6,9 --method compare --seeds 0,1,2
    python -m warpgs.pipelines.batch --data synthetic --views 3 --seeds 0,1,2 --iterations 300 --device cpu
    python -m warpgs.pipelines.batch --address auto ...     # on a cluster started with `ray start`
    python -m warpgs.pipelines.batch ... --list             # the runs and their GPU shares; nothing runs
    python -m warpgs.pipelines.batch --sweep FILE --only '*_compact-virtual'   # some of a sweep's runs
    python -m warpgs.pipelines.batch --sweep bench/sweeps/captures_384x256.yaml --deadline 9m   # a sweep file

Each run is one Ray task that starts ``python -m warpgs.pipelines.sparse`` into ``OUT/runs/<name>`` (its own
process: a run killed by the OOM killer or ``kill -9`` is a process death this module sees, and nothing of it
stays in the worker). ``--method compare`` makes two runs, baseline and full. A ``--data`` entry is a dataset
name (``synthetic``, ``llff``, ...), a scene folder, or a scene of ``--dataset`` (DL3DV by default:
``castle_p30`` is ``--data dl3dv --scene castle_p30``). Runs are named ``<scene>_<views>v_<method>_s<seed>``, with
``_<variant>`` after it for the runs of a variant (``--variant``; bench/report/compare.py matches them by that).

Sweep files (``--sweep FILE``, YAML; ``load_sweep``): the runs of a batch written down, as groups of runs (each
every combination of its lists, as on the command line), settings every group shares, each group's ``variants``
(named sets of ``--set`` values, which repeat the group with the variant's name as suffix), and the batch's own
settings (``out``, ``data_root``, ``device``, ``runs_per_gpu``, ...; a flag given on the command line wins).

A call's time (``--deadline``: a duration, a UTC time or an ISO time): once it has passed no run starts, and a
run still going gets SIGTERM (it writes its checkpoint and stops; SIGKILL ``--grace`` seconds later). Such runs
are recorded as ``stopped`` and ``not_started`` (exit code 1), and the same command again resumes them.

Faults (issue 17):

- a run whose process dies (killed, out of memory: host or GPU) or whose Ray worker dies is retried, at most
  ``--max-retries`` times, and the retry continues from the run's last checkpoint (``--resume``); every
  attempt is recorded in ``OUT/logs/<name>.attempts.jsonl`` and in the results. So is a run that stopped
  itself on a GPU out of memory (its metrics.json with ``stopped_early: out_of_memory``, the last good
  state's): runs sharing a GPU cause that, and it passes;
- a run that stops with a clear error (exit code 2, ``error: ...``: a bad scene, bad settings) is reported
  with that line and not retried; the other runs go on;
- running the same command again skips every run whose ``metrics.json`` is complete (not stopped on out of
  memory) and resumes the others.

Resources: a run asks Ray for ``--cpus-per-run`` CPUs (1) and, on CUDA, for a share of a GPU, so that small
runs pack onto one GPU (``gpu_share``: megapixels / 2 + millions of Gaussians / 10, rounded up to 1/k and
kept in [1/8, 1]; ``--gpus-per-run`` overrides it, and ``--runs-per-gpu N`` gives every GPU N slots: each run asks
for 1/N). Ray spreads the runs over the visible GPUs and sets each run's ``CUDA_VISIBLE_DEVICES``.

Outputs in ``--out`` (default ``outputs/batch``): ``results.json`` and ``results.md`` (median and range over
seeds per scene, views and method; every run with its stage times, attempts and wall time; the GPU-hours
used), ``psnr_vs_time.png``, ``psnr_vs_gaussians.png``; a progress line while it runs (done / running /
failed, ETA). Exit code 0 when every run finished, 1 when some did not, 2 on bad input (one line).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

from warpgs.engine.signals import OUT_OF_MEMORY
from warpgs.pipelines.batch_plan import (BatchError, RunSpec, gpu_share, load_sweep,  # noqa: F401 (gpu_share: the
                                         parse_deadline, plan, plan_sweep)          # runner's API, as before)
from warpgs.runfolder import checkpoint_file, read_metrics, stopped_early

INSTALL_HINT = "pip install 'warpgs[ray]'"
# Ctrl-C or SIGTERM (the deadline's stop): the run stopped on request; not a fault to retry
STOPPED = (130, -signal.SIGINT, 128 + signal.SIGTERM, -signal.SIGTERM)
GRACE_S = 60.0  # seconds a run has after SIGTERM at the deadline before it is killed



class RunDied(RuntimeError):
    """A run's process died (a signal, or out of memory): Ray retries the task, which resumes the run."""


# ----------------------------------------------------------------------------------------------
# one run (the Ray task's body): start it, resume it, or skip it


def stopped_out_of_memory(m: dict | None) -> bool:
    """Whether metrics ``m`` are those of a run that stopped because its device ran out of memory (the last good
    state's, ``stopped_early.reason == "out_of_memory"``). Runs sharing a GPU cause that; it passes, so such a run
    is resumed from its checkpoint, not kept as finished (a run that diverged is: it would diverge again)."""
    return (stopped_early(m) or {}).get("reason") == "out_of_memory"


def metrics_complete(path: Path, method: str | None = None) -> dict | None:
    """The metrics of a finished run in ``path`` (its metrics.json with every record its method writes:
    the full method's ``cycles`` come after the common ones), else None. A run that stopped on running out
    of memory is not finished (``stopped_out_of_memory``)."""
    m = read_metrics(path)
    if m is None or stopped_out_of_memory(m):
        return None
    need = ("psnr", "iterations", "num_gaussians", "stage_times_s") + (("cycles",) if (method or m.get("method")) == "full" else ())
    return m if all(k in m for k in need) else None


RECORD_KEYS = ("method", "scene", "train_views", "test_views", "resolution", "iterations", "psnr", "ssim", "lpips",
               "masked", "num_gaussians", "train_time_s", "render_fps", "peak_cuda_allocated_mb", "peak_rss_mb",
               "device", "seed", "final_loss", "stopped_early", "recoveries", "curve", "compact", "stage_times_s")


def slim_metrics(m: dict) -> dict:
    """What the results keep of a run's metrics.json: the figures, and its stage times with the full
    method's per-cycle pseudo-view and densification times summed in."""
    out = {k: m[k] for k in RECORD_KEYS if k in m}
    stages = dict(out.get("stage_times_s") or {})
    for key in ("pseudo_views_s", "densify_s"):
        times = [c[key] for c in m.get("cycles") or [] if isinstance(c.get(key), (int, float))]
        if times:
            stages[key] = round(sum(times), 2)
    out["stage_times_s"] = stages
    return out


def _append(path: Path, row: dict) -> None:
    with open(path, "a") as f:
        f.write(json.dumps(row) + "\n")


def read_attempts(path: Path, batch: str | None = None) -> list[dict]:
    """The attempts of a run (its ``.attempts.jsonl``; of batch ``batch`` only, when given): one dict per
    attempt, ``end`` missing for one whose process or worker died before it could write it."""
    attempts: list[dict] = []
    try:
        lines = Path(path).read_text().splitlines()
    except OSError:
        return attempts
    for line in lines:
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if "start" in row:
            attempts.append(row)
        elif attempts and row.get("attempt") == attempts[-1]["attempt"]:
            attempts[-1].update(row)
    return [a for a in attempts if batch is None or a.get("batch") == batch]


def describe_end(a: dict) -> str:
    """One attempt's end in words."""
    if "returncode" not in a:
        return "its worker died (no end recorded)"
    rc = a["returncode"]
    if rc < 0:
        try:
            return f"killed by {signal.Signals(-rc).name}"
        except ValueError:
            return f"killed by signal {-rc}"
    return f"out of memory (exit code {rc})" if a.get("oom") else f"exit code {rc}"


def _last_error(text: str) -> str | None:
    lines = [ln for ln in text.splitlines() if ln.startswith("error: ")]
    return lines[-1] if lines else None


def _prepare_run_process() -> None:
    """In the run's process before it starts (Linux): SIGKILL when its parent, the Ray worker, dies, so that a
    killed worker leaves no run behind holding the folder's lock; and SIGINT as in a terminal (a Ray worker
    blocks or ignores it, and a child inherits both), so that Ctrl-C of the batch makes the run checkpoint."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def finished_record(name: str, out: Path, metrics: dict, attempts: list[dict]) -> dict:
    return {"name": name, "out": str(out), "status": "finished", "reused": not attempts, "attempts": attempts,
            "wall_s": round(sum(a.get("wall_s", 0) for a in attempts), 2) if attempts else None,
            "metrics": slim_metrics(metrics)}


def _wait(proc: subprocess.Popen, deadline: float | None, grace: float) -> tuple[int, bool]:
    """The exit code of ``proc``, and whether the deadline cut it: at ``deadline`` (epoch seconds) it gets SIGTERM
    (the run checkpoints and stops), and SIGKILL when it is still there ``grace`` seconds later."""
    try:
        return proc.wait(timeout=None if deadline is None else max(0.0, deadline - time.time())), False
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout=grace), True
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait(), True


def execute_run(spec: dict, out: str, logs: str, batch: str, overwrite: bool = False, deadline: float | None = None,
                grace: float = GRACE_S) -> dict:
    """Runs ``spec`` (a ``RunSpec`` as a dict) into ``out`` -> its record; ``batch`` names this batch in the
    attempts file. A run with complete metrics is skipped (unless ``overwrite`` and this batch has not run it
    yet); one with a checkpoint (an earlier attempt, an earlier batch) is resumed. Raises ``RunDied`` when the
    run's process dies, so that Ray retries it; a clean error (exit code 2) is a record with status
    ``failed``, not an exception. ``deadline`` (epoch seconds): a run not started by then is not started (status
    ``not_started``), one still going then is stopped with SIGTERM (``_wait``; status ``stopped``): the same batch
    again resumes both."""
    out, logs = Path(out), Path(logs)
    logs.mkdir(parents=True, exist_ok=True)
    log, attempts_path = logs / f"{spec['name']}.log", logs / f"{spec['name']}.attempts.jsonl"
    earlier = read_attempts(attempts_path, batch)
    fresh = overwrite and not earlier  # --overwrite: this batch's first attempt starts the run over
    done = None if fresh else metrics_complete(out, spec["method"])
    if done is not None:
        return finished_record(spec["name"], out, done, earlier)
    if deadline is not None and time.time() >= deadline:
        return {"name": spec["name"], "out": str(out), "status": "not_started", "attempts": earlier,
                "wall_s": round(sum(a.get("wall_s", 0) for a in earlier), 2),
                "error": "not started: the batch's deadline had passed (the same batch again runs it)"}
    resume = not fresh and (checkpoint_file(out) is not None or (out / "config.yaml").is_file())
    import warpgs

    cmd = [sys.executable, "-m", "warpgs.pipelines.sparse"]
    cmd += ["--resume", str(out), "--no-progress"] if resume else [*spec["argv"], "--out", str(out)]
    cmd += ["--overwrite"] if fresh else []
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": str(max(1, int(spec.get("num_cpus") or 1))),
           "PYTHONPATH": os.pathsep.join(p for p in (str(Path(warpgs.__file__).resolve().parents[1]),
                                                     os.environ.get("PYTHONPATH")) if p)}
    number, host = len(earlier) + 1, socket.gethostname()
    _append(attempts_path, {"batch": batch, "attempt": number, "start": time.time(), "host": host, "worker_pid": os.getpid(),
                            "resume": resume, "cuda_visible_devices": os.environ.get("CUDA_VISIBLE_DEVICES")})
    t0 = time.time()
    with open(log, "a") as f:
        f.write(f"==== batch {batch}, attempt {number} on {host}: {' '.join(cmd)}\n")
        f.flush()
        offset = f.tell()
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env,
                                preexec_fn=_prepare_run_process if sys.platform.startswith("linux") else None)
        _append(attempts_path, {"attempt": number, "pid": proc.pid})
        rc, cut = _wait(proc, deadline, grace)
    with open(log, errors="replace") as f:
        f.seek(offset)
        text = f.read()
    resumed = re.search(r"resumed \S+ at step (\d+)", text)
    tail = text[-3000:]  # the end of the attempt's log: where the error that ended it is
    oom = rc not in (0, 2) and (OUT_OF_MEMORY.search(tail) is not None or "MemoryError" in tail
                                or stopped_out_of_memory(read_metrics(out)))
    _append(attempts_path, {"attempt": number, "end": time.time(), "wall_s": round(time.time() - t0, 2),
                            "returncode": rc, "oom": oom, "from_step": int(resumed.group(1)) if resumed else None,
                            "deadline": cut})
    attempts = read_attempts(attempts_path, batch)
    metrics = metrics_complete(out, spec["method"])
    if metrics is not None and rc in (0, 1):  # 1: stopped early (diverged) with the last good state's metrics
        return finished_record(spec["name"], out, metrics, attempts)
    if cut:
        return {"name": spec["name"], "out": str(out), "status": "stopped", "returncode": rc, "attempts": attempts,
                "wall_s": round(sum(a.get("wall_s", 0) for a in attempts), 2),
                "error": f"stopped at the batch's deadline (SIGTERM; exit code {rc}): the same batch again resumes it"}
    if (rc < 0 and rc not in STOPPED) or oom:
        raise RunDied(f"{spec['name']}: attempt {number} {describe_end(attempts[-1])}")
    tail = text[-1500:]
    return {"name": spec["name"], "out": str(out), "status": "stopped" if rc in STOPPED else "failed",
            "returncode": rc, "attempts": attempts, "wall_s": round(sum(a.get("wall_s", 0) for a in attempts), 2),
            "error": _last_error(text) or (tail.strip().splitlines() or ["no output"])[-1], "log_tail": tail}


# ----------------------------------------------------------------------------------------------
# the batch on Ray


def import_ray():
    """Ray, or ``BatchError`` saying what to install."""
    try:
        import ray
    except ImportError:
        raise BatchError(f"the batch runner needs Ray, which is not installed: {INSTALL_HINT}") from None
    return ray


def start_ray(address: str | None = None, num_cpus: int | None = None, num_gpus: int | None = None):
    """``ray.init``: a local Ray (``num_cpus`` / ``num_gpus`` of this machine, default all) or the cluster at
    ``address``; quiet (no dashboard, the runs' output goes to their own logs)."""
    import logging

    ray = import_ray()
    if not ray.is_initialized():
        kwargs = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
        if address:
            kwargs["address"] = address
        else:
            kwargs.update(num_cpus=num_cpus, num_gpus=num_gpus)
        ray.init(**kwargs)
    return ray


def _fmt_time(s: float | None) -> str:
    if s is None or not math.isfinite(s):
        return "?"
    s = int(round(s))
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


class Progress:
    """The batch's progress line: done / running / failed / waiting, elapsed, ETA (from the runs this batch
    finished: elapsed / finished x left). Printed when a count changes, and every ``every`` seconds."""

    def __init__(self, total: int, log=print, every: float = 60.0):
        self.total, self.log, self.every = total, log, every
        self.t0 = time.time()
        self.done = self.reused = self.failed = self.cut = 0
        self.last: tuple | None = None
        self.last_time = 0.0

    def record(self, rec: dict) -> None:
        if rec.get("status") == "finished":
            self.done += 1
            self.reused += bool(rec.get("reused"))
        elif rec.get("status") in ("stopped", "not_started"):
            self.cut += 1
        else:
            self.failed += 1

    def line(self, running: int) -> str:
        elapsed = time.time() - self.t0
        left = self.total - self.done - self.failed - self.cut
        ran = self.done - self.reused + self.failed
        eta = elapsed / ran * left if ran and left else (0.0 if not left else None)
        reused = f" ({self.reused} reused)" if self.reused else ""
        cut = f", {self.cut} stopped or not started at the deadline" if self.cut else ""
        return (f"batch: {self.done}/{self.total} done{reused}, {running} running, {self.failed} failed{cut}, "
                f"{max(0, left - running)} waiting; {_fmt_time(elapsed)} elapsed, ETA {_fmt_time(eta)}")

    def show(self, running: int, force: bool = False) -> None:
        state = (self.done, self.failed, running)
        if force or state != self.last or time.time() - self.last_time >= self.every:
            self.log(self.line(running))
            self.last, self.last_time = state, time.time()


def _running(names: set[str], logs: Path, batch: str) -> int:
    """Runs with an attempt under way (started, not ended), from their attempt files."""
    n = 0
    for name in names:
        a = read_attempts(logs / f"{name}.attempts.jsonl", batch)
        n += bool(a) and "end" not in a[-1]
    return n


def record_settings(specs: list[RunSpec], logs: Path, overwrite: bool) -> None:
    """Keeps each run's arguments in ``logs/<name>.argv.json``; ``BatchError`` when one holds other arguments
    (an earlier batch into this folder with other settings: its runs would be reused or resumed as they were),
    unless ``overwrite``."""
    for s in specs:
        p = logs / f"{s.name}.argv.json"
        try:
            before = json.loads(p.read_text())
        except (OSError, ValueError):
            before = None
        if before is not None and before != s.argv and not overwrite:
            changed = sorted(set(map(str, before)) ^ set(map(str, s.argv)))
            raise BatchError(f"{logs.parent}: run {s.name} was made with other settings ({' '.join(changed[:6])} "
                             "differ); choose another --out, or --overwrite to run everything again")
    for s in specs:
        (logs / f"{s.name}.argv.json").write_text(json.dumps(s.argv))


def retries_in_words(attempts: list[dict]) -> list[str]:
    """Each attempt that was followed by another: how it ended, and where the next one resumed."""
    return [f"attempt {a['attempt']}: {describe_end(a)}; attempt {b['attempt']} "
            + (f"resumed at step {b['from_step']}" if b.get("from_step") is not None else "started over")
            for a, b in zip(attempts, attempts[1:])]


def run_on_ray(specs: list[RunSpec], work: Path, logs: Path, *, max_retries: int = 2, overwrite: bool = False,
               log=print, progress_every: float = 60.0, ray_init: dict | None = None, deadline: float | None = None,
               grace: float = GRACE_S) -> list[dict]:
    """Runs ``specs`` as Ray tasks into ``work/<name>``, logs in ``logs``; returns their records in the order of
    ``specs``, each with its ``spec`` and ``retries``. A run that finished already is not submitted (unless
    ``overwrite``). Ray is started (``start_ray(**ray_init)``, shut down at the end) only where it is not
    running yet and there is a run to submit. ``deadline``, ``grace``: ``execute_run``'s."""
    import secrets

    ray = import_ray()
    work, logs = Path(work).resolve(), Path(logs).resolve()
    logs.mkdir(parents=True, exist_ok=True)
    record_settings(specs, logs, overwrite)
    batch = time.strftime("%Y%m%d-%H%M%S-") + secrets.token_hex(3)
    progress = Progress(len(specs), log, progress_every)
    records: dict[str, dict] = {}
    todo = []
    for s in specs:
        done = None if overwrite else metrics_complete(work / s.name, s.method)
        if done is not None:  # no task for a finished run
            records[s.name] = finished_record(s.name, work / s.name, done, [])
            progress.record(records[s.name])
        else:
            todo.append(s)
    started = bool(todo) and not ray.is_initialized()
    if started:
        start_ray(**(ray_init or {}))
        progress.t0 = time.time()  # the ETA counts from the first task
    try:
        _run_tasks(ray, todo, work, logs, batch, records, progress, max_retries, overwrite, deadline, grace)
    finally:
        if started:
            ray.shutdown()
    progress.show(0, force=True)
    return [{**records[s.name], "spec": asdict(s), "retries": retries_in_words(records[s.name].get("attempts") or [])}
            for s in specs]


def _run_tasks(ray, todo: list[RunSpec], work: Path, logs: Path, batch: str, records: dict, progress: Progress,
               max_retries: int, overwrite: bool, deadline: float | None = None, grace: float = GRACE_S) -> None:
    """Submits one task per run of ``todo`` and collects their records into ``records`` as they end."""
    task = ray.remote(execute_run)
    refs = {}
    for s in todo:
        opts = dict(num_cpus=s.num_cpus, max_retries=max_retries, retry_exceptions=[RunDied], name=s.name)
        if s.num_gpus:
            opts["num_gpus"] = s.num_gpus
        refs[task.options(**opts).remote(asdict(s), str(work / s.name), str(logs), batch, overwrite, deadline,
                                         grace)] = s
    pending = set(refs)
    try:
        while pending:
            progress.show(_running({refs[r].name for r in pending}, logs, batch))
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=2.0)
            for ref in ready:
                pending.discard(ref)
                s = refs[ref]
                try:
                    rec = ray.get(ref)
                except Exception as e:  # noqa: BLE001 - retries spent: RunDied, or the worker died each time
                    attempts = read_attempts(logs / f"{s.name}.attempts.jsonl", batch)
                    last = describe_end(attempts[-1]) if attempts else type(e).__name__
                    rec = {"name": s.name, "out": str(work / s.name), "status": "failed", "attempts": attempts,
                           "wall_s": round(sum(a.get("wall_s", 0) for a in attempts), 2),
                           "error": f"died in each of {len(attempts)} attempts (the last: {last}; --max-retries {max_retries})"}
                records[s.name] = rec
                progress.record(rec)
    except KeyboardInterrupt:
        stop_runs([refs[r].name for r in pending], logs, batch)
        raise


def stop_runs(names: list[str], logs: Path, batch: str, timeout: float = 120.0) -> None:
    """Ctrl-C: SIGINT to every run of ``names`` under way on this host (each writes a checkpoint and stops, as
    after Ctrl-C in a terminal), then waits for them; a run on another node is left to ``ray.shutdown``
    (which kills it: it continues from its last periodic checkpoint)."""
    here, stopping = socket.gethostname(), []
    for name in names:
        a = read_attempts(logs / f"{name}.attempts.jsonl", batch)
        if a and "end" not in a[-1] and a[-1].get("host") == here and a[-1].get("pid"):
            try:
                os.kill(a[-1]["pid"], signal.SIGINT)
                stopping.append(a[-1]["pid"])
            except OSError:
                pass
    t0 = time.time()
    while stopping and time.time() - t0 < timeout:
        stopping = [p for p in stopping if Path(f"/proc/{p}").exists() and
                    Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[-1].split()[0] != "Z"]
        time.sleep(0.2)


# ----------------------------------------------------------------------------------------------
# command line


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m warpgs.pipelines.batch", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sweep", default=None, metavar="FILE", help="a sweep file (YAML, bench/sweeps/): its groups of runs "
                    "instead of --data ... --iterations, its batch settings where the command line gives none")
    g = ap.add_argument_group("runs (every combination of the lists)")
    g.add_argument("--data", default="synthetic",
                   help="comma-separated: dataset names, scene folders, or scenes of --dataset (default: synthetic)")
    g.add_argument("--dataset", default="dl3dv", help="the dataset a bare scene name belongs to (default: dl3dv)")
    g.add_argument("--data-root", default=None, help="folder holding the datasets (as for warpgs.pipelines.sparse)")
    g.add_argument("--views", default=None, help="comma-separated training view counts (default: the dataset's)")
    g.add_argument("--method", default="compare", help="baseline, full, corgs or compare (baseline and full; default)")
    g.add_argument("--seeds", default="0", help="comma-separated seeds (default: 0)")
    g.add_argument("--iterations", type=int, default=None, help="training steps of every run")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="config override of every run (repeatable)")
    g.add_argument("--config", action="append", default=[], metavar="FILE", help="extra YAML config of every run (repeatable)")
    g.add_argument("--device", default=None, help="cpu or cuda (default: cuda when the Ray cluster has GPUs)")
    g.add_argument("--variant", default=None, help="a suffix of every run's name: <scene>_<views>v_<method>_s<seed>_VARIANT "
                   "(the runs of a --set variant, beside the default's; bench/report/compare.py)")
    g = ap.add_argument_group("scheduling")
    g.add_argument("--address", default=None, help="Ray cluster to join (auto, HOST:PORT, ray://...); default: a local Ray")
    g.add_argument("--cpus", type=int, default=None, help="local Ray: CPUs it may use (default: all)")
    g.add_argument("--gpus", type=int, default=None, help="local Ray: GPUs it may use (default: all)")
    g.add_argument("--cpus-per-run", type=float, default=1.0, help="CPUs each run asks for (default: 1)")
    g.add_argument("--gpus-per-run", type=float, default=None, help="GPU share each run asks for (default: gpu_share)")
    g.add_argument("--runs-per-gpu", type=int, default=None, help="GPU slots: N runs at a time on each visible GPU "
                   "(each asks for 1/N of one; overrides --gpus-per-run)")
    g.add_argument("--deadline", default=None, help="wall-clock end of this call: a duration (600, 45m, 2h), a UTC time "
                   "(07:30) or an ISO time; then no run starts, and the runs still going get SIGTERM (they checkpoint "
                   "and stop; killed --grace s later). The same command again skips the finished runs and resumes the rest")
    g.add_argument("--grace", type=float, default=GRACE_S, help=f"seconds between SIGTERM and SIGKILL at the deadline "
                   f"(default {GRACE_S:g})")
    g.add_argument("--max-retries", type=int, default=2, help="retries of a run whose process or worker died (default: 2)")
    g = ap.add_argument_group("outputs")
    g.add_argument("--out", default="outputs/batch", help="batch folder: runs/, logs/, results (default: outputs/batch)")
    g.add_argument("--overwrite", action="store_true", help="run every run again from the start, finished or not")
    g.add_argument("--list", action="store_true", help="print the runs and their resources; run nothing")
    g.add_argument("--only", default=None, metavar="GLOBS", help="only the runs whose names match one of these "
                   "comma-separated shell patterns (e.g. '*_compact-virtual,fern_3v_full_s2*'): part of a sweep")
    g.add_argument("--progress-every", type=float, default=60.0, help="seconds between progress lines when nothing changes")
    return ap


def check_args(a) -> None:
    if a.gpus_per_run is not None and not 0 < a.gpus_per_run <= 1:
        raise BatchError(f"--gpus-per-run {a.gpus_per_run}: must be in (0, 1]")
    if a.cpus_per_run <= 0:
        raise BatchError(f"--cpus-per-run {a.cpus_per_run}: must be > 0")
    if a.max_retries < 0:
        raise BatchError(f"--max-retries {a.max_retries}: must be >= 0")
    if a.runs_per_gpu is not None and a.runs_per_gpu < 1:
        raise BatchError(f"--runs-per-gpu {a.runs_per_gpu}: must be >= 1")
    if a.grace < 0:
        raise BatchError(f"--grace {a.grace}: must be >= 0")
    if a.variant is not None and not re.fullmatch(r"[A-Za-z0-9.-]+", a.variant):
        raise BatchError(f"--variant {a.variant!r}: letters, digits, '.' and '-' only (it ends run names)")
    if a.device is not None and a.device != "cpu" and not a.device.startswith("cuda"):
        raise BatchError(f"--device {a.device!r}: cpu or cuda (Ray gives each run its GPU)")
    if a.device is not None and a.device.startswith("cuda:"):
        raise BatchError(f"--device {a.device}: give cuda; Ray picks each run's GPU (CUDA_VISIBLE_DEVICES)")


def select(specs: list[RunSpec], only: str | None) -> list[RunSpec]:
    """The runs of ``specs`` whose names match one of ``only``'s comma-separated shell patterns (``--only``; None:
    all); ``BatchError`` when a pattern matches none of them (a typo would run nothing, silently)."""
    if only is None:
        return specs
    import fnmatch

    globs = [g.strip() for g in only.split(",") if g.strip()]
    if not globs:
        raise BatchError("--only: give one or more shell patterns of run names, comma-separated")
    for g in globs:
        if not any(fnmatch.fnmatchcase(s.name, g) for s in specs):
            raise BatchError(f"--only {g!r}: matches no run of this batch (--list without --only names them)")
    return [s for s in specs if any(fnmatch.fnmatchcase(s.name, g) for g in globs)]


def print_plan(specs: list[RunSpec], log=print) -> None:
    for s in specs:
        size = "x".join(map(str, s.image_size)) if s.image_size else "size unknown"
        gpu = f", {s.num_gpus:.3g} GPU" if s.num_gpus else ""
        log(f"  {s.name:<40} {size:>10}  {s.num_cpus:g} CPU{gpu}")


def main(argv=None) -> int:
    from warpgs.pipelines.batch_report import write_results

    parser = build_parser()
    a = parser.parse_args(argv)
    ray = started = None
    try:
        deadline = parse_deadline(a.deadline)
        groups = None
        if a.sweep is not None:
            settings, groups = load_sweep(a.sweep)
            settings.setdefault("out", str(Path("outputs") / "sweeps" / Path(a.sweep).stem))
            for key, value in settings.items():  # the command line wins where it gives a value
                if getattr(a, key) == parser.get_default(key):
                    setattr(a, key, value)
        out = Path(a.out).resolve()
        check_args(a)
        if not a.list:
            import_ray()  # before any work: what to install, when it is missing
        # every config checked before Ray starts; GPU shares unless --device cpu
        specs = select(plan_sweep(a, groups) if groups is not None else plan(a), a.only)
        if a.list:
            print(f"{len(specs)} runs into {out / 'runs'}:")
            print_plan(specs)
            return 0
        ray = import_ray()
        started = not ray.is_initialized()
        start_ray(a.address, a.cpus, a.gpus)
        gpus = ray.cluster_resources().get("GPU", 0)
        if a.device == "cuda" and not gpus:
            raise BatchError("--device cuda: the Ray cluster has no GPU" + ("" if a.address else " on this machine"))
        device = a.device or ("cuda" if gpus else "cpu")
        for s in specs:
            s.argv += [] if a.device else ["--device", device]
            s.num_gpus = s.num_gpus if device == "cuda" else 0.0
    except BatchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        res = ray.cluster_resources()
        info = {"command": "python -m warpgs.pipelines.batch " + " ".join(argv if argv is not None else sys.argv[1:]),
                "date": time.strftime("%Y-%m-%d %H:%M"), "device": device, "address": a.address or "local",
                "cluster": {k: res[k] for k in ("CPU", "GPU") if k in res}, "nodes": len(ray.nodes()),
                "max_retries": a.max_retries, "runs": len(specs), "sweep": a.sweep,
                "deadline": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(deadline)) if deadline else None}
        print(f"batch: {len(specs)} runs on {info['nodes']} node(s) "
              f"({', '.join(f'{v:g} {k}' for k, v in info['cluster'].items())}); runs in {out / 'runs'}, "
              f"logs in {out / 'logs'}", file=sys.stderr)
        t0 = time.time()
        try:
            records = run_on_ray(specs, out / "runs", out / "logs", max_retries=a.max_retries, overwrite=a.overwrite,
                                 log=lambda msg: print(msg, file=sys.stderr), progress_every=a.progress_every,
                                 deadline=deadline, grace=a.grace)
        except BatchError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("\nbatch: stopped; the unfinished runs keep their checkpoints: run the same command again to "
                  "continue", file=sys.stderr)
            return 130
        info["wall_s"] = round(time.time() - t0, 2)
        paths = write_results(records, info, out)
        print(f"batch: wrote {', '.join(str(p) for p in paths)}", file=sys.stderr)
        cut = sum(r["status"] in ("stopped", "not_started") for r in records)
        if cut:
            print(f"batch: {cut} run(s) stopped or not started at the deadline: run the same command again to go on "
                  "(finished runs are skipped, stopped ones resumed)", file=sys.stderr)
        return 0 if all(r["status"] == "finished" for r in records) else 1
    finally:
        if started and ray.is_initialized():
            ray.shutdown()


if __name__ == "__main__":
    sys.exit(main())
