"""A protocol-following viewer for tests and benchmarks: rebuilds the grid from a snapshot and deltas only."""

from __future__ import annotations

import asyncio
import base64
import json
import threading
import time
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray
from websockets.asyncio.client import ClientConnection, connect

GREY = 2
TERMINAL = {"finished", "stopped", "error", "interrupted"}
T = TypeVar("T")


def wait_for(predicate: Callable[[], object], timeout_s: float = 60.0) -> None:
    """Poll ``predicate`` every 50 ms until it is true; fail the test after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached in time"
        time.sleep(0.05)


def wait_ended(api: Any, run_id: str, timeout_s: float = 90.0) -> dict[str, Any]:
    """Poll ``GET /api/runs/{id}`` (``api``: an httpx client on the service) until the run has ended."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        run = api.get(f"/api/runs/{run_id}").json()
        if run["status"] not in ("queued", "running"):
            return dict(run)
        time.sleep(0.05)
    raise AssertionError(f"run {run_id} did not end within {timeout_s} s")


def run_async(coro: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run`` on a thread of its own: it works even when the calling thread already runs an
    event loop (Playwright's sync API, used by the browser tests in the same session, leaves one)."""
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["result"] = asyncio.run(coro)
        except BaseException as exc:
            box["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join()
    if "error" in box:
        raise box["error"]
    return box["result"]  # type: ignore[no-any-return]


def decode_cells(b64: str, rows: int, cols: int) -> NDArray[np.uint8]:
    return np.frombuffer(base64.b64decode(b64), dtype=np.uint8).reshape(rows, cols).copy()


def csv_codes(text: str) -> NDArray[np.uint8]:
    """``map.csv`` as wire codes: 1 black, 0 white, empty grey (2)."""
    rows = [line.split(",") for line in text.rstrip("\n").split("\n")]
    return np.array([[GREY if v == "" else int(v) for v in row] for row in rows], dtype=np.uint8)


# What a step carries only when it changed since the step before (docs/protocol.md), and where a viewer keeps it.
SNAPSHOT_FIELDS = ("pose", "sweep", "target", "action", "metrics")
PROGRESS_FIELDS = {"t_s": "sim_time_s", "explored": "explored", "frontier": "frontier"}


@dataclass
class Viewer:
    """What one viewer saw. ``grid`` is None until the first snapshot; ``view`` holds the latest pose
    ([x mm, y mm, theta mrad]), sweep [cm], target [mm], action, progress and metrics, as sent."""

    hello: dict[str, Any] | None = None
    grid: NDArray[np.uint8] | None = None
    view: dict[str, Any] = field(default_factory=dict)
    trail: list[list[int]] = field(default_factory=list)
    seq: int = -1
    snapshots: int = 0
    steps: int = 0  # step messages applied
    merged_steps: int = 0  # step messages that stood for several steps
    resyncs: int = 0
    statuses: list[dict[str, Any]] = field(default_factory=list)
    last_snapshot: dict[str, Any] | None = None
    close_code: int | None = None
    bytes_received: int = 0
    latencies_s: list[float] = field(default_factory=list)  # step end to arrival (wall clock; ?timing=1)
    waiting_for_snapshot: bool = True

    @property
    def final_status(self) -> dict[str, Any] | None:
        ended = [s for s in self.statuses if s.get("event") in TERMINAL]
        return ended[-1] if ended else None

    async def handle(self, ws: ClientConnection, raw: str | bytes) -> None:
        """Apply one server message as docs/protocol.md tells a client to."""
        self.bytes_received += len(raw)
        msg = json.loads(raw)
        kind = msg["type"]
        if kind == "hello":
            self.hello = msg
        elif kind == "snapshot":
            g = msg["grid"]
            self.grid = decode_cells(msg["cells"], g["rows"], g["cols"])
            self.view = {key: msg[key] for key in SNAPSHOT_FIELDS}
            self.view["progress"] = dict(msg["progress"])
            self.trail = list(msg["trail"])
            self.seq = msg["seq"]
            self.snapshots += 1
            self.last_snapshot = msg
            self.waiting_for_snapshot = False
        elif kind == "step":
            if "wall_time" in msg:
                self.latencies_s.append(time.time() - msg["wall_time"])
            if self.waiting_for_snapshot or self.grid is None:
                return
            if msg["seq"] - msg.get("merged", 1) != self.seq:  # a merged step continues from seq - merged
                self.resyncs += 1
                self.waiting_for_snapshot = True
                await ws.send(json.dumps({"type": "resync"}))
                return
            for r, c, code in msg.get("cells", []):
                self.grid[r, c] = code
            for key in SNAPSHOT_FIELDS:
                if key in msg:
                    self.view[key] = msg[key]
            progress = self.view["progress"]
            progress["step"] = msg.get("step", msg["seq"])
            for key, name in PROGRESS_FIELDS.items():
                if key in msg:
                    progress[name] = msg[key]
            self.trail.extend(msg.get("trail") or ())  # a merged step: the ends of the steps before its last
            if self.view["pose"] is not None:
                self.trail.append(self.view["pose"][:2])
            self.seq = msg["seq"]
            self.steps += 1
            self.merged_steps += 1 if msg.get("merged") else 0
        elif kind == "status":
            self.statuses.append(msg)


async def watch(
    url: str,
    *,
    timeout_s: float = 60.0,
    on_message: Callable[[Viewer, dict[str, Any], ClientConnection], Awaitable[None]] | None = None,
    read_delay_s: float = 0.0,
    headers: dict[str, str] | None = None,
    until: Callable[[Viewer], bool] | None = None,
) -> Viewer:
    """Watch a run until the server closes the socket (or ``until`` says so); every wait is bounded."""
    viewer = Viewer()
    async with asyncio.timeout(timeout_s):
        async with connect(url, max_size=None, compression=None, additional_headers=headers) as ws:
            try:
                async for raw in ws:
                    await viewer.handle(ws, raw)
                    if on_message is not None:
                        await on_message(viewer, json.loads(raw), ws)
                    if until is not None and until(viewer):
                        return viewer
                    if read_delay_s:
                        await asyncio.sleep(read_delay_s)
            finally:
                viewer.close_code = ws.close_code
    return viewer
