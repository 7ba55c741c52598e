"""A screenshot of the web viewer (``python -m warpgs.view``) on a run, taken in headless Chromium.

    python bench/diagnostics/viewer_screenshot.py outputs/castle6_full --out bench/results/viewer/castle_p30_cpu.png --show added
    python bench/diagnostics/viewer_screenshot.py outputs/lego --out bench/results/viewer/lego_cuda.png --view test/r_0

Starts a ``warpgs.view.Viewer`` on RUN (a run folder or a 3D-GS PLY), opens it in Chromium through
playwright (the browser of ``$WARPGS_CHROMIUM``, ``chromium-headless-shell`` or ``chromium``; no
``playwright install``), optionally turns on panel toggles (``--show added`` turns on "cycle N added" of
every cycle; also ``pseudo``, ``kept``, ``removed``, ``test cameras`` ...) and jumps to a view (``--view
test/NAME``, as in the panel's list; ``--back`` then steps back from it), waits for a full-resolution frame that has been on screen for a
moment, and saves the page.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from warpgs.train import resolve_device  # noqa: E402
from warpgs.view import Viewer, load_run  # noqa: E402


def chromium() -> str:
    for c in (os.environ.get("WARPGS_CHROMIUM"), shutil.which("chromium-headless-shell"), shutil.which("chromium")):
        if c and Path(c).is_file():
            return c
    raise SystemExit("error: no Chromium: apt-get install chromium-headless-shell, or set WARPGS_CHROMIUM")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("--out", required=True)
    ap.add_argument("--size", default="1280x800", help="browser window WIDTHxHEIGHT")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--res", type=int, default=None, help="longest side of the frame (default: the window's)")
    ap.add_argument("--show", action="append", default=[], help="toggle to turn on (repeatable): a panel name, or "
                    "pseudo / kept / added / removed for every cycle")
    ap.add_argument("--view", default=None, help="jump to this view of the panel's list (e.g. test/0008)")
    ap.add_argument("--back", type=float, default=0.0,
                    help="then move the camera back along its axis by this many scene sizes (shows the cameras)")
    ap.add_argument("--wait", type=float, default=600.0, help="seconds to wait for the frame")
    a = ap.parse_args(argv)
    from playwright.sync_api import sync_playwright

    width, height = (int(v) for v in a.size.lower().split("x"))
    run = load_run(a.run, device=resolve_device(a.device))
    res = a.res or max(width, height)
    viewer = Viewer(run, host="127.0.0.1", port=0, res=res, preview_res=res)
    for name in a.show:
        hits = [k for k in viewer.toggles if k == name or k.endswith(f" {name}")]
        if not hits:
            raise SystemExit(f"error: no toggle {name!r}; there are {sorted(viewer.toggles)}")
        for k in hits:
            viewer.toggles[k].value = True
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium(), args=[
                "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"])
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(viewer.url)
            t0 = time.monotonic()
            while not viewer.loops and time.monotonic() - t0 < 60:
                time.sleep(0.1)
            (client_id, loop), = viewer.loops.items()
            if a.view:
                while loop.frames == 0 and time.monotonic() - t0 < a.wait:
                    time.sleep(0.1)
                viewer.go_to(viewer.server.get_clients()[client_id], *viewer.targets[a.view])
            if a.back:
                cam = viewer.server.get_clients()[client_id].camera
                forward = np.asarray(cam.look_at) - np.asarray(cam.position)
                cam.position = np.asarray(cam.position) - a.back * viewer.size * forward / np.linalg.norm(forward)
            n, seen, since = loop.frames, None, time.monotonic()
            while time.monotonic() - t0 < a.wait:
                key = (loop.frames, loop.last_final)
                if key != seen:
                    seen, since = key, time.monotonic()
                if loop.frames > n and loop.last_final and time.monotonic() - since > 2.0:
                    break
                time.sleep(0.1)
            # the browser's "software WebGL" notice (a headless machine has no GPU for the page) is not the viewer's
            page.add_style_tag(content=".mantine-Notifications-root { display: none !important; }")
            page.wait_for_timeout(300)
            Path(a.out).parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=a.out)
            browser.close()
    finally:
        viewer.close()
    print(f"wrote {a.out} ({width}x{height}; frame {loop.last.shape[1]}x{loop.last.shape[0]} in "
          f"{loop.last_render_s:.2f} s on {run.model.device.type})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
