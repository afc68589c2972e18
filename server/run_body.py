"""One run's body: drive the step engine, post every step, checkpoint, and finish cleanly.

It runs where its handle (``server/session.py``) puts it: on a thread of the service for real hardware,
in a child process of its own for the simulator (``run_in_child``). Either way it hands over finished
messages only, through ``post``, and takes stop and speed requests from any thread.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robot.engine import SlamEngine, StepResult
from robot.errors import HardwareError, SonarSlamError
from robot.hardware import Hardware
from robot.mapio import atomic_write_bytes, read_csv, write_map_files
from robot.metrics import score
from robot.runner import log_metadata, trajectory_csv
from robot.sensorlog import SensorLogWriter
from robot.sim import SimRobot
from server.broadcast import encode
from server.engine_process import Listen, Message
from server.hardware import halt, open_hardware, set_speed
from server.live import GREY, TRAIL_LENGTH
from server.plan import RunPlan
from server.store import RunStore
from server.wire import StepDeltas, point_wire, pose_wire, sweep_wire

log = logging.getLogger("sonarslam.server")

LIVE_METRICS = ("f1", "precision", "recall", "error_ratio", "cell_errors")
STATE_FILE = "state.json"  # the viewer state that goes with the map checkpoint

# What a body posts, in order: ("status", event, extra), then ("step", message, text, wall_time, rows) for
# every step (``rows``: the trajectory rows recorded since the step before), and a terminal status last.
Post = Callable[[Message], None]


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


def truncate_to_last_line(path: Path) -> None:
    """A log cut by a crash may end mid-record; drop the partial line so that replay can read it."""
    if not path.exists():
        return
    data = path.read_bytes()
    cut = data.rfind(b"\n") + 1
    if cut < len(data):
        with open(path, "r+b") as fh:
            fh.truncate(cut)


def checkpoint_metrics(run_dir: Path) -> dict[str, Any] | None:
    """The scores of a run's last checkpoint, for a run whose body ended without scoring its map."""
    truth_path = run_dir / "truth.csv"
    if not (run_dir / "map.csv").exists() or not truth_path.exists():
        return None
    return score(read_csv(run_dir / "map.csv"), read_csv(truth_path)).as_dict()


@dataclass(frozen=True)
class RunJob:
    """What a run's body needs besides a store and somewhere to post: all of it travels to a child process."""

    id: str
    plan: RunPlan
    run_dir: Path
    checkpoint_interval_s: float  # map checkpoint period [s wall]
    pi_config_file: Path | None = None


class RunBody:
    """Runs one plan to its end on the calling thread; hands every message to ``post``. ``request_stop`` and
    ``set_speed`` may be called from any other thread meanwhile."""

    def __init__(self, job: RunJob, store: RunStore, post: Post, speed: float | None = None) -> None:
        self.job = job
        self.id, self.plan, self.run_dir = job.id, job.plan, job.run_dir
        self.store = store
        self.post = post
        self.hw: Hardware | None = None
        self.trajectory: list[tuple[float, ...]] = []
        self.states = job.plan.grid.empty()
        self._stop = threading.Event()
        self._stop_reason = "stopped"
        self._halted = False  # real motors were halted by a stop request
        self._speed = speed
        self._trail: deque[list[float | None]] = deque(maxlen=TRAIL_LENGTH)
        self._deltas = StepDeltas()
        self._last: tuple[StepResult, int, dict[str, Any] | None, float | None] | None = None  # the latest step
        self._posted_rows = 0  # trajectory rows already posted with a step

    # -- control (any thread) --------------------------------------------------------------------
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

    # -- the run ---------------------------------------------------------------------------------
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
        """Fold a step into the run's map and post its message; returns the new scores."""
        if r.changed_rows.size:
            self.states[r.changed_rows, r.changed_cols] = r.changed_states
            metrics = self._metrics()
            explored = explored_share(self.states, self.plan.truth) if self.plan.truth is not None else None
        msg = self._step_message(r, seq, metrics, explored)
        self._last = (r, seq, metrics, explored)
        self._trail.append([_num(r.pose.x, 4), _num(r.pose.y, 4)])
        rows = self.trajectory[self._posted_rows :]
        self._posted_rows = len(self.trajectory)
        self.post(("step", msg, encode(msg), round(time.time(), 4), rows))
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

    def run(self) -> None:
        plan = self.plan
        wall0 = time.monotonic()
        recorder: SensorLogWriter | None = None
        status, terminated_by, error = "error", None, None
        try:
            if self._stop.is_set():  # stopped while queued
                status, terminated_by = self._end_status()
                return
            self.hw = hw = open_hardware(plan, self.job.pi_config_file)
            set_speed(hw, None if self._stop.is_set() else self._speed)
            extra = {"world": plan.world.name if plan.world else None, "seed": plan.options["seed"]}
            meta = log_metadata(plan.robot, plan.frame, {**extra, "slam": plan.slam.model_dump()})
            recorder = SensorLogWriter(self.run_dir / "sensors.log", meta)
            engine = SlamEngine(hw, plan.robot, plan.slam, plan.frame, recorder=recorder)
            self.store.update(self.id, status="running", started_at=time.time())
            self.post(("status", "started", {}))
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
                if time.monotonic() - last_checkpoint >= self.job.checkpoint_interval_s:
                    self._checkpoint(recorder)
                    last_checkpoint = time.monotonic()
            status, terminated_by = self._end_status(engine.stats.terminated_by)
        except SonarSlamError as exc:  # an expected failure (a device missing, a bad setting): one line
            if isinstance(exc, HardwareError) and self._halted:
                # A stop halted the motors while the run was setting up: it ends as stopped.
                log.info("run %s stopped while starting (%s)", self.id, exc)
                status, terminated_by = self._end_status()
            else:
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
        self.post(("status", status, event))


def run_in_child(job: RunJob, db_path: Path, speed: float | None, post: Post, listen: Listen) -> None:
    """A simulated run's body in its child process, with a store connection of its own (SQLite's WAL lets
    the service and its children write one database), taking stop and speed orders from its handle."""
    store = RunStore(db_path)
    body = RunBody(job, store, post, speed)

    def obey(order: Message) -> None:
        kind, value = order
        if kind == "stop":
            body.request_stop(value)
        elif kind == "speed":
            body.set_speed(value)

    listen(obey)
    try:
        body.run()
    finally:
        store.close()
