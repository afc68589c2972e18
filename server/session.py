"""One run on its own thread: drive the step engine, publish every step, checkpoint, and finish cleanly."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robot.engine import SlamEngine, StepResult
from robot.errors import HardwareError, SonarSlamError
from robot.hardware import Hardware
from robot.mapio import atomic_write_bytes, write_map_files
from robot.metrics import score
from robot.runner import log_metadata, trajectory_csv
from robot.sensorlog import SensorLogWriter
from robot.sim import SimRobot
from server.broadcast import encode
from server.hardware import halt, open_hardware, set_speed
from server.live import GREY, TRAIL_LENGTH, LiveRun
from server.plan import RunPlan
from server.store import RunStore
from server.wire import StepDeltas, point_wire, pose_wire, sweep_wire

log = logging.getLogger("sonarslam.server")

LIVE_METRICS = ("f1", "precision", "recall", "error_ratio", "cell_errors")
STATE_FILE = "state.json"  # the viewer state that goes with the map checkpoint


def _num(value: float, digits: int) -> float | None:
    return round(float(value), digits) if math.isfinite(value) else None


def explored_share(states: NDArray[np.int8], truth: NDArray[np.int8]) -> float:
    """The share of the truly reachable area that the map shows as free."""
    reachable = truth == 0
    total = int(reachable.sum())
    return round(float((reachable & (states == 0)).sum()) / total, 4) if total else 0.0


def write_checkpoint(run_dir: Path, states: NDArray[np.int8], plan: RunPlan, rows: list[tuple[float, ...]],
                     view: dict[str, Any]) -> None:  # fmt: skip
    """The map files, the trajectory and the viewer state, each replaced atomically."""
    write_map_files(run_dir, states, plan.grid)
    atomic_write_bytes(run_dir / "trajectory.csv", trajectory_csv(rows).encode())
    atomic_write_bytes(run_dir / STATE_FILE, json.dumps(view, separators=(",", ":")).encode())


class RunSession:
    """Runs one plan to its end on a worker thread; the event loop only ever receives finished messages."""

    def __init__(
        self,
        run_id: str,
        plan: RunPlan,
        run_dir: Path,
        store: RunStore,
        live: LiveRun,
        loop: asyncio.AbstractEventLoop,
        checkpoint_interval_s: float,
        on_exit: Callable[[RunSession], None],
        pi_config_file: Path | None = None,
    ) -> None:
        self.id = run_id
        self.plan = plan
        self.run_dir = run_dir
        self.store = store
        self.live = live
        self.loop = loop
        self.checkpoint_interval_s = checkpoint_interval_s
        self.on_exit = on_exit
        self.pi_config_file = pi_config_file
        self.hw: Hardware | None = None
        self.trajectory: list[tuple[float, ...]] = []
        self.states = plan.grid.empty()
        self._stop = threading.Event()
        self._stop_reason = "stopped"
        self._halted = False  # real motors were halted by a stop request
        self._speed = plan.speed
        self._trail: deque[list[float | None]] = deque(maxlen=TRAIL_LENGTH)
        self._deltas = StepDeltas()
        self._last: tuple[StepResult, int, dict[str, Any] | None, float | None] | None = None  # the latest step
        self.thread = threading.Thread(target=self._main, name=f"run-{run_id}", daemon=True)

    # -- control (any thread) --------------------------------------------------------------------
    def start(self) -> None:
        self.thread.start()

    def request_stop(self, reason: str = "stopped") -> None:
        """End after the current step; the step finishes at full speed so that stopping is prompt.

        Real motors stop at once: the robot's next hardware call in the step fails, and the run ends
        as stopped with the map it has (rather than driving on to the end of a cell move)."""
        if not self._stop.is_set():
            self._stop_reason = reason
            self._stop.set()
        hw = self.hw
        if hw is not None:
            set_speed(hw, None)
            if halt(hw, f"run {reason}"):
                self._halted = True

    def set_speed(self, speed: float | None) -> None:
        self._speed = speed
        hw = self.hw
        if hw is not None and not self._stop.is_set():
            set_speed(hw, speed)

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    # -- the run thread -----------------------------------------------------------------------------
    def _post(self, fn: Callable[..., None], *args: Any, **kwargs: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the loop has closed: the service is going away
            self.loop.call_soon_threadsafe(lambda: fn(*args, **kwargs))

    def _record(self, engine: SlamEngine, hw: Hardware) -> None:
        est = engine.pose
        true = hw.true_pose if isinstance(hw, SimRobot) else None
        tx, ty, tt = (true.x, true.y, true.theta) if true is not None else (math.nan, math.nan, math.nan)
        self.trajectory.append((hw.now(), est.x, est.y, est.theta, tx, ty, tt))

    def _metrics(self) -> dict[str, Any] | None:
        if self.plan.truth is None:
            return None
        m = score(self.states, self.plan.truth).as_dict()
        return {k: (round(m[k], 4) if isinstance(m[k], float) else m[k]) for k in LIVE_METRICS}

    def _step_message(self, r: StepResult, seq: int, metrics: dict[str, Any] | None, explored: float | None
                      ) -> dict[str, Any]:  # fmt: skip
        """The wire message: the step's values in the protocol's units, only those that changed."""
        codes = np.where(r.changed_states < 0, GREY, r.changed_states)
        cells = np.column_stack([r.changed_rows, r.changed_cols, codes]).tolist() if codes.size else []
        sweep = r.sweep_ranges_m
        values = {
            "t_s": _num(r.t_s, 2),
            "pose": pose_wire(r.pose.x, r.pose.y, r.pose.theta),
            "sweep": sweep_wire(sweep, self.plan.robot.sonar.max_range_m) if sweep is not None else None,
            "target": point_wire(*r.target_xy) if r.target_xy is not None else None,
            "action": r.action,
            "explored": explored,
            "frontier": r.frontier_cells,
            "metrics": metrics,
        }
        return self._deltas.message(seq, r.step, values, cells)

    @staticmethod
    def _view_of(r: StepResult, seq: int, metrics: dict[str, Any] | None, explored: float | None
                 ) -> dict[str, Any]:  # fmt: skip
        """What a viewer sees after this step, in metres and radians, as the checkpoint keeps it."""
        sweep = r.sweep_ranges_m
        return {
            "seq": seq,
            "pose": {"x": _num(r.pose.x, 4), "y": _num(r.pose.y, 4), "theta": _num(r.pose.theta, 4)},
            "sweep": [_num(v, 3) for v in sweep] if sweep is not None else None,
            "target": [_num(v, 4) for v in r.target_xy] if r.target_xy is not None else None,
            "action": r.action,
            "progress": {"step": r.step, "sim_time_s": _num(r.t_s, 2), "explored": explored,
                         "frontier": r.frontier_cells},
            "metrics": metrics,
        }  # fmt: skip

    def _publish(self, r: StepResult, seq: int, metrics: dict[str, Any] | None, explored: float | None
                 ) -> tuple[dict[str, Any] | None, float | None]:  # fmt: skip
        """Fold a step into the run's map and hand its message to the event loop; returns the new scores."""
        if r.changed_rows.size:
            self.states[r.changed_rows, r.changed_cols] = r.changed_states
            metrics = self._metrics()
            explored = explored_share(self.states, self.plan.truth) if self.plan.truth is not None else None
        msg = self._step_message(r, seq, metrics, explored)
        self._last = (r, seq, metrics, explored)
        self._trail.append([_num(r.pose.x, 4), _num(r.pose.y, 4)])
        self._post(self.live.on_step, msg, encode(msg), round(time.time(), 4))
        return metrics, explored

    def _checkpoint(self, recorder: SensorLogWriter | None) -> None:
        if recorder is not None:
            recorder.flush()
        view: dict[str, Any] = self._view_of(*self._last) if self._last is not None else {"seq": 0}
        write_checkpoint(self.run_dir, self.states, self.plan, self.trajectory, {**view, "trail": list(self._trail)})
        progress = view.get("progress") or {}
        self.store.update(
            self.id,
            steps=int(progress.get("step", 0)),
            sim_time_s=float(progress.get("sim_time_s") or 0.0),
            explored=progress.get("explored"),
            frontier=progress.get("frontier"),
        )

    def _main(self) -> None:
        plan = self.plan
        wall0 = time.monotonic()
        recorder: SensorLogWriter | None = None
        status, terminated_by, error = "error", None, None
        try:
            if self._stop.is_set():  # stopped while queued
                status, terminated_by = self._end_status()
                return
            self.hw = hw = open_hardware(plan, self.pi_config_file)
            set_speed(hw, None if self._stop.is_set() else self._speed)
            extra = {"world": plan.world.name if plan.world else None, "seed": plan.options["seed"]}
            meta = log_metadata(plan.robot, plan.frame, {**extra, "slam": plan.slam.model_dump()})
            recorder = SensorLogWriter(self.run_dir / "sensors.log", meta)
            engine = SlamEngine(hw, plan.robot, plan.slam, plan.frame, recorder=recorder)
            self.store.update(self.id, status="running", started_at=time.time())
            self._post(self.live.on_status, "started")
            self._record(engine, hw)
            metrics, explored = self._metrics(), 0.0 if plan.truth is not None else None
            last_checkpoint = time.monotonic()
            seq = 0
            while not engine.done:
                if self._stop.is_set():
                    # Stopping settles the map once more: its last changes go out as one more step.
                    final = engine.stop(self._stop_reason)
                    if isinstance(final, StepResult):
                        seq += 1
                        metrics, explored = self._publish(final, seq, metrics, explored)
                    break
                try:
                    r = engine.step()
                except HardwareError:
                    if self._halted:
                        continue  # a stop halted the motors mid-step: settle the map and end as stopped
                    raise
                self._record(engine, hw)
                seq += 1
                metrics, explored = self._publish(r, seq, metrics, explored)
                if time.monotonic() - last_checkpoint >= self.checkpoint_interval_s:
                    self._checkpoint(recorder)
                    last_checkpoint = time.monotonic()
            status, terminated_by = self._end_status(engine.stats.terminated_by)
        except SonarSlamError as exc:  # an expected failure (a device missing, a bad setting): one line
            log.error("run %s failed: %s: %s", self.id, type(exc).__name__, exc)
            status, terminated_by, error = "error", "error", f"{type(exc).__name__}: {exc}"
        except Exception as exc:
            log.exception("run %s failed", self.id)
            status, terminated_by, error = "error", "error", f"{type(exc).__name__}: {exc}"
        finally:
            self._finish(recorder, status, terminated_by, error, time.monotonic() - wall0)

    def _end_status(self, engine_reason: str | None = None) -> tuple[str, str]:
        if self._stop.is_set() and engine_reason in (None, self._stop_reason):
            return ("interrupted", "shutdown") if self._stop_reason == "shutdown" else ("stopped", "stopped")
        return "finished", engine_reason or "complete"

    def _finish(self, recorder: SensorLogWriter | None, status: str, terminated_by: str | None, error: str | None,
                wall_time_s: float) -> None:  # fmt: skip
        """Write the final files, then record the status, then tell the viewers: in that order, so that
        whoever hears "finished" can download the final map at once."""
        metrics = None
        try:
            if recorder is not None:
                recorder.close()
            if self.hw is not None:
                self.hw.close()
            if self.plan.truth is not None:
                metrics = score(self.states, self.plan.truth).as_dict()
            self._checkpoint(None)
        except Exception as exc:
            log.exception("run %s: could not write its final files", self.id)
            status, error = "error", error or f"{type(exc).__name__}: {exc}"
        try:
            self.store.update(
                self.id,
                status=status,
                terminated_by=terminated_by,
                metrics=metrics,
                error=error,
                ended_at=time.time(),
                wall_time_s=round(wall_time_s, 3),
            )
        except Exception:
            log.exception("run %s: could not record its end", self.id)
        event: dict[str, Any] = {"terminated_by": terminated_by, "metrics": metrics}
        if error is not None:
            event["message"] = error
        self._post(self.live.on_status, status, **event)
        self._post(self.on_exit, self)
