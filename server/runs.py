"""The run manager: accepts runs, queues them within the concurrency limit, stops, deletes and recovers them."""

from __future__ import annotations

import asyncio
import json
import logging
import shutil
from collections import deque
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from robot.grid import GridSpec
from robot.mapio import atomic_write_bytes, read_csv, write_csv
from robot.settings import load_run_config
from server.downloads import MEDIA_TYPES
from server.engine_process import warm_up
from server.errors import ApiError, conflict, not_found
from server.hardware import halt
from server.live import LiveRun, robot_view
from server.models import ConfigUpdate, GridInfo, Progress, RunCreate, RunDefaults, RunView
from server.plan import RunPlan, merge_options, validate_options
from server.run_body import RunJob, checkpoint_metrics, truncate_to_last_line, write_checkpoint
from server.session import RunSession
from server.settings import ServerSettings
from server.store import ACTIVE, RunRecord, RunStore
from server.worlds import WorldCatalog

log = logging.getLogger("sonarslam.server")

DEFAULTS_KEY = "run_defaults"
DEFAULT_WORLD = "room1"
DEFAULT_SPEED = 10.0  # real-time factor: fast enough to watch a whole room, slow enough to follow
STOP_WAIT_S = 30.0  # how long stop, delete and shutdown wait for a run to end


def iso(t: float | None) -> str | None:
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds") if t is not None else None


class RunManager:
    """Owns every run of this service. Lives on the event loop; runs report back through it."""

    def __init__(self, settings: ServerSettings, store: RunStore, catalog: WorldCatalog) -> None:
        self.settings = settings
        self.store = store
        self.catalog = catalog
        self.runs_dir = settings.data_dir / "runs"
        self.sessions: dict[str, RunSession] = {}  # queued or running
        self.lives: dict[str, LiveRun] = {}
        self._queue: deque[str] = deque()
        self._running: set[str] = set()
        self._ended: dict[str, asyncio.Event] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._robot_lock = asyncio.Lock()  # real hardware: one run at a time

    # -- lifecycle -------------------------------------------------------------------------------
    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self.runs_dir.mkdir(parents=True, exist_ok=True)
        if self._engine_in_child:
            warm_up()  # in the background: only a run asked for in its first second or two waits for it
        await asyncio.to_thread(self.recover)

    @property
    def _engine_in_child(self) -> bool:
        """Whether runs' bodies run in child processes (a run's plan has the service's hardware)."""
        return self.settings.hardware == "sim" and self.settings.sim_engine == "process"

    def recover(self) -> None:
        """After a crash: runs that were in progress become ``interrupted``, with their last checkpoint."""
        for run_id in self.store.mark_interrupted():
            run_dir = self.run_dir(run_id)
            try:
                truncate_to_last_line(run_dir / "sensors.log")
                metrics = checkpoint_metrics(run_dir)
                if metrics is not None:
                    self.store.update(run_id, metrics=metrics)
            except Exception:
                log.exception("run %s: could not tidy its checkpoint", run_id)
            log.warning("run %s was interrupted by a restart; its last checkpoint is kept", run_id)

    async def shutdown(self) -> None:
        """Stop every run (they end as ``interrupted`` with their map saved) and wait for them to end."""
        for session in list(self.sessions.values()):
            session.request_stop("shutdown")
            if session.id in self._queue:  # never started: it ends at once
                session.start()
        self._queue.clear()
        for session in list(self.sessions.values()):
            if not await self._wait_ended(session.id):
                session.abandon()
        for live in self.lives.values():
            live.broadcaster.close_all()

    def halt_hardware(self, reason: str) -> None:
        """Stop real motors now and end their runs: for a signal handler on the loop's thread, because
        the graceful shutdown first waits for open connections before it stops the runs."""
        for session in list(self.sessions.values()):
            if session.plan.hardware == "sim":
                continue  # nothing moves; the shutdown interrupts it as usual
            session.request_stop("shutdown")  # a run between steps ends as interrupted, one mid-step as error
            hw = session.hw
            if hw is not None and halt(hw, reason):
                log.warning("run %s: %s: motors stopped", session.id, reason)

    # -- defaults --------------------------------------------------------------------------------
    def builtin_defaults(self) -> RunDefaults:
        slam = load_run_config(self.settings.run_config_file).slam
        return RunDefaults(
            world=DEFAULT_WORLD,
            mapper=slam.mapper,
            resolution=slam.resolution,
            seed=0,
            speed=DEFAULT_SPEED,
            time_limit_s=slam.time_limit_s,
            noise={},
            max_steps=slam.max_steps,
            end_when_mapped=slam.end_when_mapped,
        )

    def defaults(self) -> RunDefaults:
        stored = self.store.get_setting(DEFAULTS_KEY)
        base = self.builtin_defaults()
        if stored is None:
            return base
        try:
            return RunDefaults.model_validate(base.model_dump() | stored)
        except ValueError:
            log.warning("ignoring stored run defaults that no longer validate")
            return base

    def _validate(self, options: dict[str, Any], with_truth: bool) -> RunPlan:
        s = self.settings
        return validate_options(
            options,
            self.catalog,
            s.hardware,
            s.run_config_file,
            s.max_grid_cells,
            s.pi_config_file,
            with_truth=with_truth,
        )

    async def update_defaults(self, update: ConfigUpdate) -> RunDefaults:
        options = merge_options(self.defaults(), update)
        await asyncio.to_thread(self._validate, options, False)
        defaults = RunDefaults.model_validate(options)
        self.store.put_setting(DEFAULTS_KEY, defaults.model_dump())
        return defaults

    # -- runs ------------------------------------------------------------------------------------
    def run_dir(self, run_id: str) -> Path:
        return self.runs_dir / run_id

    def record(self, run_id: str) -> RunRecord:
        record = self.store.get(run_id)
        if record is None:
            raise not_found(f"run {run_id}")
        return record

    async def create(self, body: RunCreate) -> RunRecord:
        if self.settings.hardware == "sim":
            return await self._create(body)
        # One robot: a second run is refused rather than queued, since a queued run would set off on
        # its own when the first one ends. Checked and claimed under the lock, so two requests cannot
        # both get it while the first is still being validated.
        async with self._robot_lock:
            holder = next(iter(self.sessions), None)
            if holder is not None:
                raise conflict(f"the robot is busy with run {holder}; stop it before starting another")
            return await self._create(body)

    async def _create(self, body: RunCreate) -> RunRecord:
        if len(self._queue) >= self.settings.max_queued_runs and len(self._running) >= self.settings.concurrent_runs:
            raise ApiError(429, f"{len(self._queue)} runs are already waiting; try again when one has ended")
        options = merge_options(self.defaults(), body)
        plan = await asyncio.to_thread(self._validate, options, True)
        if plan.hardware != "sim":
            options["world"] = None
        g = plan.grid
        grid = {"rows": g.rows, "cols": g.cols, "resolution": g.resolution, "origin": [g.origin_x, g.origin_y]}
        record = self.store.create_run(plan.hardware, options["world"], options, grid)
        run_dir = self.run_dir(record.id)
        await asyncio.to_thread(self._prepare_dir, run_dir, plan)
        live = LiveRun(
            {
                "id": record.id,
                "world": options["world"],
                "mapper": options["mapper"],
                "hardware": plan.hardware,
                "resolution": g.resolution,
                "speed": options["speed"],
                "seed": options["seed"],
            },
            g,
            robot_view(plan.robot),
            plan.truth,
            self.settings.ws_queue_size,
        )
        assert self._loop is not None
        job = RunJob(record.id, plan, run_dir, self.settings.checkpoint_interval_s, self.settings.pi_config_file)
        session = RunSession(job, self.store, live, self._loop, self._on_exit, self._engine_in_child)
        self.sessions[record.id] = session
        self.lives[record.id] = live
        self._ended[record.id] = asyncio.Event()
        self._queue.append(record.id)
        self._pump()
        return record

    @staticmethod
    def _prepare_dir(run_dir: Path, plan: RunPlan) -> None:
        """The run's folder before it starts: its world, its truth and an empty first checkpoint."""
        run_dir.mkdir(parents=True, exist_ok=True)
        if plan.world_text is not None:
            atomic_write_bytes(run_dir / "world.toml", plan.world_text.encode("utf-8"))
        if plan.truth is not None:
            write_csv(run_dir / "truth.csv", plan.truth)
        atomic_write_bytes(run_dir / "robot.json", json.dumps(robot_view(plan.robot)).encode())
        write_checkpoint(run_dir, plan.grid.empty(), plan, [], {"seq": 0})

    def _pump(self) -> None:
        while self._queue and len(self._running) < self.settings.concurrent_runs:
            run_id = self._queue.popleft()
            self._running.add(run_id)
            self.sessions[run_id].start()

    def _on_exit(self, session: RunSession) -> None:
        """Called on the loop once a run has published its end."""
        self._running.discard(session.id)
        self.sessions.pop(session.id, None)
        live = self.lives.pop(session.id, None)
        if live is not None:
            live.broadcaster.close_all()  # viewers still get what is queued, ending with the closing status
        event = self._ended.pop(session.id, None)
        if event is not None:
            event.set()
        self._pump()

    async def _wait_ended(self, run_id: str) -> bool:
        """Wait for a run to end; False if it did not within ``STOP_WAIT_S``."""
        event = self._ended.get(run_id)
        if event is not None:
            try:
                await asyncio.wait_for(event.wait(), STOP_WAIT_S)
            except TimeoutError:
                log.warning("run %s did not end within %.0f s of being stopped", run_id, STOP_WAIT_S)
                return False
        return True

    async def stop(self, run_id: str) -> RunRecord:
        record = self.record(run_id)
        session = self.sessions.get(run_id)
        if session is None:
            raise conflict(f"run {run_id} has already ended ({record.status})")
        session.request_stop("stopped")
        if run_id in self._queue:  # never started: it ends at once
            self._queue.remove(run_id)
            self._running.add(run_id)
            session.start()
        await self._wait_ended(run_id)
        return self.record(run_id)

    async def delete(self, run_id: str) -> None:
        self.record(run_id)
        if run_id in self.sessions:
            await self.stop(run_id)
        self.store.delete(run_id)
        await asyncio.to_thread(shutil.rmtree, self.run_dir(run_id), True)

    def set_speed(self, run_id: str, speed: float | str) -> RunRecord:
        record = self.record(run_id)
        session = self.sessions.get(run_id)
        if session is None or session.stopping:
            raise conflict(f"run {run_id} has ended ({record.status}); its speed cannot change")
        if record.hardware != "sim":
            raise ApiError(409, "speed applies to simulated runs only", ["body", "speed"])
        session.set_speed(None if speed == "max" else float(speed))
        config = dict(record.config, speed=speed)
        self.store.update(run_id, config=config)
        live = self.lives.get(run_id)
        if live is not None:
            live.on_status("speed", speed=speed)
        return self.record(run_id)

    # -- views -----------------------------------------------------------------------------------
    def view(self, record: RunRecord) -> RunView:
        cfg = record.config
        live = self.lives.get(record.id)
        if live is not None and record.status in ACTIVE:
            p = live.progress
            progress = Progress(
                step=p.get("step", 0), sim_time_s=p.get("sim_time_s") or 0.0,
                explored=p.get("explored"), frontier=p.get("frontier"),
            )  # fmt: skip
        else:
            progress = Progress(
                step=record.steps, sim_time_s=record.sim_time_s, explored=record.explored, frontier=record.frontier
            )
        return RunView(
            id=record.id,
            status=record.status,  # type: ignore[arg-type]
            hardware=record.hardware,  # type: ignore[arg-type]
            world=record.world,
            mapper=cfg["mapper"],
            resolution=cfg["resolution"],
            seed=cfg["seed"],
            speed=cfg["speed"],
            time_limit_s=cfg["time_limit_s"],
            noise=cfg["noise"],
            max_steps=cfg.get("max_steps", 0),
            end_when_mapped=cfg.get("end_when_mapped", True),
            grid=GridInfo(**record.grid),
            created_at=iso(record.created_at) or "",
            started_at=iso(record.started_at),
            ended_at=iso(record.ended_at),
            wall_time_s=record.wall_time_s,
            progress=progress,
            terminated_by=record.terminated_by,
            metrics=record.metrics,
            error=record.error,
            downloads={name: f"/api/runs/{record.id}/{name}" for name in MEDIA_TYPES},
        )

    def list_views(self) -> list[RunView]:
        return [self.view(r) for r in self.store.list_runs()]

    def live_view(self, run_id: str) -> LiveRun | None:
        return self.lives.get(run_id)

    def read_view_state(self, run_id: str) -> dict[str, Any]:
        path = self.run_dir(run_id) / "state.json"
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            return data if isinstance(data, dict) else {}
        except (OSError, ValueError):
            return {}

    def ended_live(self, record: RunRecord) -> LiveRun:
        """A closed view of an ended run from its files: its final (or last checkpointed) map and state."""
        run_dir = self.run_dir(record.id)
        g = record.grid
        grid = GridSpec(g["origin"][0], g["origin"][1], g["resolution"], g["rows"], g["cols"])
        try:
            robot = json.loads((run_dir / "robot.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            robot = None
        truth = read_csv(run_dir / "truth.csv", grid.shape) if (run_dir / "truth.csv").exists() else None
        cfg = record.config
        run = {
            "id": record.id, "world": record.world, "mapper": cfg["mapper"], "hardware": record.hardware,
            "resolution": cfg["resolution"], "speed": cfg["speed"], "seed": cfg["seed"],
        }  # fmt: skip
        live = LiveRun(run, grid, robot, truth, queue_size=8, status=record.status)
        states = read_csv(run_dir / "map.csv", grid.shape) if (run_dir / "map.csv").exists() else grid.empty()
        live.load(states, self.read_view_state(record.id))
        extra: dict[str, Any] = {"terminated_by": record.terminated_by, "metrics": record.metrics}
        if record.error:
            extra["message"] = record.error
        live.on_status(record.status if record.status not in ACTIVE else "interrupted", **extra)
        return live
