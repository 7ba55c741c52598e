"""``pseudo.backend: auto`` finds Stable Video Diffusion without flags, and the front door takes the flags.

The tiny random model is laid out as ``huggingface-cli download`` lays it out in the Hugging Face cache
(``models--stabilityai--stable-video-diffusion-img2vid-xt/snapshots/<hash>/`` with the component folders, files
linked to ``blobs/``, ``refs/main`` naming the snapshot); auto must find it through --svd-path,
$WARPGS_SVD_PATH, $HF_HOME and $HF_HUB_CACHE, name what an incomplete folder lacks, and fall back to the
weight-free prior with one line when there is nothing. Through the command line (a subprocess): a missing
folder is one ``error:`` line naming flags the command accepts, exit 2, no run folder made. The read ahead of the
first cycle (``prefetch_backend``, in a thread): the load's weight files, no model built there, the load's error
raised by the load, nothing printed, no wait at exit.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from warpgs.pseudo.backends import SVD_ENV, SVD_HF_FOLDER, SVDWeightsNotFound, choose_backend, find_svd_weights

ROOT = Path(__file__).resolve().parents[1]
HASH = "0123456789abcdef0123456789abcdef01234567"


@pytest.fixture(autouse=True)
def no_weights_anywhere(tmp_path, monkeypatch):
    """Nothing found unless a test puts it there: no $WARPGS_SVD_PATH, an empty cache."""
    monkeypatch.delenv(SVD_ENV, raising=False)
    monkeypatch.delenv("HF_HOME", raising=False)
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty_cache"))


@pytest.fixture(scope="module")
def tiny_svd(tmp_path_factory):
    pytest.importorskip("diffusers")
    pytest.importorskip("transformers")
    from test_svd_tiny import build_tiny_svd

    return build_tiny_svd(tmp_path_factory.mktemp("svd") / "tiny")


def lay_out_as_hf_cache(model: Path, hub: Path) -> Path:
    """``model``'s files in the cache's layout under ``hub``: blobs by content hash, the snapshot's files links to
    them, refs/main. -> the snapshot folder."""
    repo = hub / SVD_HF_FOLDER
    snap = repo / "snapshots" / HASH
    for f in sorted(p for p in model.rglob("*") if p.is_file()):
        blob = repo / "blobs" / hashlib.sha256(f.read_bytes()).hexdigest()
        blob.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(f, blob)
        link = snap / f.relative_to(model)
        link.parent.mkdir(parents=True, exist_ok=True)
        os.symlink(os.path.relpath(blob, link.parent), link)
    (repo / "refs").mkdir(parents=True, exist_ok=True)
    (repo / "refs" / "main").write_text(HASH)
    return snap


def test_auto_finds_the_weights_in_each_place(tiny_svd, tmp_path, monkeypatch):
    from warpgs.pseudo.backends import SVDBackend, make_backend

    assert choose_backend("auto")[0] == "default"  # nothing anywhere: the weight-free prior
    # --svd-path (pseudo.svd.path)
    name, folder, line = choose_backend("auto", str(tiny_svd))
    assert (name, folder) == ("svd", tiny_svd) and "--svd-path" in line and str(tiny_svd) in line
    # $WARPGS_SVD_PATH
    monkeypatch.setenv(SVD_ENV, str(tiny_svd))
    assert choose_backend("auto")[:2] == ("svd", tiny_svd)
    monkeypatch.delenv(SVD_ENV)
    # the Hugging Face cache under $HF_HOME/hub, then $HF_HUB_CACHE (which wins over HF_HOME)
    snap = lay_out_as_hf_cache(tiny_svd, tmp_path / "hf_home" / "hub")
    monkeypatch.delenv("HF_HUB_CACHE")
    monkeypatch.setenv("HF_HOME", str(tmp_path / "hf_home"))
    name, folder, line = choose_backend("auto")
    assert (name, folder) == ("svd", snap) and "Hugging Face cache" in line
    other = lay_out_as_hf_cache(tiny_svd, tmp_path / "hub_cache")
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "hub_cache"))
    assert choose_backend("auto")[:2] == ("svd", other)
    # and the cache's snapshot loads: the components behind the links are the model
    backend = make_backend("auto", "cpu")
    assert isinstance(backend, SVDBackend) and backend.latent_shape(32, 32)[0] == 4


def test_incomplete_folders_name_what_is_missing(tiny_svd, tmp_path, monkeypatch):
    partial = tmp_path / "partial"
    shutil.copytree(tiny_svd, partial)
    shutil.rmtree(partial / "feature_extractor")
    for f in (partial / "unet").glob("*.safetensors"):
        f.unlink()
    with pytest.raises(SVDWeightsNotFound) as e:
        choose_backend("svd", str(partial))
    msg = str(e.value)
    assert "feature_extractor/" in msg and "unet/ weights" in msg and "vae" not in msg.split("lacks")[1].split(".")[0]
    # an interrupted download into the cache: a snapshot whose weights link to a blob that is not there
    snap = lay_out_as_hf_cache(tiny_svd, tmp_path / "cache")
    target = next((snap / "vae").glob("*.safetensors"))
    (target.parent / os.readlink(target)).unlink()
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "cache"))
    name, folder, line = choose_backend("auto")  # auto: the weight-free prior, saying what the cache's folder lacks
    assert name == "default" and folder is None and "vae/ weights" in line and str(snap) in line
    assert find_svd_weights()[0] is None


def test_choose_backend_without_weights(tmp_path):
    assert choose_backend("default") == ("default", None, "")
    name, folder, line = choose_backend("auto")
    assert name == "default" and "--svd-path" in line and "empty_cache" in line
    for name in ("svd", "auto"):  # a folder given that is not there is an error, auto or not
        with pytest.raises(SVDWeightsNotFound, match="not a folder"):
            choose_backend(name, str(tmp_path / "nowhere"))
    with pytest.raises(ValueError, match="auto, default, svd"):
        choose_backend("svdx")


def run_cli(args, tmp_path, env_extra=None):
    env = {k: v for k, v in os.environ.items() if k not in (SVD_ENV, "HF_HOME")}
    env.update({"HF_HUB_CACHE": str(tmp_path / "empty_cache"), "PYTHONPATH": str(ROOT)}, **(env_extra or {}))
    return subprocess.run([sys.executable, "-m", "warpgs.pipelines.sparse", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("flags", [["--svd-path", "/nonexistent/svd"], ["--pseudo-backend", "svd"]])
def test_missing_weights_through_the_command_line(tmp_path, flags):
    out = tmp_path / "run"
    r = run_cli(["--method", "full", "--device", "cpu", "--out", str(out), *flags], tmp_path)
    assert r.returncode == 2, r.stderr
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "Stable Video Diffusion weights" in errors[0] and "run folder" not in errors[0]
    assert not out.exists()  # checked before the run folder is made
    # every flag the message names is one the command accepts
    from warpgs.pipelines.sparse import build_parser

    accepted = {s for a in build_parser()._actions for s in a.option_strings}
    named = {w.strip("(),;.`") for w in errors[0].split() if w.startswith("--")}
    assert named and named <= accepted, named - accepted


def test_flags_reach_the_config():
    from warpgs.pipelines.sparse import build_parser, make_config

    for choice in ("svd", "default", "auto"):
        cfg, _ = make_config(build_parser().parse_args(["--pseudo-backend", choice, "--svd-path", "/x/svd"]))
        assert cfg.pseudo.backend == choice and cfg.pseudo.svd.path == "/x/svd"
    cfg, _ = make_config(build_parser().parse_args([]))
    assert cfg.pseudo.backend == "auto"


def test_the_main_command_runs_the_full_method_with_svd_path(tiny_svd, tmp_path):
    """--svd-path through the front door: the full method with the tiny model, its stage times recorded."""
    import json

    out = tmp_path / "run"
    r = run_cli(["--method", "full", "--device", "cpu", "--iterations", "12", "--no-progress", "--out", str(out),
                 "--svd-path", str(tiny_svd), "--set", "pseudo.svd.width=32", "--set", "pseudo.svd.height=32",
                 "--set", "pseudo.trajectory.n_frames=4", "--set", "pseudo.sampler.steps=2",
                 "--set", "model.init_num=300", "--set", "full.flythrough_frames=2", "--set", "eval.fps_repeats=1",
                 "--set", "eval.save_images=false", "--set", f"eval.lpips_weights={tmp_path / 'none.pth'}"], tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "Loading" not in r.stderr and "it/s" not in r.stderr  # no third-party progress bars
    m = json.loads((out / "metrics.json").read_text())
    c = m["cycles"][1]
    assert c["pseudo_trajectories"] == 2 and c["pseudo_frames_per_trajectory"] == 4
    assert c["pseudo_denoise_s"] > 0 and c["pseudo_per_trajectory_s"] > 0
    assert c["pseudo_per_trajectory_s"] * 2 <= c["pseudo_views_s"] + 1e-6
    # the model's files are read while the baseline phase trains (prefetch_backend); the first cycle times its load
    assert 0 <= c["pseudo_model_load_s"] <= c["pseudo_views_s"] and c["pseudo_save_s"] >= 0
    # where the whole command's time went: its stages add up to no more than the total, and training holds the
    # pseudo views' generation
    wall = m["wall_s"]
    stages = [k for k in wall if k != "total"]
    assert {"startup", "load", "geometry", "setup", "train", "finish"} <= set(stages)
    assert sum(wall[k] for k in stages) <= wall["total"] + 0.05
    assert wall["train"] >= sum(x.get("pseudo_views_s", 0) for x in m["cycles"]) - 0.05
    assert set(m["outputs_s"]) == {"flythrough", "report"} and sum(m["outputs_s"].values()) <= wall["finish"] + 0.05


def test_the_model_is_loaded_once_for_the_cycles(tiny_svd):
    """generate_pseudo_views asks backend_from_config at every cycle: the loaded model is reused while the settings
    and device are the same, and replaced (not kept beside) when they change."""
    from warpgs.pseudo.views import PseudoConfig, backend_from_config

    cfg = PseudoConfig.load(overrides=[f"svd.path={tiny_svd}", "svd.width=32", "svd.height=32"])
    first = backend_from_config(cfg, "cpu")
    assert first.name == "svd" and backend_from_config(cfg, "cpu") is first
    assert cfg.backend == "auto"  # the caller's settings are not changed by the resolution
    other = backend_from_config(PseudoConfig.load(overrides=[f"svd.path={tiny_svd}", "svd.width=64",
                                                             "svd.height=64"]), "cpu")
    assert other is not first and other.model_size(10, 10) == (64, 64)


def test_one_line_says_which_prior_and_what_the_weight_free_one_costs_on_real_data(monkeypatch, capsys):
    import warpgs.console as console
    from warpgs.pseudo.views import PseudoConfig, resolve_backend

    monkeypatch.setattr(console, "_said", set())
    cfg = PseudoConfig()
    assert resolve_backend(cfg, real_data=False) == "default" and cfg.backend == "default"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "weight-free prior" in err[0] and "--svd-path" in err[0]
    cfg = PseudoConfig()
    resolve_backend(cfg, real_data=True)  # on a real capture: what that costs, with the measured figure, once
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "-0.09 dB" in err[0] and "2.5x the Gaussians" in err[0]
    resolve_backend(PseudoConfig(), real_data=True)
    assert capsys.readouterr().err == ""


@pytest.fixture
def nothing_loaded(monkeypatch):
    """backend_from_config's memory emptied for the test (restored after): loads start afresh."""
    import warpgs.pseudo.views as views

    monkeypatch.setattr(views, "_LOADED", {})
    monkeypatch.setattr(views, "_LOADING", {})
    return views


def test_a_prefetch_reads_the_weight_files_and_the_load_builds_in_the_calling_thread(tiny_svd, nothing_loaded,
                                                                                      monkeypatch, capfd):
    """prefetch_backend reads, in a daemon thread, the weight files the load reads (the dtype's variant of the
    unet's, the vae's and the image encoder's) and builds nothing there: diffusers' and transformers' loaders
    change process-wide torch state while they build, which a training thread beside them picks up. The load then
    runs in the calling thread, once; nothing is printed; a loaded backend or the weight-free one starts nothing."""
    import threading

    views = nothing_loaded
    calls = []
    real = views.make_backend

    def counted(*args, **kwargs):
        calls.append(threading.current_thread().name)
        return real(*args, **kwargs)

    monkeypatch.setattr(views, "make_backend", counted)
    read = []
    real_read = views._read_files
    monkeypatch.setattr(views, "_read_files", lambda files: (read.extend(files), real_read(files)))
    fp16 = tiny_svd / "unet" / "diffusion_pytorch_model.fp16.safetensors"  # a variant a float32 load skips
    shutil.copy(tiny_svd / "unet" / "diffusion_pytorch_model.safetensors", fp16)
    cfg = views.PseudoConfig.load(overrides=["backend=svd", f"svd.path={tiny_svd}", "svd.width=32", "svd.height=32"])
    capfd.readouterr()
    try:
        thread = views.prefetch_backend(cfg, "cpu")
        assert thread is not None and thread.daemon
        thread.join(60)
    finally:
        fp16.unlink()
    want = sorted(f for part in ("unet", "vae", "image_encoder") for f in (tiny_svd / part).iterdir()
                  if f.suffix in (".safetensors", ".bin") and ".fp16." not in f.name)
    assert len(want) == 3 and sorted(read) == want and not calls
    backend = views.backend_from_config(cfg, "cpu")
    assert backend.name == "svd" and calls == [threading.main_thread().name]
    assert views.prefetch_backend(cfg, "cpu") is None and views.backend_from_config(cfg, "cpu") is backend
    assert calls == [threading.main_thread().name]
    assert capfd.readouterr() == ("", "")
    assert views.prefetch_backend(views.PseudoConfig(backend="default"), "cpu") is None


@pytest.mark.parametrize("damage", ["missing part", "unreadable weights"])
def test_a_prefetch_of_a_broken_folder_leaves_the_error_to_the_load(damage, tiny_svd, nothing_loaded, tmp_path,
                                                                    monkeypatch):
    """A folder the load fails on: prefetch_backend raises nothing and its thread reports nothing
    (threading.excepthook sees nothing); the load raises what it raises without a prefetch, the same type and
    message. A missing part is found before any thread starts (no thread)."""
    import threading

    views = nothing_loaded
    broken = tmp_path / "broken"
    shutil.copytree(tiny_svd, broken)
    if damage == "missing part":
        shutil.rmtree(broken / "feature_extractor")
    else:
        for f in (broken / "unet").glob("*.safetensors"):
            f.write_bytes(b"not a safetensors file")
    cfg = views.PseudoConfig.load(overrides=["backend=svd", f"svd.path={broken}", "svd.width=32", "svd.height=32"])
    with pytest.raises(Exception) as direct:
        views.backend_from_config(cfg, "cpu")
    hooked = []
    monkeypatch.setattr(threading, "excepthook", hooked.append)
    thread = views.prefetch_backend(cfg, "cpu")
    assert (thread is None) == (damage == "missing part")
    if thread is not None:
        thread.join(60)
        assert not thread.is_alive() and not hooked
    with pytest.raises(type(direct.value)) as later:
        views.backend_from_config(cfg, "cpu")
    assert str(later.value) == str(direct.value) and str(direct.value)
    assert not views._LOADING and not views._LOADED  # forgotten: a later call tries again


def test_an_exit_during_a_prefetch_stops_the_read(tiny_svd, tmp_path):
    """The process ends while the read runs (a SIGTERM in the baseline phase, the end of a short run): the read
    stops at its next chunk, and the process exits at once with its own code. The stand-in read takes 10 minutes
    unless stopped; without the stop the interpreter would end over it (a daemon thread) just as fast, but the
    thread would not see the stop: the script checks that it did."""
    import time

    script = (
        "import time, warpgs.pseudo.views as views\n"
        "def slow(files):\n"
        "    if views._STOP.wait(600):\n"
        "        print('stopped', flush=True)\n"
        "views._read_files = slow\n"
        f"cfg = views.PseudoConfig.load(overrides=['backend=svd', 'svd.path={tiny_svd}'])\n"
        "thread = views.prefetch_backend(cfg, 'cpu')\n"
        "assert thread.is_alive()\n"
        "print('reading', flush=True)\n"
        "raise SystemExit(143)\n"
    )
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 143 and r.stdout == "reading\nstopped\n", r.stderr[-2000:]
    assert time.perf_counter() - t0 < 120  # the imports' seconds, not the read's 600


def test_a_load_in_another_thread_hides_its_own_warnings_only():
    """warnings_hidden_here outside the main thread: that thread's warnings are dropped, the main thread's (the
    training's, meanwhile) shown; a catch_warnings of the main thread interleaved with it (entered during the load,
    left after it) leaves the main thread's warnings shown, not ignored for good."""
    import threading
    import warnings

    from warpgs.pseudo.backends import warnings_hidden_here

    inside, leave, done = threading.Event(), threading.Event(), threading.Event()

    def load():
        with warnings_hidden_here():
            warnings.warn("from the load")
            inside.set()
            leave.wait(10)
        done.set()

    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        threading.Thread(target=load, daemon=True).start()
        assert inside.wait(10)
        warnings.warn("from the training")
        with warnings.catch_warnings():  # as Warp's logger wraps each of its warnings
            leave.set()
            assert done.wait(10)
        warnings.warn("after the load")
    messages = [str(w.message) for w in shown]
    assert messages == ["from the training", "after the load"], messages
