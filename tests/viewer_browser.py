"""Driving the 3D viewer in headless Chromium (Debian's package) with playwright, for tests/test_viewer.py; run
as a script it writes the README's screenshot of the viewer on a finished run:

    python tests/viewer_browser.py results/ docs/images/viewer.png [--task placing]

The browser gets software WebGL (SwiftShader) and no network beyond loopback; every request it makes is
recorded so that a test can check that nothing left the machine.
"""

from __future__ import annotations

import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

REPO = Path(__file__).resolve().parent.parent
#: Headless Chromium without the background services that would try the (closed) network, with software GL.
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]
#: viser's "software WebGL" notice would cover part of the canvas in a screenshot
HIDE_NOTICES = ".mantine-Notifications-root { display: none !important; }"
VIEWPORT = {"width": 1600, "height": 900}
LOCAL = re.compile(r"^(https?|wss?)://(127\.0\.0\.1|localhost|\[::1\])(:\d+)?/|^(blob|data|file):")


def chromium() -> str | None:
    """Debian's chromium, if installed."""
    return shutil.which("chromium") or (os.path.exists("/usr/bin/chromium") and "/usr/bin/chromium") or None


@contextmanager
def browser() -> Iterator:
    """A headless Chromium (playwright's sync API) with a fresh profile."""
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="tohgs-chromium-") as profile, sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(profile, executable_path=chromium(), args=FLAGS,
                                                  viewport=VIEWPORT, headless=True)
        try:
            yield ctx
        finally:
            ctx.close()


def open_page(ctx, url: str, requests: list[str]):
    """A page of ``url`` whose requests are appended to ``requests``, notices hidden."""
    blank = [p for p in ctx.pages if p.url == "about:blank"]
    page = blank[0] if blank else ctx.new_page()
    page.on("request", lambda r: requests.append(r.url))
    page.goto(url)
    page.add_style_tag(content=HIDE_NOTICES)
    return page


def outside(requests: list[str]) -> list[str]:
    """The requests that were not to loopback, a blob, a data URL or a local file."""
    return [u for u in requests if not LOCAL.match(u)]


def canvas_image(page) -> np.ndarray:
    """(H, W, 3) uint8 screenshot of the page's (first) canvas: the 3D view (the mouse in a corner first, so
    that no control's hint covers it)."""
    from PIL import Image

    page.mouse.move(1, 1)
    png = page.locator("canvas").first.screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def save(img: np.ndarray, path: str | Path) -> None:
    """Write an (H, W, 3) uint8 screenshot as a PNG."""
    from PIL import Image

    Image.fromarray(img).save(path)


def scene_fraction(img: np.ndarray, background: tuple[int, int, int] = (255, 255, 255), tol: int = 10) -> float:
    """The fraction of pixels that differ from viser's white background by more than ``tol`` in some channel:
    what the scene covers (an empty or unrendered canvas: 0)."""
    return float((np.abs(img.astype(int) - np.asarray(background)).max(-1) > tol).mean())


def changed(a: np.ndarray, b: np.ndarray, tol: int = 24) -> float:
    """The fraction of pixels that differ between two screenshots by more than ``tol``."""
    if a.shape != b.shape:
        return 1.0
    return float((np.abs(a.astype(int) - b.astype(int)).max(-1) > tol).mean())


def wait_for_scene(page, min_fraction: float = 0.05, timeout: float = 60.0, settle: float = 1.5) -> np.ndarray:
    """Poll the canvas until the scene covers ``min_fraction`` of it and two shots ``settle`` s apart agree;
    returns the last shot (the last one also when the time runs out, for the caller's assertion)."""
    end = time.monotonic() + timeout
    last = canvas_image(page)
    while time.monotonic() < end:
        page.wait_for_timeout(settle * 1000)
        shot = canvas_image(page)
        if scene_fraction(shot) >= min_fraction and changed(shot, last) < 0.002:
            return shot
        last = shot
    return last


def wait_for_change(page, before: np.ndarray, min_change: float = 0.01, timeout: float = 30.0) -> np.ndarray:
    """Poll the canvas until it differs from ``before`` on ``min_change`` of its pixels and has settled."""
    end = time.monotonic() + timeout
    shot = canvas_image(page)
    while time.monotonic() < end:
        page.wait_for_timeout(1000)
        new = canvas_image(page)
        if changed(new, before) >= min_change and changed(new, shot) < 0.002:
            return new
        shot = new
    return shot


def start_viewer(results: str | Path, task: str, stop_after: float = 300.0, timeout: float = 120.0
                 ) -> tuple[subprocess.Popen, str, float]:
    """``python -m tohgs.viz.view results --task task --port 0 --stop-after stop_after`` in a subprocess;
    returns it, its URL and the seconds until it said it was ready (it fails the caller's way when it exits
    first or stays silent for ``timeout`` s)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    cmd = [sys.executable, "-m", "tohgs.viz.view", str(results), "--task", task, "--port", "0",
           "--stop-after", str(stop_after)]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    lines = []
    while time.monotonic() - t0 < timeout:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        m = re.search(r"tohgs viewer of .* at (http://\S+)", line)
        if m:
            return proc, m.group(1), time.monotonic() - t0
    proc.kill()
    raise RuntimeError(f"the viewer did not start ({' '.join(cmd)}): {''.join(lines)[-3000:]}")


def screenshot(results: str | Path, out: str | Path, task: str = "placing", width: int = 1000) -> None:
    """The README's picture: the viewer on ``results`` at its start, the whole page (panel and scene), as a PNG
    ``width`` pixels wide."""
    from PIL import Image

    proc, url, _ = start_viewer(results, task)
    try:
        with browser() as ctx:
            page = open_page(ctx, url, [])
            wait_for_scene(page)
            png = page.screenshot()
    finally:
        proc.terminate()
        proc.wait(30)
    img = Image.open(io.BytesIO(png)).convert("RGB")
    img = img.resize((width, round(img.height * width / img.width)), Image.LANCZOS)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    img.save(out, optimize=True)
    print(f"wrote {out} ({Path(out).stat().st_size // 1024} KB)")


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description="Write the README's screenshot of the viewer.")
    ap.add_argument("results")
    ap.add_argument("out")
    ap.add_argument("--task", default="placing")
    a = ap.parse_args()
    screenshot(a.results, a.out, a.task)
