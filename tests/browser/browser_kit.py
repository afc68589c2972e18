"""Helpers for the browser tests: the service in a child process, Chromium, the page and its pixels."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 15.0
VIEWPORT = {"width": 1280, "height": 900}


# -- Chromium --------------------------------------------------------------------------------------
def find_chromium() -> str | None:
    explicit = os.environ.get("SONARSLAM_CHROMIUM")
    if explicit:
        return explicit if os.access(explicit, os.X_OK) else None
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if os.access("/usr/bin/chromium", os.X_OK) else None


def unavailable(reason: str) -> NoReturn:
    """Skip on a developer machine; fail under CI, where a missing browser is a broken set-up."""
    if os.environ.get("CI"):
        pytest.fail(f"browser tests cannot run under CI: {reason}", pytrace=False)
    pytest.skip(f"browser tests skipped: {reason} (install Debian's chromium or set SONARSLAM_CHROMIUM)")


# -- the service -----------------------------------------------------------------------------------
def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Service:
    """``sonarslam serve`` in a child process on 127.0.0.1; restartable on the same port and data dir."""

    data_dir: Path
    log_path: Path
    port: int = field(default_factory=free_port)
    extra_args: tuple[str, ...] = ()
    extra_env: dict[str, str] = field(default_factory=dict)
    proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> None:
        env = {k: v for k, v in os.environ.items() if not k.startswith("SONARSLAM_")}
        env.update(self.extra_env)
        cmd = [sys.executable, "-m", "robot", "serve", "--host", "127.0.0.1", "--port", str(self.port),
               "--data-dir", str(self.data_dir), *self.extra_args]  # fmt: skip
        with open(self.log_path, "ab") as log:
            self.proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the service exited with {self.proc.returncode}:\n{self.log()}")
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{self.url}/api/health", timeout=1.0).status_code == 200:
                    return
            time.sleep(0.1)
        self.stop()
        raise RuntimeError(f"the service did not answer within {START_TIMEOUT_S} s:\n{self.log()}")

    def stop(self, crash: bool = False) -> None:
        """Shut down (SIGTERM, as an operator would) or, with ``crash``, kill at once (SIGKILL)."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL if crash else signal.SIGTERM)
            try:
                self.proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(STOP_TIMEOUT_S)
        self.proc = None

    def restart(self, crash: bool = False) -> None:
        self.stop(crash=crash)
        self.start()

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-4000:]
        except OSError:
            return ""

    def api(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        return httpx.request(method, f"{self.url}{path}", timeout=30.0, **kwargs)


class LinkCutter:
    """A TCP relay in front of the service, so a test can cut every open connection at once, as a
    network failure or a proxy restart would, while the service itself (and its session) lives on.
    While ``hold()`` is on, new connections wait unanswered, so the page stays visibly reconnecting."""

    def __init__(self, upstream_port: int) -> None:
        self.upstream_port = upstream_port
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = int(self.listener.getsockname()[1])
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._released = threading.Event()
        self._released.set()
        self._closed = False
        threading.Thread(target=self._accept, daemon=True).start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def hold(self) -> None:
        self._released.clear()

    def release(self) -> None:
        self._released.set()

    def cut(self) -> None:
        """Reset every relayed connection (both directions)."""
        with self._lock:
            doomed = list(self._open)
            self._open.clear()
        for s in doomed:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()

    def close(self) -> None:
        self._closed = True
        self._released.set()
        self.listener.close()
        self.cut()

    def _accept(self) -> None:
        while not self._closed:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            threading.Thread(target=self._relay, args=(client,), daemon=True).start()

    def _relay(self, client: socket.socket) -> None:
        self._released.wait(STOP_TIMEOUT_S)
        try:
            upstream = socket.create_connection(("127.0.0.1", self.upstream_port), timeout=5)
        except OSError:
            client.close()
            return
        upstream.settimeout(None)
        with self._lock:
            self._open.update((client, upstream))
        for a, b in ((client, upstream), (upstream, client)):
            threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := src.recv(65536):
                dst.sendall(data)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                with contextlib.suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)


# -- the page ----------------------------------------------------------------------------------------
@dataclass
class ConsoleWatch:
    """Every console error and uncaught exception of a page. Browser network errors that match an
    ``allow`` pattern (while a test deliberately takes the service away) are kept apart."""

    errors: list[str] = field(default_factory=list)
    tolerated: list[str] = field(default_factory=list)
    allow: list[Callable[[str], bool]] = field(default_factory=list)

    def on_console(self, msg: Any) -> None:
        if msg.type != "error":
            return
        text = f"{msg.text} @ {msg.location.get('url', '')}"
        if any(rule(msg.text) for rule in self.allow):
            self.tolerated.append(text)
        else:
            self.errors.append(text)

    def on_page_error(self, exc: Any) -> None:
        self.errors.append(f"uncaught: {exc}")


CODE_OF_CSV = {"1": 1, "0": 0, "": 2}


def parse_map_csv(text: str) -> list[list[int]]:
    """map.csv (SPEC §4) as rows of wire codes: 1 occupied, 0 free, 2 unknown (empty field)."""
    return [[CODE_OF_CSV[f.strip()] for f in line.split(",")] for line in text.splitlines() if line.strip() != ""]


def classify_pixel(rgb: tuple[int, ...]) -> int | None:
    """A map pixel as a cell code, or None when it is none of black, white and grey 128."""
    r, g, b = rgb[:3]
    if max(r, g, b) - min(r, g, b) > 24:
        return None  # tinted: an overlay, not a bare cell
    lum = (r + g + b) / 3
    if lum < 40:
        return 1
    if lum > 215:
        return 0
    if 108 <= lum <= 148:
        return 2
    return None


class Dashboard:
    """The page under test, with the few steps the tests share."""

    def __init__(self, page: Any, service: Service, console: ConsoleWatch) -> None:
        self.page = page
        self.service = service
        self.console = console

    def open(self, fragment: str = "", base_url: str | None = None) -> None:
        """Load the page from the service (or from ``base_url``, e.g. a LinkCutter in front of it)."""
        self.page.goto(f"{base_url or self.service.url}/{fragment}")
        self.page.wait_for_function("() => window.sonarslam && document.querySelector('#world option')")

    def state(self) -> dict[str, Any]:
        return dict(self.page.evaluate("window.sonarslam.state()"))

    def wait_for(self, js: str, timeout_s: float = 20.0) -> None:
        self.page.wait_for_function(js, timeout=timeout_s * 1000)

    def wait_state(self, predicate: str, timeout_s: float = 20.0) -> dict[str, Any]:
        """Wait until the JS ``predicate`` (e.g. ``s => s.steps > 2``) holds for the hook's state."""
        self.wait_for(f"({predicate})(window.sonarslam.state())", timeout_s)
        return self.state()

    def start_run(self, world: str = "room2", speed: str = "50", seed: int = 0) -> str:
        page = self.page
        page.get_by_label("World", exact=True).select_option(world)
        page.get_by_label("Speed (times real time)", exact=True).select_option(speed)
        page.get_by_label("Seed", exact=True).fill(str(seed))
        before = self.state()
        page.get_by_role("button", name="Start run").click()
        state = self.wait_state(
            f"s => s.runId !== {json.dumps(before['runId'])} && s.snapshots > {before['snapshots']}"
        )
        return str(state["runId"])

    def show_layers(self, **layers: bool) -> None:
        for name, on in layers.items():
            box = self.page.locator(f"#layer-{name}")
            if box.is_enabled():
                box.set_checked(on)

    def hide_overlays(self) -> None:
        self.show_layers(robot=False, trail=False, beams=False, target=False, truth=False)

    def screenshot_rgb(self) -> Any:
        from PIL import Image

        return Image.open(io.BytesIO(self.page.screenshot())).convert("RGB")

    def sample_cells(self) -> dict[tuple[int, int], int | None]:
        """Read every cell's colour off the screen at the centre the page reports for it."""
        self.page.locator("#map").scroll_into_view_if_needed()
        grid = self.state()["grid"]
        points = self.page.evaluate(
            """([rows, cols]) => {
                const out = [];
                for (let r = 0; r < rows; r += 1)
                  for (let c = 0; c < cols; c += 1) out.push([r, c, window.sonarslam.cellToClient(r, c)]);
                return out;
            }""",
            [grid["rows"], grid["cols"]],
        )
        dpr = float(self.page.evaluate("window.devicePixelRatio"))
        img = self.screenshot_rgb()
        out: dict[tuple[int, int], int | None] = {}
        for r, c, p in points:
            x, y = int(p["x"] * dpr), int(p["y"] * dpr)
            out[(r, c)] = classify_pixel(img.getpixel((x, y))) if 0 <= x < img.width and 0 <= y < img.height else None
        return out

    def pixel_at_world(self, x: float, y: float) -> tuple[int, int, int]:
        p = self.page.evaluate("([x, y]) => window.sonarslam.worldToClient(x, y)", [x, y])
        dpr = float(self.page.evaluate("window.devicePixelRatio"))
        img = self.screenshot_rgb()
        return tuple(img.getpixel((int(p["x"] * dpr), int(p["y"] * dpr))))  # type: ignore[return-value]

    def assert_no_console_errors(self) -> None:
        assert self.console.errors == [], "the page logged errors:\n" + "\n".join(self.console.errors)


def wait_until(check: Callable[[], Any], timeout_s: float, what: str, every_s: float = 0.25) -> Any:
    """Poll ``check`` until it returns something truthy; fail naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(every_s)
