"""``python -m warpgs.view RUN_DIR`` (or a 3D-GS PLY): an interactive web viewer of a trained model.

    python -m warpgs.view outputs/compare/synthetic-room-0_3v/full          # prints the URL to open
    python -m warpgs.view outputs/lego/point_cloud.ply --port 8081 --host 127.0.0.1
    python -m warpgs.view outputs/fern --device cpu --res 480 --preview-res 192

Built on viser (https://viser.studio), the web viewer gsplat's ``nerfview`` and nerfstudio use: a page with
a 3D scene and a panel, served by this process, so it runs on a headless server (open the printed URL, or
forward the port: ``ssh -L 8080:localhost:8080 host``). The model is rendered by warpgs's own rasterizer
(``warpgs.render.rasterize`` through ``GaussianModel.render``) on each browser's camera, on a background
thread per browser, and shown as the scene's background image. Only the newest camera is rendered: camera
moves that arrive during a render are merged into the next one, never queued. While the camera moves,
frames are rendered at ``preview_res`` (longest side; on the CPU 256 px by default), and once it has been
still for ``settle_s`` at ``res`` (640 on the CPU, 1920 on CUDA), as nerfview does.

The page shows, for a run folder (``point_cloud.ply`` and ``config.yaml`` of ``python -m
warpgs.pipelines.sparse``):

- the training cameras (frusta with their images) and the test cameras; a click on one, or the panel's
  "go to view" list, moves the camera there, and the panel shows that view's render beside its image
  (the ground truth, for a test view), rendered with the view's own intrinsics;
- for the full method, each cycle's pseudo-view trajectories (``cycle_N/pseudo/seq_*/poses.npz``) and its
  densified points (``cycle_N/densified.ply``) as kept / added / removed, coloured as ``warpgs.viz``
  colours them, each with a toggle;
- the render mode: ``rgb``, ``depth`` (expected depth, turbo colour map between the 2nd and 98th
  percentiles of the covered pixels) or ``alpha`` (accumulated opacity).

The cameras come from loading the run's scene again (its ``config.yaml``'s ``data:`` section); where that
data is not on this machine the model is shown alone, with a one-line note. Camera convention as in the
rest of the library (OpenCV axes, world-to-camera ``viewmat``, ``K`` in pixels); viser's camera is the
same OpenCV frame (``wxyz``/``position`` of the camera in the world, vertical field of view).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from warpgs.geometry import camera_centres, pose, quat_to_rotmat, rotmat_to_quat
from warpgs.model import GaussianModel
from warpgs.viz import ORIGIN_COLORS, ORIGIN_NAMES, OneLineParser, default_camera, read_cloud

MODES = ("rgb", "depth", "alpha")
CLOSE_WAIT_S = 10.0  # seconds Ctrl-C waits for the server to stop before the command ends anyway
VISER_HINT = "pip install 'viser>=1.0'  (or: pip install -e '.[view]')"


# ----------------------------------------------------------------------------------------------
# what a run folder holds


@dataclass
class View:
    """One camera of the run: world-to-camera ``viewmat`` (4x4), ``K`` (3x3, pixels), its image [H, W, 3] in
    [0, 1] (the training input, or a test view's ground truth)."""

    name: str
    viewmat: np.ndarray
    K: np.ndarray
    width: int
    height: int
    image: np.ndarray | None = None

    @property
    def fov_y(self) -> float:
        return 2.0 * math.atan(0.5 * self.height / float(self.K[1, 1]))


@dataclass
class Cycle:
    """One cycle of the full method: its pseudo-view trajectories ([T, 4, 4] viewmats each) and its
    densified cloud (``read_cloud``'s dict, with ``origin``), either possibly empty."""

    index: int
    trajectories: list[np.ndarray] = field(default_factory=list)
    cloud: dict | None = None


@dataclass
class Run:
    """What the viewer shows: the model and, where the run's scene could be loaded, its views."""

    name: str
    model: GaussianModel
    train: list[View] = field(default_factory=list)
    test: list[View] = field(default_factory=list)
    cycles: list[Cycle] = field(default_factory=list)
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    notes: list[str] = field(default_factory=list)
    far_field: object = None  # the run's far field (far_field.json, warpgs.farfield), drawn behind the Gaussians

    @property
    def backdrop(self):
        """What ``render_image`` draws behind the Gaussians: the far field where the run had one, else the colour."""
        return self.far_field if self.far_field is not None else self.background

    def summary(self) -> str:
        cycles = len(self.cycles)
        return f"{len(self.train)} training / {len(self.test)} test views, {cycles} cycle{'' if cycles == 1 else 's'}"


def _views(cams) -> list[View]:
    return [View(c.name, np.asarray(c.viewmat, np.float64), np.asarray(c.K, np.float64), int(c.width), int(c.height),
                 np.asarray(c.image, np.float32)) for c in cams]


def load_run(path: str | Path, device: str | torch.device = "cpu", cameras: bool = True) -> Run:
    """A run folder (``point_cloud.ply``, ``config.yaml``, ``cycle_N/``) or a 3D-GS PLY -> ``Run``. A path
    that is neither is a ``FileNotFoundError`` / ``ValueError`` naming it; a scene that cannot be loaded
    again (data not on this machine) leaves the views out with a note in ``Run.notes``."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such run folder or PLY file")
    if path.is_file():
        return Run(name=path.stem, model=GaussianModel.load_ply(path, device=device))
    ply = path / "point_cloud.ply"
    if not ply.is_file():
        runs = sorted(p.name for p in path.iterdir() if (p / "point_cloud.ply").is_file())
        if runs:
            raise ValueError(f"{path}: holds the runs {', '.join(runs)}; give one of them "
                             f"(python -m warpgs.view {path / runs[-1]})")
        raise FileNotFoundError(f"{path}: not a run folder (no point_cloud.ply)")
    run = Run(name=f"{path.parent.name}/{path.name}", model=GaussianModel.load_ply(ply, device=device))
    for d in sorted(path.glob("cycle_*"), key=lambda p: (len(p.name), p.name)):
        try:
            index = int(d.name.split("_", 1)[1])
        except ValueError:
            continue
        cyc = Cycle(index)
        for npz in sorted(d.glob("pseudo/seq_*/poses.npz")):
            with np.load(npz) as z:
                cyc.trajectories.append(np.asarray(z["viewmats"], np.float64))
        if (d / "densified.ply").is_file():
            cyc.cloud = read_cloud(d / "densified.ply")
        run.cycles.append(cyc)
    if (path / "far_field.json").is_file():
        from warpgs.farfield import ElevationFarField

        run.far_field = ElevationFarField.load(path / "far_field.json")
    if cameras and (path / "config.yaml").is_file():
        _add_views(run, path / "config.yaml")
    return run


def _add_views(run: Run, config_path: Path) -> None:
    from warpgs.config import config_from_dict, read_yaml
    from warpgs.pipelines.sparse import load_scene_for

    try:
        cfg = config_from_dict(read_yaml(config_path), str(config_path))
        cfg.train.device = "cpu"  # the views' images only; a synthetic scene is generated on the CPU then
        scene = load_scene_for(cfg)
    except (OSError, ValueError, RuntimeError) as e:  # SceneError, DatasetNotFoundError, ConfigError among them
        run.notes.append(f"the run's scene cannot be loaded here, so its cameras are not shown ({e})")
        return
    run.train, run.test = _views(scene.train), _views(scene.test)
    from warpgs.train import background_colour

    run.background = tuple(background_colour(cfg, scene))


# ----------------------------------------------------------------------------------------------
# rendering


def pinhole(fov_y: float, width: int, height: int) -> np.ndarray:
    """K of a camera with vertical field of view ``fov_y`` (radians), square pixels, centred."""
    f = 0.5 * height / math.tan(0.5 * fov_y)
    return np.array([[f, 0.0, 0.5 * width], [0.0, f, 0.5 * height], [0.0, 0.0, 1.0]])


def viewmat_from_pose(wxyz, position) -> np.ndarray:
    """World-to-camera 4x4 of a camera at ``position`` with orientation ``wxyz`` (camera to world, OpenCV axes:
    viser's camera frame)."""
    return pose(quat_to_rotmat(np.asarray(wxyz, np.float64)), position)


def pose_from_viewmat(viewmat) -> tuple[np.ndarray, np.ndarray]:
    """(wxyz, position) of the camera with world-to-camera ``viewmat``, for viser."""
    vm = np.asarray(viewmat, np.float64)
    return rotmat_to_quat(vm[:3, :3].T), camera_centres(vm)


def fit_size(width: int, height: int, longest: int) -> tuple[int, int]:
    """(w, h) with the aspect of width x height and the longest side at most ``longest`` (at least 1 px)."""
    s = min(1.0, longest / max(width, height, 1))
    return max(1, round(width * s)), max(1, round(height * s))


def _turbo(x: np.ndarray) -> np.ndarray:
    import matplotlib

    return matplotlib.colormaps["turbo"](np.clip(x, 0.0, 1.0))[..., :3].astype(np.float32)


def render_image(model: GaussianModel, viewmat, K, width: int, height: int, mode: str = "rgb",
                 background=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The viewer's frame: [H, W, 3] uint8 of ``model`` seen by (viewmat, K) through warpgs's rasterizer, in
    ``mode`` (rgb / depth / alpha; see the module's docstring). ``background``: an RGB colour, or a far field
    (anything with ``image(viewmat, K, width, height)``, ``Run.backdrop``)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    dev = model.device
    vm = torch.as_tensor(np.asarray(viewmat, np.float32), device=dev)
    k = torch.as_tensor(np.asarray(K, np.float32), device=dev)
    if mode == "rgb" and hasattr(background, "image"):  # a far field: a colour per pixel
        bg = background.image(vm, k, int(width), int(height)).to(dev)
    else:
        bg = torch.tensor(background if mode == "rgb" else (0.0, 0.0, 0.0), dtype=torch.float32, device=dev)
    with torch.no_grad():
        out = model.render(vm, k, int(width), int(height), background=bg, check_finite=False)
        if mode == "rgb":
            img = (out.image.clamp(0, 1) * 255.0 + 0.5).to(torch.uint8)
            return img.cpu().numpy()
        alpha = out.alpha.float().cpu().numpy()
        if mode == "alpha":
            return np.repeat((np.clip(alpha, 0, 1) * 255.0 + 0.5).astype(np.uint8)[..., None], 3, axis=2)
        depth = out.depth.float().cpu().numpy()  # expected depth, sum(w z) / alpha
    covered = alpha > 0.5
    img = np.zeros((*alpha.shape, 3), np.float32)
    if covered.any():
        lo, hi = np.percentile(depth[covered], [2, 98])
        img = _turbo((depth - lo) / max(hi - lo, 1e-9)) * np.clip(alpha, 0, 1)[..., None]
    return (img * 255.0 + 0.5).astype(np.uint8)


class FrameLoop:
    """Renders one browser's frames on its own thread. ``request(moving=True)`` after each camera move:
    the loop renders the camera as it is when a render starts (moves during a render are merged into the
    next frame, never queued), at ``preview_res`` while moving, then once at ``res`` when the camera has been
    still for ``settle_s``. ``camera()`` -> (viewmat, fov_y, canvas width, canvas height) or None;
    ``send(image, final)`` shows a frame. ``frames`` (sent so far), ``last`` (image), ``last_viewmat`` and
    ``last_final`` are kept for tests and benchmarks."""

    def __init__(self, viewer: "Viewer", camera, send, settle_s: float = 0.25):
        self.viewer, self.camera, self.send, self.settle_s = viewer, camera, send, settle_s
        self.frames = 0
        self.last: np.ndarray | None = None
        self.last_viewmat: np.ndarray | None = None
        self.last_final = False
        self.last_render_s = 0.0
        self._moved_at = 0.0
        self._final_due = True
        self._event = threading.Event()
        self._running = True
        self._thread = threading.Thread(target=self._loop, daemon=True, name="warpgs.view frames")
        self._thread.start()

    def request(self, moving: bool = True) -> None:
        if moving:
            self._moved_at = time.monotonic()
        self._final_due = True
        self._event.set()

    def stop(self) -> None:
        self._running = False
        self._event.set()

    def _loop(self) -> None:
        while self._running:
            woke = self._event.wait(0.05)
            self._event.clear()
            if not self._running:
                return
            still = time.monotonic() - self._moved_at >= self.settle_s
            if not woke and not (still and self._final_due):
                continue
            try:
                self.render_once(final=still)
            except Exception as e:  # a browser gone mid-frame, a failed render: said once, the loop goes on
                from warpgs.console import warn_once

                warn_once(f"warpgs.view: a frame failed ({type(e).__name__}: {e})", key=f"view-frame-{type(e).__name__}")

    def render_once(self, final: bool = True) -> np.ndarray | None:
        if final:  # before the camera is read: a move that arrives after that asks for another full frame
            self._final_due = False
        cam = self.camera()
        if cam is None:
            self._final_due = self._final_due or final
            return None
        viewmat, fov_y, cw, ch = cam
        v = self.viewer
        w, h = fit_size(cw, ch, v.res if final else v.preview_res)
        t0 = time.perf_counter()
        with v.lock:
            img = render_image(v.run.model, viewmat, pinhole(fov_y, w, h), w, h, v.mode, v.run.backdrop)
        self.last_render_s = time.perf_counter() - t0
        self.send(img, final)
        self.last, self.last_viewmat, self.last_final = img, viewmat, final
        self.frames += 1
        return img


# ----------------------------------------------------------------------------------------------
# the page


FRUSTUM_COLORS = {"train": (40, 110, 255), "test": (255, 140, 0), "pseudo": (170, 60, 200)}


def _thumbnail(image: np.ndarray | None, longest: int = 128) -> np.ndarray | None:
    if image is None:
        return None
    from PIL import Image

    h, w = image.shape[:2]
    tw, th = fit_size(w, h, longest)
    return np.asarray(Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)).resize((tw, th), Image.BILINEAR))


def scene_extent(run: Run) -> tuple[np.ndarray, float]:
    """(centre, size) of what the page shows: the cameras' spread when there are several, else the robust
    bounding box of the Gaussians."""
    views = run.train + run.test
    if len(views) >= 2:
        c = camera_centres(np.stack([v.viewmat for v in views]))
        size = float(np.linalg.norm(c - c.mean(0), axis=1).max())
        if size > 1e-6:
            return c.mean(0), size
    p = run.model.means.detach().cpu().numpy().astype(np.float64)
    if not len(p):
        return np.zeros(3), 1.0
    lo, hi = np.percentile(p, 2, axis=0), np.percentile(p, 98, axis=0)
    return 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)


class Viewer:
    """A viser server showing ``run``; ``url`` is where to open it, ``loops`` the connected browsers' frame
    loops (client id -> ``FrameLoop``), ``close()`` stops it. The panel's checkboxes are ``toggles`` ("train
    cameras", "test cameras", "cycle N pseudo" / "kept" / "added" / "removed"; setting ``.value`` acts as a
    click), the render mode menu ``mode_menu``. ``res`` / ``preview_res``: longest side of the
    still / moving frames (None: 1920 / 1920 on CUDA, 640 / 256 on the CPU)."""

    def __init__(self, run: Run, host: str = "0.0.0.0", port: int = 8080, res: int | None = None,
                 preview_res: int | None = None, settle_s: float = 0.25):
        import viser

        self.run = run
        cpu = run.model.device.type == "cpu"
        self.res = int(res or (640 if cpu else 1920))
        self.preview_res = int(preview_res or (min(256, self.res) if cpu else self.res))
        self.settle_s = settle_s
        self.mode = "rgb"
        self.lock = threading.Lock()
        self.loops: dict[int, FrameLoop] = {}
        self.host = host
        with contextlib.redirect_stdout(io.StringIO()):  # viser's own banner: main() prints one line instead
            self.server = viser.ViserServer(host=host, port=port, label="warpgs", verbose=False)
        self.port = self.server.get_port()
        self.centre, self.size = scene_extent(run)
        self._frusta: dict[str, list] = {"train": [], "test": []}
        self._frustum_of: dict[tuple[str, str], object] = {}
        self._hidden = None  # the frustum of the view jumped to last
        self._build_scene()
        self._build_panel()
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)

    @property
    def url(self) -> str:
        host = "localhost" if self.host in ("0.0.0.0", "", "::") else self.host
        return f"http://{host}:{self.port}"

    def close(self) -> None:
        for loop in list(self.loops.values()):
            loop.stop()
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()

    # the 3D scene ---------------------------------------------------------------------------------

    def _build_scene(self) -> None:
        scene, run = self.server.scene, self.run
        views = run.train + run.test
        if views:
            up = -np.mean([np.linalg.inv(v.viewmat)[:3, 1] for v in views], axis=0)  # OpenCV: y points down
            if np.linalg.norm(up) > 1e-6:
                scene.set_up_direction(up / np.linalg.norm(up))
            start = run.train[0] if run.train else views[0]
            self._initial(start.viewmat, start.fov_y)
        else:
            K, vm = default_camera(run.model.means.detach().cpu().numpy(), 960, 720)
            self._initial(vm, 2 * math.atan(360.0 / K[1, 1]))
        scale = 0.08 * self.size
        for kind, group in (("train", run.train), ("test", run.test)):
            for v in group:
                wxyz, pos = pose_from_viewmat(v.viewmat)
                handle = scene.add_camera_frustum(
                    f"/{kind}/{v.name}", fov=v.fov_y, aspect=v.width / v.height, scale=scale,
                    thickness=0.02 * scale, color=FRUSTUM_COLORS[kind], image=_thumbnail(v.image),
                    format="jpeg", wxyz=wxyz, position=pos)
                handle.on_click(lambda event, v=v, kind=kind: self.go_to(event.client, kind, v))
                self._frusta[kind].append(handle)
                self._frustum_of[(kind, v.name)] = handle
        self._cycle_nodes: dict[tuple[int, str], list] = {}
        for cyc in run.cycles:
            nodes = []
            for j, traj in enumerate(cyc.trajectories):
                centres = camera_centres(traj)
                if len(centres) >= 2:
                    nodes.append(scene.add_spline_catmull_rom(
                        f"/cycle_{cyc.index}/trajectory_{j}", points=centres, thickness=0.01 * scale,
                        color=FRUSTUM_COLORS["pseudo"], visible=False))
                for t, vm in enumerate(traj[1:-1], start=1):  # frames 0 and T-1 are the inputs themselves
                    wxyz, pos = pose_from_viewmat(vm)
                    nodes.append(scene.add_camera_frustum(
                        f"/cycle_{cyc.index}/trajectory_{j}/pseudo_{t}", fov=run.train[0].fov_y if run.train else 1.0,
                        aspect=run.train[0].width / run.train[0].height if run.train else 1.0, scale=0.4 * scale,
                        thickness=0.01 * scale, color=FRUSTUM_COLORS["pseudo"], wxyz=wxyz, position=pos, visible=False))
            self._cycle_nodes[(cyc.index, "pseudo")] = nodes
            if cyc.cloud is not None and cyc.cloud.get("origin") is not None:
                for k, name in enumerate(ORIGIN_NAMES):
                    sel = cyc.cloud["origin"] == k
                    pts = cyc.cloud["points"][sel]
                    self._cycle_nodes[(cyc.index, name)] = [scene.add_point_cloud(
                        f"/cycle_{cyc.index}/{name}", points=pts.astype(np.float32),
                        colors=tuple(int(255 * c) for c in ORIGIN_COLORS[k]), point_size=0.004 * self.size,
                        visible=False)] if len(pts) else []

    def _initial(self, viewmat, fov_y: float) -> None:
        wxyz, pos = pose_from_viewmat(viewmat)
        forward = quat_to_rotmat(wxyz)[:, 2]
        cam = self.server.initial_camera
        cam.position = pos
        cam.look_at = pos + forward * max(float(np.dot(self.centre - pos, forward)), 0.5 * self.size)
        cam.up = -quat_to_rotmat(wxyz)[:, 1]
        cam.fov = fov_y

    # the panel ------------------------------------------------------------------------------------

    def _build_panel(self) -> None:
        gui, run = self.server.gui, self.run
        self.toggles, self.targets = {}, {}
        gui.add_markdown(f"**{run.name}**: {len(run.model):,} Gaussians, {run.summary()}")
        with gui.add_folder("Render"):
            mode = self.mode_menu = gui.add_dropdown("mode", MODES, initial_value="rgb")
            res = gui.add_slider("resolution", min=64, max=4096, step=16, initial_value=self.res,
                                 hint="longest side of a still frame (moving: the preview resolution)")

            @mode.on_update
            def _(_event) -> None:
                self.mode = mode.value
                self.rerender()

            @res.on_update
            def _(_event) -> None:
                self.res = int(res.value)
                self.preview_res = min(self.preview_res, self.res)
                self.rerender()

        self.stats = gui.add_markdown("")
        self.compare = None
        if run.train or run.test:
            with gui.add_folder("Views"):
                for kind in ("train", "test"):
                    box = gui.add_checkbox(f"{kind} cameras ({len(self._frusta[kind])})", initial_value=True)
                    box.on_update(lambda _e, kind=kind, box=box: self._show(self._frusta[kind], box.value))
                    self.toggles[f"{kind} cameras"] = box
                self.targets = {f"{k}/{v.name}": (k, v) for k, group in (("train", run.train), ("test", run.test))
                                 for v in group}
                go = gui.add_dropdown("go to view", ["(free camera)"] + list(self.targets), initial_value="(free camera)")

                @go.on_update
                def _(event) -> None:
                    if go.value in self.targets and event.client is not None:
                        self.go_to(event.client, *self.targets[go.value])

                self.compare_caption = gui.add_markdown("pick a view: its render appears here beside its image")
                self.compare = gui.add_image(np.zeros((8, 16, 3), np.uint8))
        if run.cycles:
            with gui.add_folder("Cycles"):
                for cyc in run.cycles:
                    for part, label in (("pseudo", f"cycle {cyc.index}: pseudo views ({len(cyc.trajectories)} trajectories)"),
                                        *[(n, f"cycle {cyc.index}: {n} points") for n in ORIGIN_NAMES]):
                        nodes = self._cycle_nodes.get((cyc.index, part), [])
                        if not nodes:
                            continue
                        count = len(cyc.cloud["points"][cyc.cloud["origin"] == ORIGIN_NAMES.index(part)]) \
                            if part != "pseudo" else None
                        box = gui.add_checkbox(label + (f" ({count:,})" if count is not None else ""), initial_value=False)
                        box.on_update(lambda _e, nodes=nodes, box=box: self._show(nodes, box.value))
                        self.toggles[f"cycle {cyc.index} {part}"] = box

    @staticmethod
    def _show(nodes, visible: bool) -> None:
        for n in nodes:
            n.visible = visible

    def go_to(self, client, kind: str, view: View) -> None:
        """Moves ``client``'s camera to ``view`` and shows its render beside its image in the panel."""
        wxyz, pos = pose_from_viewmat(view.viewmat)
        # from inside its own frustum the view would see that frustum's image instead of the render
        previous, self._hidden = self._hidden, self._frustum_of.get((kind, view.name))
        if previous is not None and previous is not self._hidden:
            previous.visible = self.toggles[f"{previous.name.split('/')[1]} cameras"].value
        if self._hidden is not None:
            self._hidden.visible = False
        with client.atomic():
            client.camera.fov = view.fov_y
            client.camera.position = pos
            client.camera.wxyz = wxyz
        if self.compare is not None and view.image is not None:
            w, h = fit_size(view.width, view.height, 512)
            K = view.K.copy()
            K[:2] *= np.array([w / view.width, h / view.height])[:, None]
            with self.lock:
                img = render_image(self.run.model, view.viewmat, K, w, h, "rgb", self.run.backdrop)
            self.compare.image = np.concatenate([img, _thumbnail(view.image, max(w, h))[:h, :w]], axis=1)
            self.compare_caption.content = f"{kind} view `{view.name}`: render | {'ground truth' if kind == 'test' else 'input'}"

    # browsers -------------------------------------------------------------------------------------

    def rerender(self) -> None:
        for loop in list(self.loops.values()):
            loop.request(moving=False)

    def _connect(self, client) -> None:
        def camera():
            c = client.camera
            try:
                return viewmat_from_pose(c.wxyz, c.position), float(c.fov), int(c.image_width), int(c.image_height)
            except AssertionError:  # no camera message from this browser yet
                return None

        def send(img, final):
            client.scene.set_background_image(img, format="jpeg", jpeg_quality=85 if final else 60)
            loop = self.loops.get(client.client_id)
            if final and loop is not None:
                self.stats.content = (f"{img.shape[1]}x{img.shape[0]} in {1000 * loop.last_render_s:.0f} ms "
                                      f"({self.run.model.device.type})")

        loop = FrameLoop(self, camera, send, self.settle_s)
        self.loops[client.client_id] = loop
        client.camera.on_update(lambda _cam: loop.request(moving=True))
        loop.request(moving=False)

    def _disconnect(self, client) -> None:
        loop = self.loops.pop(client.client_id, None)
        if loop is not None:
            loop.stop()


# ----------------------------------------------------------------------------------------------
# command line


def build_parser() -> argparse.ArgumentParser:
    ap = OneLineParser(prog="python -m warpgs.view", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", help="a run folder (point_cloud.ply, config.yaml, cycle_N/) or a 3D-GS PLY")
    ap.add_argument("--host", default="0.0.0.0", help="address to listen on (default 0.0.0.0: every interface)")
    ap.add_argument("--port", type=int, default=8080, help="port (default 8080; the next free one if taken)")
    ap.add_argument("--device", default="auto", help="auto (CUDA when there is one), cpu or cuda")
    ap.add_argument("--res", type=int, default=None, help="longest side of a still frame (default 1920 CUDA, 640 CPU)")
    ap.add_argument("--preview-res", type=int, default=None,
                    help="longest side while the camera moves (default: --res on CUDA, 256 on the CPU)")
    ap.add_argument("--no-cameras", action="store_true", help="do not load the run's scene (model and cycles only)")
    return ap


def main(argv=None) -> int:
    """The command line: bad input ends in one line, ``error: ...``, exit code 2; Ctrl-C stops the server."""
    a = build_parser().parse_args(argv)
    try:
        importlib.import_module("viser")
    except ImportError:
        print(f"error: the viewer needs viser, which is not installed: {VISER_HINT}", file=sys.stderr)
        return 2
    from warpgs.train import resolve_device

    try:
        if a.port < 0 or a.port > 65535:
            raise ValueError(f"--port {a.port}: not a port number (0..65535)")
        if (a.res is not None and a.res < 16) or (a.preview_res is not None and a.preview_res < 16):
            raise ValueError("--res and --preview-res are pixel counts >= 16")
        device = resolve_device(a.device)
        run = load_run(a.run, device=device, cameras=not a.no_cameras)
        viewer = Viewer(run, host=a.host, port=a.port, res=a.res, preview_res=a.preview_res)
    except (OSError, ValueError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for note in run.notes:
        print(f"warpgs.view: note: {note}", file=sys.stderr)
    if a.port and viewer.port != a.port:
        print(f"warpgs.view: note: port {a.port} is taken; serving on port {viewer.port} instead", file=sys.stderr)
    print(f"warpgs.view: open {viewer.url} ({len(run.model):,} Gaussians on {device.type}, {run.summary()}; "
          "Ctrl-C stops)", flush=True)
    # Ctrl-C (and SIGTERM) by a handler of our own, installed after the libraries are loaded: one of them can
    # leave SIGINT without Python's KeyboardInterrupt (in a fresh environment's first CI run the viewer once did not
    # stop within 120 s of Ctrl-C, printing nothing)
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        while not stop.is_set():
            time.sleep(0.2)
        return 0
    except KeyboardInterrupt:
        return 0
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        # viser's server can take long to stop (an open websocket, its thread pool): Ctrl-C must still end the
        # command, so the stop gets CLOSE_WAIT_S and the process exits without waiting on its threads (below)
        closer = threading.Thread(target=viewer.close, daemon=True, name="warpgs.view close")
        closer.start()
        closer.join(CLOSE_WAIT_S)


def _exit(code: int) -> None:
    """Ends the command with ``code`` once its output is flushed, without joining the threads viser may leave
    (interpreter exit joins non-daemon threads and thread pools, which can hang after a Ctrl-C)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    _exit(main())
