"""``python -m warpgs.view``: what it reads from a run folder, the frames it renders (against the run's own test
renders), its command line, and the page in a real browser (headless Chromium driven by playwright).

The browser test needs viser, playwright's pip package and a Chromium binary: ``$WARPGS_CHROMIUM``, else
Debian's ``chromium-headless-shell`` (``apt-get install chromium-headless-shell``; ``scripts/env.sh`` installs
it where it can), else ``chromium``. No ``playwright install`` is needed. Without one of them it is skipped,
saying which is missing.
"""

from __future__ import annotations

import io
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tiny_scene import write_nerfstudio
from warpgs.view import (
    MODES,
    fit_size,
    load_run,
    main,
    pinhole,
    pose_from_viewmat,
    render_image,
    viewmat_from_pose,
)

REPO = Path(__file__).resolve().parents[1]


def chromium_path() -> str | None:
    """The browser the test drives: $WARPGS_CHROMIUM, Debian's headless shell, or a full chromium."""
    for c in (os.environ.get("WARPGS_CHROMIUM"), shutil.which("chromium-headless-shell"),
              "/usr/lib/chromium/chromium-headless-shell", shutil.which("chromium"), shutil.which("chromium-browser")):
        if c and Path(c).is_file() and os.access(c, os.X_OK):
            return c
    return None


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A tiny trained run (300 Gaussians, 20 steps of the baseline on a 3-view capture, with 2 test views),
    plus one cycle in the files the full method writes: pseudo-view poses between the inputs and a
    densified cloud with kept / added / removed points."""
    from warpgs.pipelines.sparse import main as sparse_main
    from warpgs.pseudo.trajectory import path_trajectories
    from warpgs.viz import save_origin_ply

    tmp = tmp_path_factory.mktemp("view")
    data = write_nerfstudio(tmp / "scene")
    out = tmp / "run"
    assert sparse_main(["--data", str(data), "--views", "3", "--device", "cpu", "--no-progress", "--method", "baseline",
                        "--set", "model.init=box", "--set", "model.init_box=[-1.2,-1.2,-1.2,1.2,1.2,1.2]",
                        "--set", "model.init_num=300", "--set", f"eval.lpips_weights={tmp / 'none.pth'}",
                        "--set", "eval.fps_repeats=1", "--iterations", "20", "--out", str(out)]) == 0
    run = load_run(out)
    V = np.stack([v.viewmat for v in run.train])
    for j, traj in enumerate(path_trajectories(V, 6, "capture")):
        d = out / "cycle_1" / "pseudo" / f"seq_{traj.start:03d}_{traj.end:03d}"
        d.mkdir(parents=True)
        np.savez(d / "poses.npz", viewmats=np.asarray(traj.viewmats, np.float32), K=run.train[0].K)
    rng = np.random.default_rng(0)
    save_origin_ply(out / "cycle_1" / "densified.ply", rng.uniform(-1, 1, (60, 3)), rng.uniform(0, 1, (60, 3)),
                    np.repeat([0, 1, 2], 20))
    return out


def test_run_folder_is_read(run_dir):
    run = load_run(run_dir)
    assert len(run.model) > 0 and run.notes == []
    assert [v.name for v in run.test] == ["f000", "f008"] and len(run.train) == 3
    assert all(v.image.shape == (v.height, v.width, 3) for v in run.train + run.test)
    assert [c.index for c in run.cycles] == [1]
    cyc = run.cycles[0]
    assert len(cyc.trajectories) == 2 and all(t.shape == (6, 4, 4) for t in cyc.trajectories)
    # the trajectories start and end at the inputs
    assert np.allclose(cyc.trajectories[0][0], run.train[0].viewmat, atol=1e-5)
    assert np.bincount(cyc.cloud["origin"]).tolist() == [20, 20, 20]
    # a bare PLY: the model only; a run without its data: the model, with a note instead of the cameras
    bare = load_run(run_dir / "point_cloud.ply")
    assert len(bare.model) == len(run.model) and bare.train == [] and bare.cycles == []
    assert load_run(run_dir, cameras=False).train == []


def test_rgb_frame_is_the_runs_own_test_render(run_dir):
    """The viewer's frame at a test camera is the render the evaluation wrote into test/ (render | ground
    truth), to the bit, and its right half is the ground truth the panel shows."""
    run = load_run(run_dir)
    pngs = sorted((run_dir / "test").glob("*.png"))
    assert len(pngs) == len(run.test) == 2
    for png, v in zip(pngs, run.test):
        saved = np.asarray(Image.open(png).convert("RGB")).astype(int)
        img = render_image(run.model, v.viewmat, v.K, v.width, v.height, "rgb", run.backdrop)  # the far field where the run had one
        assert img.dtype == np.uint8 and img.shape == (v.height, v.width, 3)
        assert np.abs(saved[:, : v.width] - img).max() == 0
        assert np.abs(saved[:, v.width:] - np.round(v.image * 255)).max() <= 1
        assert img.std() > 5  # a picture, not a blank frame


def test_depth_and_alpha_modes():
    """Two opaque Gaussians side by side at depths 2 and 6: the alpha frame is white on both and black between,
    the depth frame puts them at the two ends of matplotlib's turbo colour map (near: 0, far: 1)."""
    import matplotlib
    import torch

    from warpgs.model import GaussianModel

    means = torch.tensor([[-0.5, 0.0, 2.0], [1.5, 0.0, 6.0]])
    m = GaussianModel.from_points(means, torch.tensor([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]]), sh_degree=0)
    with torch.no_grad():
        m.params["scales"].fill_(float(np.log(0.2)))
        m.params["opacities"].fill_(8.0)
    K = pinhole(np.radians(60), 96, 64)
    vm = np.eye(4)
    alpha = render_image(m, vm, K, 96, 64, "alpha")
    depth = render_image(m, vm, K, 96, 64, "depth").astype(float)
    uv = [(K @ p.numpy())[:2] / p[2].item() for p in means]
    near, far = [(int(v), int(u)) for u, v in uv]
    assert alpha[near].min() > 220 and alpha[far].min() > 220 and alpha[2, 2].max() == 0
    lut = matplotlib.colormaps["turbo"](np.linspace(0, 1, 256))[:, :3] * 255

    def place(pixel):  # where on the colour map a pixel's colour lies (its alpha divided out)
        c = depth[pixel] * 255.0 / alpha[pixel][0]
        return int(np.argmin(np.abs(lut - c).sum(1))) / 255.0

    assert place(near) < 0.05 and place(far) > 0.95, (place(near), place(far))
    assert depth[2, 2].max() == 0
    with pytest.raises(ValueError, match="mode"):
        render_image(m, vm, K, 8, 8, "normals")
    assert MODES == ("rgb", "depth", "alpha")


def test_camera_conversions_round_trip():
    from warpgs.geometry import axis_angle_to_rotmat

    rng = np.random.default_rng(3)
    for _ in range(20):
        vm = np.eye(4)
        vm[:3, :3] = axis_angle_to_rotmat(rng.normal(size=3))
        vm[:3, 3] = rng.normal(size=3) * 3
        wxyz, pos = pose_from_viewmat(vm)
        assert np.allclose(viewmat_from_pose(wxyz, pos), vm, atol=1e-9)
        assert np.allclose((vm @ np.append(pos, 1))[:3], 0, atol=1e-9)  # the position is the camera centre
    K = pinhole(np.radians(50), 640, 360)
    assert np.isclose(2 * np.arctan(180 / K[1, 1]), np.radians(50)) and K[0, 2] == 320 and K[1, 2] == 180
    assert fit_size(1280, 720, 256) == (256, 144) and fit_size(100, 50, 4096) == (100, 50)


def test_frame_loop_previews_while_moving_then_renders_a_full_frame():
    """Moving: frames at the preview size; still for settle_s: one full-size frame of the newest camera. A move
    that arrives while a full frame is being made gets a full frame of its own (never left at the preview)."""
    import threading
    from types import SimpleNamespace

    import torch

    from warpgs.model import GaussianModel
    from warpgs.view import FrameLoop

    m = GaussianModel.from_points(torch.tensor([[0.0, 0.0, 3.0]]), torch.tensor([[1.0, 0.5, 0.2]]), sh_degree=0)
    viewer = SimpleNamespace(res=64, preview_res=16, mode="rgb", lock=threading.Lock(),
                             run=SimpleNamespace(model=m, backdrop=(0.0, 0.0, 0.0)))
    pose = {"vm": np.eye(4), "moves": 0}
    sent = []

    def camera():
        if loop.frames == 0 and pose["moves"] == 0:  # a move arrives just as the first full frame starts
            pose["moves"] += 1
            pose["vm"] = pose["vm"].copy()
            pose["vm"][0, 3] = 0.3
            loop.request(moving=True)
        return pose["vm"], 1.0, 128, 96

    loop = FrameLoop(viewer, camera, lambda img, final: sent.append((img.shape, final, loop.frames)), settle_s=0.3)
    try:
        loop.request(moving=False)
        t0 = time.monotonic()
        while sum(final for _, final, _ in sent) < 2 and time.monotonic() - t0 < 60:
            time.sleep(0.05)
        finals = [s for s in sent if s[1]]
        assert len(finals) >= 2, sent
        assert all(shape == (48, 64, 3) for shape, final, _ in sent if final)
        assert all(shape == (12, 16, 3) for shape, final, _ in sent if not final)
        assert np.allclose(loop.last_viewmat, pose["vm"]) and loop.last_final
        n = loop.frames
        for _ in range(5):  # moving: previews, then one full frame once still
            loop.request(moving=True)
            time.sleep(0.05)
        t0 = time.monotonic()
        while not (loop.frames > n and loop.last_final) and time.monotonic() - t0 < 60:
            time.sleep(0.05)
        assert loop.last_final and any(not final for _, final, k in sent if k >= n)
    finally:
        loop.stop()


def test_command_line_errors_are_one_line(run_dir, tmp_path, capsys, monkeypatch):
    def error_of(argv):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: "), err
        return err[0]

    assert "no such run folder" in error_of([str(tmp_path / "missing")])
    (tmp_path / "empty").mkdir()
    assert "not a run folder" in error_of([str(tmp_path / "empty")])
    (tmp_path / "broken.ply").write_text("hello\n")
    assert "not a PLY" in error_of([str(tmp_path / "broken.ply")])
    compare = tmp_path / "compare"
    for name in ("baseline", "full"):
        shutil.copytree(run_dir, compare / name)
    assert "holds the runs baseline, full" in error_of([str(compare)])
    assert "--port" in error_of([str(run_dir), "--port", "70000"])
    monkeypatch.setitem(sys.modules, "viser", None)  # as if it were not installed
    assert "pip install 'viser" in error_of([str(run_dir)])


def test_cli_prints_the_url_and_serves_the_page(run_dir):
    pytest.importorskip("viser")
    proc = subprocess.Popen([sys.executable, "-m", "warpgs.view", str(run_dir), "--host", "127.0.0.1", "--port", "0",
                             "--device", "cpu"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    lines = []
    reader = threading.Thread(target=lambda: lines.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(300)  # the first start after the environment is made also compiles its imports' bytecode
    try:
        assert lines and lines[0].startswith("warpgs.view: open http://127.0.0.1:"), (lines, proc.poll())
        url = lines[0].split()[2]
        page = urllib.request.urlopen(url, timeout=30).read().decode("utf-8", "replace")
        assert "<html" in page.lower()
        assert "3 training / 2 test views, 1 cycle;" in lines[0]
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:  # say what it was doing instead of only that it hung
            proc.kill()
            out, err = proc.communicate()
            raise AssertionError(f"warpgs.view did not stop within 120 s of Ctrl-C; first line {lines!r}; "
                                 f"stdout {out[-2000:]!r}; stderr {err[-4000:]!r}") from None
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert "warpgs.view: open" not in out  # the URL line was printed once


def test_ctrl_c_ends_the_command_even_when_the_server_does_not_stop(run_dir, monkeypatch, capsys):
    """A server whose stop never returns (an open websocket, a thread pool) must not keep the command alive:
    after Ctrl-C, main waits CLOSE_WAIT_S for it and returns 0."""
    pytest.importorskip("viser")
    import warpgs.view as view

    release = threading.Event()
    closing = threading.Event()

    class StuckViewer:
        url = "http://127.0.0.1:1"
        port = 8080  # the port asked for (the default)

        def __init__(self, *a, **k):
            pass

        def close(self):
            closing.set()
            release.wait(60)

    def ctrl_c(_seconds):
        raise KeyboardInterrupt

    monkeypatch.setattr(view, "Viewer", StuckViewer)
    monkeypatch.setattr(view, "CLOSE_WAIT_S", 0.3)
    monkeypatch.setattr(view.time, "sleep", ctrl_c)
    try:
        assert view.main([str(run_dir), "--device", "cpu"]) == 0
        stuck = not release.is_set()  # main returned while the stop it asked for was still blocked
    finally:
        release.set()
    assert closing.is_set()  # the stop was asked for
    assert stuck  # and not waited for beyond CLOSE_WAIT_S (the stuck close would have held it 60 s)
    assert "warpgs.view: open http://127.0.0.1:1" in capsys.readouterr().out


def test_a_taken_port_is_said_and_bad_input_is_one_error_line(run_dir, monkeypatch, capsys):
    """The viewer says when it serves on another port than the one asked for (viser takes the next free one);
    a bad --port or an unknown flag is one ``error:`` line and exit code 2."""
    pytest.importorskip("viser")
    import socket

    import warpgs.view as view

    def ctrl_c(_seconds):
        raise KeyboardInterrupt

    monkeypatch.setattr(view.time, "sleep", ctrl_c)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert view.main([str(run_dir), "--device", "cpu", "--host", "127.0.0.1", "--port", str(port)]) == 0
    err = capsys.readouterr().err
    assert f"port {port} is taken; serving on port" in err, err
    assert view.main([str(run_dir), "--port", "70000"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "70000" in err
    with pytest.raises(SystemExit) as e:
        view.main([str(run_dir), "--no-such-flag"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.startswith("error: ") and err.count("\n") == 1


# ----------------------------------------------------------------------------------------------
# in a real browser


def _browser_or_skip() -> str:
    pytest.importorskip("viser", reason="viser is not installed (pip install 'viser>=1.0')")
    pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
    path = chromium_path()
    if path is None:
        pytest.skip("no Chromium binary: apt-get install chromium-headless-shell, or set WARPGS_CHROMIUM=/path")
    return path


def _wait(cond, what: str, timeout: float = 90.0, state=None) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}" + (f" ({state()})" if state else ""))
        time.sleep(0.05)


def _settled(loop, after: int, quiet: float = 0.6):
    """A condition: ``loop`` has sent a frame after its ``after``-th, the newest is a full-resolution one,
    and no frame came for ``quiet`` seconds (the browser has had time to show it)."""
    state = {"key": None, "since": time.monotonic()}

    def cond() -> bool:
        key = (loop.frames, loop.last_final)
        if key != state["key"]:
            state["key"], state["since"] = key, time.monotonic()
        return loop.frames > after and loop.last_final and time.monotonic() - state["since"] > quiet

    return cond


def _screenshot(page) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), np.float32) / 255.0


def _shown(page, loop, timeout: float = 30.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(screenshot, frame, its viewmat, their difference) once the page shows the loop's newest frame (the
    browser decodes and draws it a little after the server sent it, seconds on a loaded machine; a camera still
    gliding after a drag may send one more), or at the timeout."""
    t0 = time.monotonic()
    while True:
        frame, viewmat = loop.last, loop.last_viewmat
        shot = _screenshot(page)
        err = _shown_error(shot, frame)
        if err < 0.03 or time.monotonic() - t0 > timeout:
            return shot, frame, viewmat, err
        time.sleep(0.25)


def _save_on_failure(name: str, shot: np.ndarray, frame: np.ndarray) -> str:
    """Keeps the screenshot and the frame under outputs/test_artifacts/ for a failed comparison; -> where."""
    out = REPO / "outputs" / "test_artifacts"
    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray((shot * 255).astype(np.uint8)).save(out / f"view_{name}_screenshot.png")
    Image.fromarray(frame).save(out / f"view_{name}_frame.png")
    return f"see {out}/view_{name}_*.png"


def _shown_error(shot: np.ndarray, frame: np.ndarray) -> float:
    """Mean difference between a screenshot and a frame stretched over the page, where no panel,
    notification or axes gizmo covers the canvas (left half, lower middle)."""
    h, w = shot.shape[:2]
    f = np.asarray(Image.fromarray(frame).resize((w, h), Image.BILINEAR), np.float32) / 255.0
    region = (slice(int(0.35 * h), int(0.85 * h)), slice(int(0.1 * w), int(0.45 * w)))
    return float(np.abs(shot[region] - f[region]).mean())


def test_viewer_in_a_real_browser(run_dir):
    """The page in headless Chromium: the first frame arrives and is what the browser shows; a mouse drag on
    the canvas moves the camera, and a new, different frame arrives and is shown; a jump to a test view
    through viser's client API puts the browser's camera there, renders that view and shows its ground
    truth beside the render in the panel; the panel's mode menu switches to alpha frames."""
    browser_path = _browser_or_skip()
    from playwright.sync_api import sync_playwright

    from warpgs.view import Viewer

    run = load_run(run_dir)
    viewer = Viewer(run, host="127.0.0.1", port=0, res=256, preview_res=128)
    viewer.toggles["train cameras"].value = False  # the frusta would cover parts of the frame compared below
    viewer.toggles["test cameras"].value = False
    assert not any(f.visible for group in viewer._frusta.values() for f in group)
    assert set(viewer.toggles) == {"train cameras", "test cameras", "cycle 1 pseudo", "cycle 1 kept", "cycle 1 added",
                                   "cycle 1 removed"}
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=browser_path, args=[
                "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
            try:
                page = browser.new_page(viewport={"width": 640, "height": 400})
                page.goto(viewer.url)
                _wait(lambda: len(viewer.loops) == 1, "the browser to connect")
                (client_id, loop), = viewer.loops.items()

                def state():
                    return f"frames {loop.frames}, last final {loop.last_final}, last render {loop.last_render_s:.2f} s"

                _wait(_settled(loop, 0), "the first frame", state=state)
                shot1, first, first_vm, err1 = _shown(page, loop)
                assert first.shape == (160, 256, 3) and first.std() > 5
                assert err1 < 0.03, _save_on_failure("first", shot1, first)

                # a drag on the canvas: the browser moves its camera and tells the server
                n = loop.frames
                page.mouse.move(200, 200)
                page.mouse.down()
                page.mouse.move(320, 240, steps=6)
                page.mouse.up()
                _wait(_settled(loop, n), "a frame after the drag", state=state)
                shot2, second, second_vm, err2 = _shown(page, loop)
                assert np.abs(second_vm - first_vm).max() > 1e-3, "the drag did not move the camera"
                assert np.abs(second.astype(float) - first).mean() > 5, "the new frame looks like the old one"
                assert err2 < 0.03, _save_on_failure("second", shot2, second)
                assert _shown_error(shot2, first) > 3 * err2 + 0.01, _save_on_failure("second_vs_first", shot2, first)

                # jump to a test view: the browser's camera follows, the frame is that view's, the panel shows
                # render | ground truth
                view = run.test[1]
                client = viewer.server.get_clients()[client_id]
                viewer.toggles["test cameras"].value = True
                n = loop.frames
                viewer.go_to(client, "test", view)
                # the view's own frustum (its image would fill the screen) is hidden, the other test view's is not
                assert [f.visible for f in viewer._frusta["test"]] == [True, False]
                _wait(_settled(loop, n), "a frame at the test view", state=state)
                _wait(lambda: np.allclose(client.camera.position, pose_from_viewmat(view.viewmat)[1], atol=1e-4),
                      "the browser's camera to reach the test view", 20)
                assert np.allclose(loop.last_viewmat, view.viewmat, atol=1e-4)
                pair = viewer.compare.image
                assert pair.shape == (view.height, 2 * view.width, 3)
                assert np.abs(pair[:, view.width:].astype(int) - np.round(view.image * 255)).max() <= 2

                # the panel's render mode: an alpha frame (grey, white where the model covers the view)
                n = loop.frames
                viewer.mode_menu.value = "alpha"
                _wait(_settled(loop, n), "an alpha frame", state=state)
                a = loop.last.astype(int)
                assert (a[..., 0] == a[..., 1]).all() and (a[..., 1] == a[..., 2]).all() and a.max() > 200
            finally:
                browser.close()
    finally:
        viewer.close()
