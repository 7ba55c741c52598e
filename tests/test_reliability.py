"""Reliability (issue 19): no run lost to a shared output folder or a bad checkpoint, every bad input named in
one line, quiet runs. Each case reproduces what a new user ran into; the fuzzed loaders are tests/test_fuzz.py.

The runs are the tiny nerfstudio capture of tiny_scene.py (48x48, 200 Gaussians, a few dozen steps); the
loader messages use a few frames of ../shared/data/castle_p30 copied into tmp_path.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from tiny_scene import write_nerfstudio
from warpgs.config import Config, ConfigError, build_config
from warpgs.configio import check_limits, limit_error, limits_of
from warpgs.console import filtered_stderr, warn_once
from warpgs.data import SceneError, load_scene
from warpgs.model import GaussianModel, read_point_cloud
from warpgs.pipelines.sparse import main
from warpgs.runfolder import LOCK, RunFolderError, open_run_folder, read_lock
from warpgs.train import CheckpointError, read_checkpoint

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("WARPGS_SHARED_DATA", REPO.parent / "shared" / "data"))
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=f"shared data not found at {SHARED}")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return write_nerfstudio(tmp_path_factory.mktemp("capture"))


def _argv(data, out, *extra, iterations=20):
    return ["--data", str(data), "--views", "3", "--device", "cpu", "--no-progress", "--method", "baseline",
            "--set", "model.init=box", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]",
            "--set", "model.init_num=200", "--set", "eval.lpips_weights=/nonexistent/alexnet.pth",
            "--set", "eval.fps_repeats=1", "--set", "eval.save_images=false", "--iterations", str(iterations),
            "--out", str(out), *extra]


def _one_error_line(err: str, *parts: str) -> str:
    """The single ``error: ...`` line of a run that stopped on bad input (no traceback), holding ``parts``."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    errors = [ln for ln in lines if ln.startswith("error: ")]
    assert len(errors) == 1, lines
    for p in parts:
        assert p in errors[0], errors[0]
    return errors[0]


def _wait_for(cond, proc, timeout=180.0):
    t0 = time.monotonic()
    while not cond():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.05)


# ----------------------------------------------------------------------------------------------
# config values: every layer, every section, one table


def test_config_values_are_checked_in_every_layer_before_anything_runs(tmp_path, capsys):
    """Out-of-range and mistyped values stop the run with one line naming the key and the layer (file,
    --set or flag) they came from, also where a later layer sets the key again; nothing is created and the
    scene is never loaded (its path does not exist)."""
    bad_yaml = tmp_path / "mine.yaml"
    bad_yaml.write_text("loss:\n  ssim_weight: -0.2\n")
    out = tmp_path / "out"
    cases = [
        (["--set", "optim.means_lr=-1e-3"], "optim.means_lr = -0.001 (from --set optim.means_lr=-1e-3): must be > 0"),
        (["--set", "train.iterations=abc", "--iterations", "5"],
         "train.iterations = 'abc' (from --set train.iterations=abc): not a valid int"),
        (["--config", str(bad_yaml), "--set", "loss.ssim_weight=0.2"],
         f"loss.ssim_weight = -0.2 (from {bad_yaml}): must be >= 0"),
        (["--views", "0"], "data.views = 0 (from --views 0): must be >= 1"),
        (["--iterations", "0"], "train.iterations = 0 (from --iterations 0): must be >= 1"),
        (["--set", "full.baseline_fraction=1.5"], "full.baseline_fraction = 1.5 (from --set full.baseline_fraction=1.5): "
                                                  "must be in [0, 1)"),
        (["--set", "regularizers.dropout.rate=.nan"], "regularizers.dropout.rate = nan (from --set "
                                                      "regularizers.dropout.rate=.nan): must be a finite number"),
        # a key of an earlier version (warpgs.config.MOVED) is named where it lives now, and where it came from
        (["--set", "train.drop_rate=.nan"], "regularizers.dropout.rate = nan (from --set train.drop_rate=.nan): "
                                            "must be a finite number"),
        (["--set", "strategy.reset_every=0"], "strategy.reset_every = 0 (from --set strategy.reset_every=0): must be >= 1"),
        (["--set", "geometry.stereo.sgm_paths=8"],
         "geometry.stereo.sgm_paths = 8 (from --set geometry.stereo.sgm_paths=8): must be in [0, 4]"),
    ]
    for argv, message in cases:
        assert main(["--data", str(tmp_path / "no-such-scene"), "--method", "baseline", "--out", str(out), *argv]) == 2
        _one_error_line(capsys.readouterr().err, message)
        assert not out.exists()


def test_every_section_declares_its_ranges_in_one_table():
    """Each option class's LIMITS names its own fields with rules that parse, the defaults keep them, and a
    key of an earlier version (config.MOVED) is checked where it lives now, naming the layer."""
    seen = []

    def walk(obj, prefix=""):
        lim = limits_of(type(obj))
        names = {f.name for f in dataclasses.fields(obj)}
        assert set(lim) <= names, (type(obj).__name__, set(lim) - names)
        for key, rule in lim.items():
            assert limit_error(getattr(obj, key), rule) is None, (prefix + key, rule)
            seen.append(prefix + key)
        for f in dataclasses.fields(obj):
            if dataclasses.is_dataclass(getattr(obj, f.name)):
                walk(getattr(obj, f.name), prefix + f.name + ".")

    walk(Config())
    check_limits(Config())
    for key in ("optim.means_lr", "train.iterations", "loss.l1_weight", "full.baseline_fraction", "strategy.prune_opa",
                "compact.prune_ratio", "pseudo.sampler.steps", "densify.filter.std_ratio", "geometry.bounds_margin"):
        assert key in seen, key
    with pytest.raises(ConfigError, match=r"pseudo\.trajectory\.n_frames = 1 \(from old\.yaml\): must be >= 2"):
        build_config([("old.yaml", {"full": {"n_frames": 1}})])
    assert build_config([("old.yaml", {"full": {"n_frames": 5}})]).pseudo.trajectory.n_frames == 5


# ----------------------------------------------------------------------------------------------
# run folders


def test_output_folder_is_checked_before_the_scene_loads(tmp_path, capsys):
    """--out under /proc or below a file: one line naming the folder and why, before the scene loads (its
    path does not exist, so a later check would have said that instead)."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    missing = ["--data", str(tmp_path / "no-such-scene"), "--method", "baseline"]
    assert main(missing + ["--out", str(afile / "run")]) == 2
    _one_error_line(capsys.readouterr().err, f"output folder {afile / 'run'}", f"{afile} is a file, not a folder")
    assert main(missing + ["--out", str(afile)]) == 2
    _one_error_line(capsys.readouterr().err, f"output folder {afile}: it exists and is a file")
    if Path("/proc/self").is_dir():
        assert main(missing + ["--out", "/proc/warpgs-run"]) == 2
        _one_error_line(capsys.readouterr().err, "output folder /proc/warpgs-run: cannot be created or written")
    # a good folder: locked, then the scene fails to load; the folder this run made goes again, lock and all
    assert main(missing + ["--out", str(tmp_path / "new")]) == 2
    _one_error_line(capsys.readouterr().err, "no-such-scene")
    assert not (tmp_path / "new").exists()


def test_run_folder_lock_stale_locks_and_earlier_runs(tmp_path):
    out = tmp_path / "run"
    out.mkdir()  # (a folder the run creates and leaves empty goes again on release)
    first = open_run_folder(out)
    info = read_lock(out)
    assert info["pid"] == os.getpid() and info["host"] == socket.gethostname()
    with pytest.raises(RunFolderError, match=f"in use by another warpgs run \\(pid {os.getpid()} on "):
        open_run_folder(out)
    first.release()
    assert not (out / LOCK).exists()

    # a lock whose process is gone (a run killed with SIGKILL) is taken over with a note
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    (out / LOCK).write_text(json.dumps({"pid": gone.pid, "host": socket.gethostname(), "token": "x"}))
    notes = []
    held = open_run_folder(out, log=notes.append)
    assert len(notes) == 1 and "took over the lock" in notes[0] and f"pid {gone.pid}" in notes[0]
    assert read_lock(out)["pid"] == os.getpid()
    held.release()

    # one from another host cannot be checked from here: the message says what to do
    (out / LOCK).write_text(json.dumps({"pid": 1, "host": "elsewhere.example", "token": "y"}))
    with pytest.raises(RunFolderError, match=f"another host.*delete {out / LOCK}"):
        open_run_folder(out)
    (out / LOCK).unlink()

    # a finished run needs --resume or --overwrite; --overwrite deletes its outputs and nothing else
    (out / "metrics.json").write_text("{}")
    (out / "test").mkdir()
    (out / "test" / "000_a.png").write_bytes(b"png")
    (out / "baseline").mkdir()
    (out / "baseline" / "checkpoint.pt").write_bytes(b"ck")
    (out / "my_notes.txt").write_text("keep me")
    with pytest.raises(RunFolderError, match="holds a finished run .*--resume.*--overwrite"):
        open_run_folder(out)
    assert not (out / LOCK).exists()  # the lock is given back when the folder is refused
    open_run_folder(out, resume=True).release()
    # one that stopped early (its last good state's metrics) says so: --resume continues it
    (out / "metrics.json").write_text(json.dumps({"stopped_early": {"reason": "out_of_memory", "step": 12}}))
    with pytest.raises(RunFolderError, match="holds a run that stopped early \\(out_of_memory at step 12; .*--resume"):
        open_run_folder(out)
    held = open_run_folder(out, overwrite=True, log=lambda msg: None)
    assert sorted(p.name for p in out.iterdir()) == sorted([LOCK, "my_notes.txt"])
    held.release()


def test_two_concurrent_runs_into_one_out_and_a_quiet_cpu_run(data, tmp_path, capsys):
    """The second run into a folder in use stops with a message naming the first; the first finishes with its
    results intact, and prints nothing on stderr that does not apply to a CPU-only run (no CUDA-driver
    warning, one short LPIPS line). Its finished folder then needs --resume or --overwrite."""
    out = tmp_path / "shared_out"
    first = subprocess.Popen([sys.executable, "-m", "warpgs.pipelines.sparse", *_argv(data, out, iterations=120)],
                             cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: (out / LOCK).exists(), first)
        assert main(_argv(data, out, iterations=10)) == 2
        _one_error_line(capsys.readouterr().err, f"output folder {out} is in use by another warpgs run (pid {first.pid} on")
        stdout, stderr = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["iterations"] == 120 and read_checkpoint(out / "checkpoint.pt")["step"] == 120
    assert not (out / LOCK).exists()
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert not [ln for ln in lines if "warning" in ln.lower() or "cuda" in ln.lower()], lines
    lpips = [ln for ln in lines if "LPIPS" in ln]
    assert len(lpips) == 1 and len(lpips[0]) < 160, lpips
    assert len(lines) <= 3, lines  # the scene summary, the LPIPS line, and at most one more
    assert f"wrote {out / 'metrics.json'}" in stdout

    before = (out / "metrics.json").read_bytes()
    assert main(_argv(data, out, iterations=10)) == 2
    _one_error_line(capsys.readouterr().err, f"output folder {out} holds a finished run", "--resume", "--overwrite")
    assert (out / "metrics.json").read_bytes() == before


# ----------------------------------------------------------------------------------------------
# checkpoints


def test_killed_run_resumes_from_the_previous_checkpoint_and_takes_over_its_lock(data, tmp_path, capsys):
    """SIGKILL leaves a stale lock; the current checkpoint is then truncated: --resume takes the lock over
    with a note, says in one line that checkpoint.pt cannot be read and resumes from checkpoint.prev.pt."""
    out = tmp_path / "killed"
    run = subprocess.Popen([sys.executable, "-m", "warpgs.pipelines.sparse",
                            *_argv(data, out, "--set", "train.checkpoint_every=5", iterations=5000)],
                           cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: (out / "checkpoint.prev.pt").exists(), run)
    finally:
        run.kill()
        run.wait()
    assert (out / LOCK).exists() and read_lock(out)["pid"] == run.pid
    ck = out / "checkpoint.pt"
    half = ck.read_bytes()[: ck.stat().st_size // 2]
    ck.unlink()  # a new file: killed between its two renames, checkpoint.prev.pt is a hard link to the same one
    ck.write_bytes(half)
    prev_step = read_checkpoint(out / "checkpoint.prev.pt")["step"]
    with pytest.raises(CheckpointError, match=f"{ck}: cannot be read, it is truncated or corrupt"):
        read_checkpoint(ck)

    assert main(["--resume", str(out), "--iterations", str(prev_step + 10), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    took = [ln for ln in err.splitlines() if "took over the lock" in ln]
    assert len(took) == 1 and f"pid {run.pid}" in took[0]
    fallback = [ln for ln in err.splitlines() if "cannot be read" in ln]
    assert len(fallback) == 1 and "resuming from the previous checkpoint checkpoint.prev.pt" in fallback[0], err
    assert f"resumed {out / 'checkpoint.prev.pt'} at step {prev_step}" in err
    assert json.loads((out / "metrics.json").read_text())["iterations"] == prev_step + 10
    assert not (out / LOCK).exists()


def test_a_failed_checkpoint_write_keeps_the_last_good_one(data, tmp_path, capsys, monkeypatch):
    """A full disk (OSError ENOSPC) at the third checkpoint: one error line naming the file, the reason and
    the intact checkpoint; both files on disk are the good ones, no temporary file is left, and --resume
    continues from there. A checkpoint no file of which can be read is one line too."""
    out = tmp_path / "full_disk"
    real_save = torch.save
    calls = []

    def save(obj, f, *args, **kwargs):
        calls.append(obj.get("step"))
        if len(calls) == 3:
            f.write(b"half a checkpoint")
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_save(obj, f, *args, **kwargs)

    monkeypatch.setattr(torch, "save", save)
    assert main(_argv(data, out, "--set", "train.checkpoint_every=5", iterations=30)) == 2
    monkeypatch.setattr(torch, "save", real_save)
    _one_error_line(capsys.readouterr().err, f"{out / 'checkpoint.pt'}: cannot write the checkpoint of step 15",
                    "No space left on device", f"the last good checkpoint {out / 'checkpoint.pt'} (step 10) is intact",
                    f"--resume {out}")
    assert calls == [5, 10, 15]
    assert read_checkpoint(out / "checkpoint.pt")["step"] == 10
    assert read_checkpoint(out / "checkpoint.prev.pt")["step"] == 5
    assert sorted(p.name for p in out.iterdir() if ".tmp" in p.name) == []
    assert main(["--resume", str(out), "--no-progress"]) == 0
    assert "resumed" in capsys.readouterr().err
    assert json.loads((out / "metrics.json").read_text())["iterations"] == 30

    for name in ("checkpoint.pt", "checkpoint.prev.pt"):
        (out / name).write_bytes(b"PK\x03\x04 not a checkpoint")
    assert main(["--resume", str(out), "--no-progress"]) == 2
    _one_error_line(capsys.readouterr().err, f"{out / 'checkpoint.pt'}: cannot be read",
                    "the previous one cannot be read either")


def test_an_interrupt_while_the_results_are_written_is_one_message_and_resume_writes_them(data, tmp_path, capsys,
                                                                                          monkeypatch):
    """Ctrl-C (or a batch's time limit, SIGINT) during the final evaluation: no traceback, exit code 130, a line that
    says training is complete and how to write the results; --resume then writes them without training again."""
    from warpgs.train import Trainer

    out = tmp_path / "interrupted_finish"
    real_evaluate, real_finish = Trainer.evaluate, Trainer.finish

    def finish(self, *args, **kwargs):
        self.finishing = True
        return real_finish(self, *args, **kwargs)

    def evaluate(self, *args, **kwargs):  # the first thing finish does after the final pruning
        if getattr(self, "finishing", False):
            raise KeyboardInterrupt
        return real_evaluate(self, *args, **kwargs)

    monkeypatch.setattr(Trainer, "finish", finish)
    monkeypatch.setattr(Trainer, "evaluate", evaluate)
    assert main(_argv(data, out, iterations=20)) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert "stopped while writing the results; training is complete" in err and f"--resume {out}" in err
    assert not (out / "metrics.json").exists()
    monkeypatch.setattr(Trainer, "evaluate", real_evaluate)
    monkeypatch.setattr(Trainer, "finish", real_finish)
    assert main(["--resume", str(out), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "at step 20 of 20" in err, err
    assert json.loads((out / "metrics.json").read_text())["iterations"] == 20


# ----------------------------------------------------------------------------------------------
# loaders: the culprit by name


@needs_shared
def test_loader_messages_name_the_field_and_mixed_channels_get_one_note(tmp_path, capfd):
    src = SHARED / "castle_p30"
    meta = json.loads((src / "transforms.json").read_text())
    meta["frames"] = sorted(meta["frames"], key=lambda f: f["file_path"])[:6]
    root = tmp_path / "castle"
    (root / "images_4").mkdir(parents=True)
    for fr in meta["frames"]:
        shutil.copy(src / "images_4" / Path(fr["file_path"]).name, root / "images_4")

    def write(m):
        (root / "transforms.json").write_text(json.dumps(m))

    write(meta)
    assert len(load_scene(str(root), views=2).train) == 2
    capfd.readouterr()

    # a wrong-size image in images_4: the folder's size is expected (768x512), not a made-up downscale
    good = (root / "images_4" / "0003.jpg").read_bytes()
    Image.new("RGB", (600, 400)).save(root / "images_4" / "0003.jpg")
    with pytest.raises(SceneError) as e:
        load_scene(str(root), views="all")
    assert "0003.jpg: image is 600x400" in str(e.value) and "expected 768x512 in images_4/" in str(e.value)
    assert "downscale 5" not in str(e.value)
    (root / "images_4" / "0003.jpg").write_bytes(good)

    # intrinsics errors name the field
    for key, value in (("fl_x", 0.0), ("fl_y", -5.0), ("cy", float("nan")), ("w", "wide")):
        write({**meta, key: value})
        with pytest.raises(SceneError) as e:
            load_scene(str(root), views=2)
        assert f"{key} = {value!r}" in str(e.value), str(e.value)
    write(meta)
    with pytest.raises(SceneError, match=r"transforms\.json: views=0: at least 1 training view"):
        load_scene(str(root), views=0)

    # a grayscale and an RGBA frame among RGB ones: taken, converted, and said once in one line
    with Image.open(root / "images_4" / "0002.jpg") as im:
        im.convert("L").save(root / "images_4" / "0002.jpg")
    with Image.open(root / "images_4" / "0004.jpg") as im:
        im.convert("RGBA").save(root / "images_4" / "0004.png")
    frames = [dict(fr, file_path=fr["file_path"].replace("0004.jpg", "0004.png")) for fr in meta["frames"]]
    write({**meta, "frames": frames})
    scene = load_scene(str(root), views="all")
    assert all(c.image.shape == (512, 768, 3) for c in scene.cameras)
    notes = [ln for ln in capfd.readouterr().err.splitlines() if "note" in ln]
    assert len(notes) == 1, notes
    assert "2 of 6 images are not RGB" in notes[0] and "0002.jpg (grayscale)" in notes[0] and "0004.png (RGBA)" in notes[0]


# ----------------------------------------------------------------------------------------------
# PLY input


def _model_with_nonfinite(path: Path, rows: list) -> Path:
    """50 Gaussians with ``rows``: (parameter, index, value) set."""
    g = torch.Generator().manual_seed(0)
    m = GaussianModel.random_box(50, [-1, -1, 3], [1, 1, 5], generator=g, sh_degree=1)
    with torch.no_grad():
        for name, index, value in rows:
            m.params[name][index] = value
    return m.save_ply(path)


def test_nonfinite_gaussians_are_refused_with_their_count_or_dropped(tmp_path, capsys):
    from warpgs import viz

    part = _model_with_nonfinite(tmp_path / "part.ply", [("means", slice(0, 3), float("nan")),
                                                         ("opacities", 10, float("inf"))])
    with pytest.raises(ValueError, match="4 of 50 Gaussians have non-finite values .* in x, y, z, opacity; --drop-invalid"):
        GaussianModel.load_ply(part)
    assert len(GaussianModel.load_ply(part, drop_invalid=True)) == 46
    assert "dropped 4 of 50 Gaussians" in capsys.readouterr().err

    every = _model_with_nonfinite(tmp_path / "nan.ply", [("means", slice(None), float("nan"))])
    png = tmp_path / "view.png"
    for extra in ([], ["--drop-invalid"]):  # all-NaN: nothing to show either way, and no blank PNG
        assert viz.main([str(every), "--png", str(png), "--renderer", "numpy", *extra]) == 2
        assert "all 50 Gaussians have non-finite values" in capsys.readouterr().err and not png.exists()
    assert viz.main([str(part), "--png", str(png), "--renderer", "numpy"]) == 2
    assert "4 of 50 Gaussians" in capsys.readouterr().err and not png.exists()
    assert viz.main([str(part), "--png", str(png), "--renderer", "numpy", "--drop-invalid", "--size", "64x48"]) == 0
    assert "46 gaussians" in capsys.readouterr().out and png.is_file()

    # a point cloud for model.init=ply: the same rule, and --drop-invalid reaches it from the command line
    pts = np.random.default_rng(0).normal(size=(30, 3)).astype(np.float32)
    pts[[2, 7]] = np.nan
    viz.save_origin_ply(tmp_path / "cloud.ply", pts, np.full((30, 3), 0.5))
    with pytest.raises(ValueError, match="2 of 30 points have non-finite values"):
        read_point_cloud(tmp_path / "cloud.ply")
    assert len(read_point_cloud(tmp_path / "cloud.ply", drop_invalid=True)[0]) == 28
    from warpgs.pipelines.sparse import build_parser, make_config

    cfg, _ = make_config(build_parser().parse_args(["--method", "baseline", "--drop-invalid"]))
    assert cfg.model.drop_invalid is True


def test_viz_png_prints_nothing_that_does_not_apply(tmp_path):
    """A headless PNG of a partly-NaN file with --drop-invalid: stderr holds the one drop warning and nothing
    else (no XDG_RUNTIME_DIR line from EGL, whichever renderer draws it)."""
    part = _model_with_nonfinite(tmp_path / "part.ply", [("means", 4, float("nan"))])
    env = {k: v for k, v in os.environ.items() if k != "XDG_RUNTIME_DIR"}
    r = subprocess.run([sys.executable, "-m", "warpgs.viz", str(part), "--png", str(tmp_path / "v.png"), "--size",
                        "96x72", "--drop-invalid"], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "dropped 1 of 50 Gaussians" in lines[0], lines
    assert (tmp_path / "v.png").is_file()


# ----------------------------------------------------------------------------------------------
# quiet output


def test_warnings_once_and_native_lines_that_do_not_apply_dropped(capfd):
    assert warn_once("warpgs: a test warning", key="test-once") is True
    assert warn_once("warpgs: a test warning, again", key="test-once") is False
    with filtered_stderr(["could not load the driver"]):
        os.write(2, b"Native warning: could not load the DRIVER here\n")
        os.write(2, b"native: something that applies\n")
        print("python: this stays", file=sys.stderr)
    err = capfd.readouterr().err
    assert err.count("a test warning") == 1 and "DRIVER" not in err
    assert "something that applies" in err and "python: this stays" in err
