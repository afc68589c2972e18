"""A run's live view on the event loop: the grid and pose as viewers see them, snapshots, and fan-out.

The run's body (in a child process, or on a thread for real hardware) never touches this object: its
handle (``server/session.py``) applies each of its messages here, on the loop. So the view changes only
between messages, and a snapshot taken here is exactly the state after ``seq``: the steps a new viewer
receives next continue it without gap or overlap.
"""

from __future__ import annotations

import base64
import time
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig
from robot.grid import GridSpec
from server.broadcast import TERMINAL_EVENTS, Broadcaster, Outgoing, Subscriber, Ticker
from server.wire import VIEW_FIELDS, apply_step, trail_wire, view_from_checkpoint

GREY = 2  # wire code of an unknown / inaccessible cell; white 0 and black 1 match the map states
TRAIL_LENGTH = 5000
PROGRESS_PERIOD_S = 1.0


def state_codes(states: NDArray[np.int8]) -> NDArray[np.uint8]:
    """Map states (-1 grey, 0 white, 1 black) as wire codes (2, 0, 1)."""
    return np.where(states < 0, GREY, states).astype(np.uint8)


def code_states(codes: NDArray[np.uint8]) -> NDArray[np.int8]:
    return np.where(codes == GREY, -1, codes).astype(np.int8)


def robot_view(robot: RobotConfig) -> dict[str, Any]:
    return {
        "radius_m": robot.radius_m,
        "beam_width_deg": robot.sonar.beam_width_deg,
        "max_range_m": robot.sonar.max_range_m,
        "sonars": [m.model_dump() for m in robot.sonars],
    }


def grid_view(grid: GridSpec) -> dict[str, Any]:
    return {
        "rows": grid.rows,
        "cols": grid.cols,
        "resolution": grid.resolution,
        "origin": [grid.origin_x, grid.origin_y],
    }


class LiveRun:
    """What viewers of one run see, updated in step order on the event loop."""

    def __init__(
        self,
        run: dict[str, Any],
        grid: GridSpec,
        robot: dict[str, Any] | None,
        truth: NDArray[np.int8] | None,
        queue_size: int,
        status: str = "queued",
    ) -> None:
        self.run = dict(run)  # id, world, mapper, hardware, resolution, speed, seed
        self.grid = grid
        self.robot = robot  # as robot_view() gives it
        self.truth_b64 = base64.b64encode(state_codes(truth).tobytes()).decode() if truth is not None else None
        self.queue_size = queue_size
        self.status = status
        self.terminated_by: str | None = None
        self.cells = np.full(grid.shape, GREY, dtype=np.uint8)
        self.seq = 0
        self.view: dict[str, Any] = {**VIEW_FIELDS, "step": 0}  # pose, sweep, ... in wire units
        self.trail: deque[list[int | None]] = deque(maxlen=TRAIL_LENGTH)  # [x mm, y mm] after every step
        self.terminal: Outgoing | None = None
        self.broadcaster = Broadcaster()
        self.ticker = Ticker()  # paces the viewers of a fast run together
        self._snapshot: Outgoing | None = None  # encoded once for every viewer that joins until the next change
        self._last_progress = 0.0

    # -- state ---------------------------------------------------------------------------------
    def load(self, states: NDArray[np.int8], saved: dict[str, Any]) -> None:
        """Start from a checkpoint (a run that has ended): the map and the saved view state."""
        self.cells = state_codes(states)
        self.seq = int(saved.get("seq", 0))
        max_range_m = self.robot.get("max_range_m") if self.robot else None
        self.view = view_from_checkpoint(saved, max_range_m)
        self.trail.extend(trail_wire(saved.get("trail", [])))
        self._snapshot = None

    def states(self) -> NDArray[np.int8]:
        """The map as viewers have it now (the live map.csv)."""
        return code_states(self.cells)

    @property
    def ended(self) -> bool:
        return self.terminal is not None

    @property
    def progress(self) -> dict[str, Any]:
        v = self.view
        return {"step": v["step"], "sim_time_s": v["t_s"], "explored": v["explored"], "frontier": v["frontier"]}

    def snapshot(self) -> dict[str, Any]:
        v = self.view
        return {
            "type": "snapshot",
            "seq": self.seq,
            "run": {**self.run, "status": self.status, "terminated_by": self.terminated_by},
            "grid": grid_view(self.grid),
            "cells": base64.b64encode(self.cells.tobytes()).decode(),
            "truth": self.truth_b64,
            "robot": self.robot,
            "pose": v["pose"],
            "trail": list(self.trail),
            "sweep": v["sweep"],
            "target": v["target"],
            "action": v["action"],
            "progress": self.progress,
            "metrics": v["metrics"],
        }

    def snapshot_message(self) -> Outgoing:
        if self._snapshot is None:
            self._snapshot = Outgoing.of(self.snapshot())
        return self._snapshot

    # -- messages from the run's body ------------------------------------------------------------
    def on_step(self, msg: dict[str, Any], text: str, wall_time: float | None = None) -> None:
        """A step as the run's body encoded it: only what changed since the step before."""
        self.seq = msg["seq"]
        if "cells" in msg:
            changes = np.asarray(msg["cells"], dtype=np.int64)
            self.cells[changes[:, 0], changes[:, 1]] = changes[:, 2]
        apply_step(self.view, msg)
        if self.view["pose"] is not None:
            self.trail.append(self.view["pose"][:2])
        self._snapshot = None
        self.broadcaster.publish(Outgoing(msg, text, wall_time=wall_time))
        now = time.monotonic()
        if now - self._last_progress >= PROGRESS_PERIOD_S:
            self._last_progress = now
            self.on_status("progress", progress=self.progress)

    def on_status(self, event: str, **extra: Any) -> None:
        """Publish a status event; ``started`` and the terminal events also change the run's status."""
        if self.terminal is not None:
            return
        if event == "started":
            self.status = "running"
        elif event in TERMINAL_EVENTS:
            self.status = event
            self.terminated_by = extra.pop("terminated_by", self.terminated_by)
            self.view["metrics"] = extra.get("metrics", self.view["metrics"])
        elif event == "speed":
            self.run["speed"] = extra["speed"]
        self._snapshot = None
        msg = {
            "type": "status",
            "seq": self.seq,
            "event": event,
            "status": self.status,
            "terminated_by": self.terminated_by,
            **extra,
        }
        item = Outgoing.of(msg)
        if event in TERMINAL_EVENTS:
            self.terminal = item
        self.broadcaster.publish(item)

    # -- viewers ---------------------------------------------------------------------------------
    def subscribe(self) -> Subscriber:
        """A new viewer: its queue starts with a snapshot (and the closing status if the run has ended)."""
        sub = Subscriber(self.queue_size)
        sub.put(self.snapshot_message())
        if self.terminal is not None:
            sub.put(self.terminal)
        else:
            self.broadcaster.add(sub)
        return sub

    def resync(self, sub: Subscriber) -> None:
        sub.reset(self.snapshot_message())

    def unsubscribe(self, sub: Subscriber) -> None:
        self.broadcaster.remove(sub)

    @property
    def viewers(self) -> int:
        return len(self.broadcaster.subscribers)
