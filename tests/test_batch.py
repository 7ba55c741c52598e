"""The batch runner on Ray (issue 17, ``warpgs.pipelines.batch``): a batch of 4 tiny runs on a local Ray with
two CPUs, one run's process killed with SIGKILL and another's Ray worker, a missing scene among them; then the
same batch again. Planning, GPU shares and the missing-Ray message need no Ray.

The runs are tiny nerfstudio captures of tiny_scene.py (48x48, 200 Gaussians, 100 steps, a checkpoint every 10).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_reliability import _wait_for  # polls a condition while a process runs
from tiny_scene import write_nerfstudio
from warpgs.pipelines import batch
from warpgs.runfolder import LOCK, open_run_folder, read_lock

REPO = Path(__file__).resolve().parents[1]
TINY = ["--set", "model.init=box", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]", "--set", "model.init_num=200",
        "--set", "eval.lpips_weights=/nonexistent/alexnet.pth", "--set", "eval.fps_repeats=1",
        "--set", "eval.save_images=false", "--set", "train.checkpoint_every=10", "--iterations", "100", "--device", "cpu"]
TIMING = ("train_time_s", "render_fps", "peak_rss_mb", "stage_times_s", "curve", "wall_s", "outputs_s")


def test_gpu_shares_and_the_plan_need_no_ray(tmp_path, capsys):
    assert batch.gpu_share(768, 512, 500_000) == 1 / 4  # the real captures, no Gaussian budget
    assert batch.gpu_share(128, 96, 12_000) == 1 / 8  # the synthetic scene: the smallest share
    assert batch.gpu_share(960, 540, 500_000) == 1 / 3  # DL3DV's 960P images_4
    assert batch.gpu_share(1920, 1080, 1_000_000) == 1.0
    data = write_nerfstudio(tmp_path / "scene")
    args = ["--data", f"{data},{tmp_path / 'missing'},synthetic", "--views", "2,3", "--method", "compare", "--seeds", "0,1",
            "--out", str(tmp_path / "b"), "--list"]
    assert batch.main(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"24 runs into {tmp_path / 'b' / 'runs'}:"
    rows = {ln.split()[0]: ln for ln in lines[1:]}
    assert "48x48" in rows["scene_2v_baseline_s0"] and "0.125 GPU" in rows["scene_3v_full_s1"]
    assert "size unknown" in rows["missing_3v_baseline_s0"] and "128x96" in rows["synthetic_2v_full_s1"]
    assert batch.main(args + ["--device", "cpu"]) == 0 and "GPU" not in capsys.readouterr().out
    # every method of the main command; CoR-GS's pair is one run
    assert batch.main(["--data", "synthetic", "--views", "2", "--method", "corgs", "--out", str(tmp_path / "c"),
                       "--list"]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[0] == "synthetic_2v_corgs_s0"
    assert batch.main(["--data", "synthetic", "--method", "nerf", "--list"]) == 2
    assert "available methods are baseline, full, corgs, compare" in capsys.readouterr().err
    # a bad setting of every run is one line before anything starts
    assert batch.main(["--data", str(data), "--set", "train.iterations=0", "--list"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "train.iterations = 0" in err[0]
    assert batch.main(["--gpus-per-run", "1.5", "--list"]) == 2
    assert "--gpus-per-run 1.5: must be in (0, 1]" in capsys.readouterr().err


def test_without_ray_it_says_what_to_install(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    assert batch.main(["--data", "synthetic"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: the batch runner needs Ray, which is not installed: pip install 'warpgs[ray]'"]


def test_a_zombie_holds_no_lock(tmp_path):
    """A run killed with its batch worker is reparented, and where nothing reaps it, it stays a zombie with its
    pid: its lock is stale all the same."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])  # never waited for: a zombie once it exits
    deadline = time.monotonic() + 30
    while Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[-1].split()[0] != "Z":
        assert time.monotonic() < deadline
        time.sleep(0.05)
    out = tmp_path / "run"
    out.mkdir()
    (out / LOCK).write_text(json.dumps({"pid": child.pid, "host": os.uname().nodename, "token": "z"}))
    notes = []
    open_run_folder(out, log=notes.append).release()
    assert len(notes) == 1 and f"pid {child.pid}" in notes[0]
    child.wait()


def test_batch_with_killed_runs_and_a_bad_scene(tmp_path):
    pytest.importorskip("ray", reason="the batch runner needs Ray: pip install 'warpgs[ray]'")
    data = write_nerfstudio(tmp_path / "ring_a")  # two tiny captures x seeds 0 and 1, and a scene that is not there
    other = write_nerfstudio(tmp_path / "ring_b", n_frames=12)
    out = tmp_path / "batch"
    runs, logs = out / "runs", out / "logs"
    argv = ["--data", f"{data},{other},{tmp_path / 'no_such_scene'}", "--views", "3", "--method", "baseline", "--seeds", "0,1",
            *TINY, "--out", str(out), "--cpus", "2", "--max-retries", "2", "--progress-every", "5"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]), "OMP_NUM_THREADS": "1"}
    t0 = time.monotonic()
    driver = subprocess.Popen([sys.executable, "-m", "warpgs.pipelines.batch", *argv], cwd=REPO, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # the same run as the one whose process is killed, uninterrupted (the batch gives its runs OMP_NUM_THREADS=1)
    ref = subprocess.Popen([sys.executable, "-m", "warpgs.pipelines.sparse", "--data", str(data), "--views", "3",
                            "--method", "baseline", "--seed", "0", *TINY, "--no-progress", "--out", str(tmp_path / "ref")],
                           cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    killed = "ring_a_3v_baseline_s0"
    others = ("ring_a_3v_baseline_s1", "ring_b_3v_baseline_s0", "ring_b_3v_baseline_s1")

    def under_way():  # another run with a checkpoint, not finished yet (the first one may finish while we wait)
        return next((n for n in others if (runs / n / "checkpoint.pt").exists() and (logs / f"{n}.attempts.jsonl").exists()
                     and not (runs / n / "metrics.json").exists()), None)
    try:
        # a checkpoint written, the run still going: SIGKILL to the run's process (the pid in its folder's lock) ...
        _wait_for(lambda: (runs / killed / "checkpoint.pt").exists() and (runs / killed / LOCK).exists(), driver)
        pid = read_lock(runs / killed)["pid"]
        assert not (runs / killed / "metrics.json").exists()
        os.kill(pid, signal.SIGKILL)
        # ... and to the Ray worker of another run under way (its run dies with it)
        seen = []
        _wait_for(lambda: seen.append(under_way()) or seen[-1] is not None, driver)
        worker = seen[-1]
        worker_pid = batch.read_attempts(logs / f"{worker}.attempts.jsonl")[-1]["worker_pid"]
        os.kill(worker_pid, signal.SIGKILL)
        stdout, stderr = driver.communicate(timeout=240)
    finally:
        for p in (driver, ref):
            if p.poll() is None:
                p.kill()
    assert ref.wait(timeout=120) == 0, ref.stderr.read()
    took = time.monotonic() - t0
    assert driver.returncode == 1, stderr  # not every run finished: the bad scene's
    assert "Traceback" not in stderr, stderr
    progress = [ln for ln in stderr.splitlines() if ln.startswith("batch: ") and " done" in ln]
    assert progress[-1].startswith("batch: 4/6 done, 0 running, 2 failed, 0 waiting;"), progress

    res = json.loads((out / "results.json").read_text())
    by = {r["name"]: r for r in res["runs"]}
    good = [n for n in by if n.startswith("ring_")]
    bad = [n for n in by if n.startswith("no_such_scene_")]
    assert len(good) == 4 and len(bad) == 2
    for n in good:
        assert by[n]["status"] == "finished" and by[n]["metrics"]["iterations"] == 100, by[n]
    for n in bad:  # reported with the run's own error line, and not retried
        assert by[n]["status"] == "failed" and len(by[n]["attempts"]) == 1, by[n]
        assert by[n]["error"].startswith("error: ") and "no_such_scene" in by[n]["error"]

    # the killed run: retried once, with --resume from its checkpoint, to the same metrics as the uninterrupted run
    a = by[killed]["attempts"]
    assert len(a) == 2 and a[0]["returncode"] == -signal.SIGKILL and a[1]["resume"] and a[1]["from_step"] >= 10, a
    assert f"--resume {runs / killed}" in (logs / f"{killed}.log").read_text()
    assert by[killed]["retries"] == [f"attempt 1: killed by SIGKILL; attempt 2 resumed at step {a[1]['from_step']}"]
    got, want = (json.loads((d / "metrics.json").read_text()) for d in (runs / killed, tmp_path / "ref"))
    assert {k: v for k, v in got.items() if k not in TIMING} == {k: v for k, v in want.items() if k not in TIMING}
    assert [c["psnr"] for c in got["curve"]] == [c["psnr"] for c in want["curve"]]
    # the run whose worker died: its attempt has no end; the retry resumed it
    w = by[worker]["attempts"]
    assert len(w) == 2 and "end" not in w[0] and w[1]["resume"] and w[1]["from_step"] >= 10, w
    assert by[worker]["retries"][0].startswith("attempt 1: its worker died")

    # the table over seeds, the per-run stage times, the charts
    groups = {(g["scene"], g["views"]): g for g in res["groups"]}
    g = groups[("ring_b", "3")]
    psnrs = [by[f"ring_b_3v_baseline_s{s}"]["metrics"]["psnr"] for s in (0, 1)]
    assert g["finished"] == 2 and g["psnr"]["min"] == min(psnrs) and g["psnr"]["max"] == max(psnrs)
    assert groups[("no_such_scene", "3")]["finished"] == 0
    md = (out / "results.md").read_text()
    assert "| ring_a | 3 | baseline | 2/2 |" in md and "## Runs that did not finish" in md and "## Retries" in md
    assert by[killed]["metrics"]["stage_times_s"]["train_s"] > 0
    for f in ("psnr_vs_time.png", "psnr_vs_gaussians.png"):
        assert (out / f).stat().st_size > 1000

    # the same batch again: the finished runs are not run (no Ray task, no attempt)
    specs = [s for s in batch.plan(batch.build_parser().parse_args(argv)) if s.name in good]
    assert sorted(s.name for s in specs) == sorted(good)
    again = batch.run_on_ray(specs, runs, logs, log=lambda msg: None)
    assert all(r["status"] == "finished" and r["reused"] for r in again)
    assert [r["metrics"]["psnr"] for r in again] == [by[s.name]["metrics"]["psnr"] for s in specs]
    assert len(batch.read_attempts(logs / f"{killed}.attempts.jsonl")) == 2
    # ... but not a batch of other settings into the same folder (its runs would be reused as they are)
    specs[0].argv[specs[0].argv.index("--iterations") + 1] = "200"
    with pytest.raises(batch.BatchError, match=f"run {specs[0].name} was made with other settings .*--overwrite"):
        batch.run_on_ray(specs, runs, logs, log=lambda msg: None)
    print(f"batch test: {took:.0f} s")


def test_a_run_stopped_on_out_of_memory_is_resumed_not_kept(tmp_path, capsys, monkeypatch):
    """A run that stopped itself on a GPU out of memory (runs sharing the GPU: 4 of 48 capture runs once)
    writes the last good state's metrics with ``stopped_early: out_of_memory``. The batch does not take that for
    a finished run: it resumes it, and the resumed run finishes all its steps. A diverged run's metrics stay final."""
    import torch

    from warpgs.pipelines.sparse import main
    from warpgs.train import Trainer

    real = Trainer.compute_loss

    def oom_from_step_12(self, out, cam):
        if self.step >= 12:
            raise torch.OutOfMemoryError("CUDA out of memory. Tried to allocate 28.00 MiB.")
        return real(self, out, cam)

    data = write_nerfstudio(tmp_path / "scene")
    out, logs = tmp_path / "runs" / "r", tmp_path / "logs"
    argv = ["--data", str(data), "--views", "3", "--method", "baseline", *TINY[:-4], "--iterations", "30",
            "--device", "cpu"]
    with monkeypatch.context() as mp:
        mp.setattr(Trainer, "compute_loss", oom_from_step_12)
        assert main([*argv, "--no-progress", "--out", str(out)]) == 1
    capsys.readouterr()
    stopped = json.loads((out / "metrics.json").read_text())
    assert stopped["stopped_early"]["reason"] == "out_of_memory" and stopped["iterations"] < 30
    assert batch.stopped_out_of_memory(stopped) and batch.metrics_complete(out, "baseline") is None
    diverged = {**stopped, "stopped_early": {"reason": "diverged", "step": 12, "cause": "loss"}}
    assert not batch.stopped_out_of_memory(diverged)

    rec = batch.execute_run({"name": "r", "method": "baseline", "argv": argv, "num_cpus": 1}, str(out), str(logs), "b1")
    assert rec["status"] == "finished" and not rec["reused"]
    assert [a["resume"] for a in rec["attempts"]] == [True]  # resumed in place, not started over elsewhere
    m = json.loads((out / "metrics.json").read_text())
    assert m["iterations"] == 30 and "stopped_early" not in m
    assert batch.metrics_complete(out, "baseline") == m
    # the batch again: now it is finished and reused as it is
    again = batch.execute_run({"name": "r", "method": "baseline", "argv": argv, "num_cpus": 1}, str(out), str(logs), "b2")
    assert again["status"] == "finished" and again["reused"]


SETUP_OOM = ("CUDA error: out of memory\nCUDA kernel errors might be asynchronously reported at some other API call, so "
             "the stacktrace below might be incorrect.\nSearch for `cudaErrorMemoryAllocation' in "
             "https://docs.nvidia.com/cuda/cuda-runtime-api/group__CUDART__TYPES.html for more information.")


def test_a_device_full_at_set_up_ends_as_out_of_memory_and_the_batch_retries_it(tmp_path, capsys, monkeypatch):
    """Runs sharing a GPU can leave none for a new run's set-up: CUDA, cuBLAS and Warp then raise a plain
    RuntimeError (SETUP_OOM: torch's words for a failed cudaMalloc), which the run once took for bad input (exit 2,
    a failed record, never retried: four fern runs of a sweep at 12 runs a GPU). It is out of memory: one line,
    exit 1, and the batch retries it. Other errors at set-up stay bad input (exit 2)."""
    from warpgs.engine.loop import Trainer
    from warpgs.pipelines.sparse import main

    data = write_nerfstudio(tmp_path / "scene")
    argv = ["--data", str(data), "--views", "3", "--method", "baseline", *TINY, "--device", "cpu"]
    cases = ((SETUP_OOM, 1), ("CUDA error: CUBLAS_STATUS_ALLOC_FAILED when calling `cublasCreate(handle)`", 1),
             ("expected a 4x4 pose", 2))
    for i, (message, code) in enumerate(cases):
        def refuse(self, *a, message=message, **k):
            raise RuntimeError(message)

        with monkeypatch.context() as mp:
            mp.setattr(Trainer, "__init__", refuse)
            assert main([*argv, "--no-progress", "--out", str(tmp_path / f"r{i}")]) == code
        err = capsys.readouterr().err
        (line,) = [ln for ln in err.splitlines() if ln.startswith("error: ")]
        assert "Traceback" not in err and message.splitlines()[0] in line
        assert ("ran out of memory while setting up the baseline run" in line) == (code == 1)
    # in a batch: the run's process (its Trainer refused in sitecustomize) ends as out of memory, and Ray retries it
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(
        "import warpgs.engine.loop\n"
        "def refuse(self, *a, **k):\n"
        f"    raise RuntimeError({SETUP_OOM!r})\n"
        "warpgs.engine.loop.Trainer.__init__ = refuse\n")
    monkeypatch.setenv("PYTHONPATH", str(hook))
    out, logs = tmp_path / "runs" / "r", tmp_path / "logs"
    with pytest.raises(batch.RunDied, match="out of memory"):
        batch.execute_run({"name": "r", "method": "baseline", "argv": argv, "num_cpus": 1}, str(out), str(logs), "b1")
    (attempt,) = batch.read_attempts(logs / "r.attempts.jsonl")
    assert attempt["oom"] and attempt["returncode"] == 1


# ----------------------------------------------------------------------------------------------
# sweep files, the deadline, GPU slots


def _sweep(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_sweep_file_plans_its_groups_and_variants(tmp_path, capsys):
    data = write_nerfstudio(tmp_path / "scene")
    sweep = _sweep(tmp_path / "s.yaml", f"""
out: {tmp_path / 'b'}
runs_per_gpu: 4
set: [eval.fps_repeats=1]
runs:
  - data: [{data}]
    views: [2, 3]
    method: compare
    seeds: [0, 1]
    iterations: 50
    variants:
      default: []
      pw02: [full.pseudo_weight=0.2]
  - data: synthetic
    method: baseline
    iterations: 30
""")
    parser = batch.build_parser()
    a = parser.parse_args(["--sweep", str(sweep), "--set", "eval.save_images=false"])
    settings, groups = batch.load_sweep(sweep)
    assert settings == {"out": str(tmp_path / "b"), "runs_per_gpu": 4}
    specs = batch.plan_sweep(a, groups)
    names = [s.name for s in specs]
    want = [f"scene_{v}v_{m}_s{s}{suffix}" for suffix in ("", "_pw02") for v in (2, 3) for m in ("baseline", "full")
            for s in (0, 1)] + ["synthetic_3v_baseline_s0"]
    assert names == want
    by = {s.name: s for s in specs}
    variant, default = by["scene_3v_full_s1_pw02"].argv, by["scene_3v_full_s1"].argv
    assert "full.pseudo_weight=0.2" in variant and "full.pseudo_weight=0.2" not in default
    for argv in (variant, default):  # the command line's settings, then the file's, then the variant's
        sets = [argv[i + 1] for i, x in enumerate(argv) if x == "--set"]
        assert sets[:2] == ["eval.save_images=false", "eval.fps_repeats=1"]
        assert argv[argv.index("--iterations") + 1] == "50"
    syn = by[want[-1]].argv
    assert syn[syn.index("--iterations") + 1] == "30" and syn[syn.index("--method") + 1] == "baseline"
    # --list through main: the file's batch settings apply (4 runs per GPU: a quarter of one each)
    assert batch.main(["--sweep", str(sweep), "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"17 runs into {tmp_path / 'b' / 'runs'}:" and all("0.25 GPU" in ln for ln in lines[1:])
    # --only: the runs matching one of its patterns, in the plan's order; a pattern matching none is an error
    assert batch.main(["--sweep", str(sweep), "--list", "--only", "*_pw02, synthetic_*"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"9 runs into {tmp_path / 'b' / 'runs'}:"
    assert [ln.split()[0] for ln in lines[1:]] == [n for n in want if n.endswith("_pw02")] + [want[-1]]
    assert batch.main(["--sweep", str(sweep), "--list", "--only", "*_pw03"]) == 2
    assert "--only '*_pw03': matches no run" in capsys.readouterr().err
    # two groups giving one name, an unknown key, a bad variant name: one line each, nothing runs
    for text, msg in ((f"runs: [{{data: {data}}}, {{data: {data}}}]", "two runs are named scene_3v_baseline_s0"),
                      ("runs: [{data: synthetic}]\nsedds: [1]", "unknown keys sedds"),
                      ("runs: [{data: synthetic, variants: {'a_b': []}}]", "variant 'a_b'")):
        bad = _sweep(tmp_path / "bad.yaml", text)
        assert batch.main(["--sweep", str(bad), "--list", "--method", "baseline", "--views", "3"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0], err


def test_the_deadline_is_a_duration_a_utc_time_or_an_iso_time():
    now = 1_794_990_400.0  # 2026-11-18 08:26:40 UTC
    assert batch.parse_deadline("600", now) == now + 600 and batch.parse_deadline("90s", now) == now + 90
    assert batch.parse_deadline("45m", now) == now + 2700 and batch.parse_deadline("2h", now) == now + 7200
    assert batch.parse_deadline("09:00", now) == now + 33 * 60 + 20
    assert batch.parse_deadline("2026-11-18T10:26:40+01:00", now) == now + 3600
    assert batch.parse_deadline("2026-11-18T10:26:40", now) == now + 7200  # UTC when it names no zone
    for bad in ("08:00", "soon", "2026-11-18T08:00"):
        with pytest.raises(batch.BatchError, match="--deadline"):
            batch.parse_deadline(bad, now)


def test_a_deadline_stops_the_run_going_and_the_next_call_resumes_it(tmp_path):
    """Without Ray (the task's body): at the deadline the run still going gets SIGTERM and is recorded as stopped,
    with its periodic checkpoint; a run whose turn comes after the deadline does not start; the next call skips the
    finished run and resumes the stopped one from its checkpoint."""
    data = write_nerfstudio(tmp_path / "scene")
    runs, logs = tmp_path / "runs", tmp_path / "logs"
    base = ["--data", str(data), "--views", "3", "--method", "baseline", *TINY[:-4], "--device", "cpu", "--no-progress"]

    def spec(name, iterations):
        return {"name": name, "method": "baseline", "argv": base + ["--iterations", str(iterations)], "num_cpus": 1}

    # the long run is stopped long before its end (no loss check: the tiny scene's loss jumps after 1000 steps)
    short, long_ = spec("short", 20), spec("long", 100_000)
    long_["argv"] += ["--set", "train.explode_factor=0"]
    t0 = time.time()
    rec = batch.execute_run(short, str(runs / "short"), str(logs), "b1", deadline=t0 + 600)
    assert rec["status"] == "finished" and rec["metrics"]["iterations"] == 20
    # long enough for the long run to start and write its first checkpoints on a busy machine, whatever its speed
    budget = 15 + 3 * (time.time() - t0)
    rec = batch.execute_run(long_, str(runs / "long"), str(logs), "b1", deadline=time.time() + budget, grace=30)
    assert rec["status"] == "stopped" and "deadline" in rec["error"], rec
    a = rec["attempts"][-1]
    assert a["deadline"] and a["returncode"] in batch.STOPPED, a
    assert (runs / "long" / "checkpoint.pt").is_file() and not (runs / "long" / "metrics.json").exists()
    late = batch.execute_run(spec("late", 20), str(runs / "late"), str(logs), "b1", deadline=time.time() - 1)
    assert late["status"] == "not_started" and not (runs / "late").exists()
    assert not (logs / "late.attempts.jsonl").exists()
    # the next call: the finished run is not run again, the stopped one goes on from its checkpoint
    again = batch.execute_run(short, str(runs / "short"), str(logs), "b2", deadline=time.time() + 600)
    assert again["status"] == "finished" and again["reused"]
    assert len(batch.read_attempts(logs / "short.attempts.jsonl")) == 1
    rec = batch.execute_run(long_, str(runs / "long"), str(logs), "b2", deadline=time.time() + budget, grace=30)
    b = rec["attempts"][-1]
    assert rec["status"] == "stopped" and b["resume"] and b["from_step"] >= 10, rec
    assert f"--resume {runs / 'long'}" in (logs / "long.log").read_text()


def test_a_sweep_on_ray_cut_by_its_deadline_then_run_again(tmp_path):
    """The batch runner end to end on a local Ray: a sweep of two tiny runs, the second far too long for the call's
    deadline; then the same command again: the first is reused as it is, the second resumed."""
    pytest.importorskip("ray", reason="the batch runner needs Ray: pip install 'warpgs[ray]'")
    data = write_nerfstudio(tmp_path / "scene")
    tiny = json.dumps([TINY[i + 1] for i, x in enumerate(TINY) if x == "--set"])  # (JSON is YAML)
    sweep = _sweep(tmp_path / "two.yaml", f"""
out: {tmp_path / 'batch'}
device: cpu
set: {tiny}
runs:
  - {{data: {data}, views: 3, method: baseline, iterations: 20}}
  - {{data: {data}, views: 3, method: baseline, iterations: 100000, set: [train.explode_factor=0], variants: {{long: []}}}}
""")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]), "OMP_NUM_THREADS": "1"}
    out = tmp_path / "batch"

    def call(deadline: str):
        p = subprocess.run([sys.executable, "-m", "warpgs.pipelines.batch", "--sweep", str(sweep), "--cpus", "2",
                            "--deadline", deadline, "--grace", "30", "--progress-every", "5"], cwd=REPO, env=env,
                           capture_output=True, text=True, timeout=300)
        assert "Traceback" not in p.stderr and p.returncode in (0, 1), p.stderr
        return p, {r["name"]: r for r in json.loads((out / "results.json").read_text())["runs"]}

    # a deadline well past Ray's start and the short run on this machine, however busy: 6x a tiny run's time (3x
    # stopped the short run while another job held both cores of a 2-core machine)
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-m", "warpgs.pipelines.sparse", "--data", str(data), "--views", "3", "--method",
                    "baseline", *TINY,
                    "--iterations", "20", "--no-progress", "--out", str(tmp_path / "timing")], cwd=REPO, env=env,
                   check=True, capture_output=True, timeout=300)
    deadline = str(round(20 + 6 * (time.monotonic() - t0)))
    p, by = call(deadline)
    assert p.returncode == 1, p.stderr  # not every run finished
    first, second = "scene_3v_baseline_s0", "scene_3v_baseline_s0_long"
    assert by[first]["status"] == "finished" and by[first]["metrics"]["iterations"] == 20
    assert by[second]["status"] == "stopped" and by[second]["attempts"][-1]["deadline"], by[second]
    assert "1 stopped or not started at the deadline" in p.stderr
    psnr = by[first]["metrics"]["psnr"]
    p, by = call(deadline)
    assert by[first]["status"] == "finished" and by[first]["reused"] and by[first]["metrics"]["psnr"] == psnr
    assert len(batch.read_attempts(out / "logs" / f"{first}.attempts.jsonl")) == 1
    a = batch.read_attempts(out / "logs" / f"{second}.attempts.jsonl")
    assert len(a) == 2 and a[1]["resume"] and a[1]["deadline"], a  # it went on from its checkpoint


def test_every_committed_sweep_file_plans(capsys):
    """bench/sweeps/*.yaml: every run's config builds as the run's own would, and no two runs share a name."""
    sweeps = sorted((REPO / "bench" / "sweeps").glob("*.yaml"))
    assert sweeps
    for path in sweeps:
        assert batch.main(["--sweep", str(path), "--list", "--device", "cpu"]) == 0, capsys.readouterr().err
        lines = capsys.readouterr().out.splitlines()
        names = [ln.split()[0] for ln in lines[1:]]
        assert int(lines[0].split()[0]) == len(names) == len(set(names)) > 0, path
