"""One run as the event loop sees it: start its body, pass it stop and speed requests, apply its messages.

The body (``server/run_body.py``) runs where the handle puts it. Real hardware runs it on a thread of the
service: one run at a time, in real time, with motors that a signal handler must be able to halt. The
simulator runs it in a child process (``server/engine_process.py``), so that a max-speed engine never
holds the event loop's interpreter lock. Either way the body hands over finished messages only, and the
handle (``RunSession``) applies them to the run's ``LiveRun`` on the loop, in order.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from robot.hardware import Hardware
from server.broadcast import TERMINAL_EVENTS
from server.engine_process import EngineProcess, Message
from server.live import LiveRun
from server.run_body import RunBody, RunJob, checkpoint_metrics, run_in_child, truncate_to_last_line
from server.store import RunStore

log = logging.getLogger("sonarslam.server")


def _terminal(message: Message) -> bool:
    return message[0] == "status" and message[1] in TERMINAL_EVENTS


class RunSession:
    """One run as the event loop sees it: starts its body on a thread or in a child process, passes it stop
    and speed requests, applies its messages to ``live``, and calls ``on_exit`` once after the last.

    A child that dies without finishing (killed, or it could not start) ends the run as ``error``, with
    the map of its last checkpoint."""

    def __init__(
        self,
        job: RunJob,
        store: RunStore,
        live: LiveRun,
        loop: asyncio.AbstractEventLoop,
        on_exit: Callable[[RunSession], None],
        in_child: bool = False,
    ) -> None:
        self.job = job
        self.id, self.plan = job.id, job.plan
        self.store = store
        self.live = live
        self.loop = loop
        self.on_exit = on_exit
        self.in_child = in_child
        self.trajectory: list[tuple[float, ...]] = []  # as far as the viewers have it
        self.thread: threading.Thread | None = None
        self.child: EngineProcess | None = None
        self._stop_reason: str | None = None
        self._speed = job.plan.speed
        self._started = 0.0
        self._dying: asyncio.Task[None] | None = None
        # On a thread the body exists from the start: a signal handler may have to halt its motors.
        self.body: RunBody | None = None if in_child else self._new_body()

    def _new_body(self) -> RunBody:
        return RunBody(self.job, self.store, self._post, self._speed)

    @property
    def hw(self) -> Hardware | None:
        return self.body.hw if self.body is not None else None

    # -- control (the loop's thread; request_stop also from a signal handler) ----------------------
    def start(self) -> None:
        self._started = time.monotonic()
        if self.in_child and self._stop_reason is None:
            args = (self.job, self.store.path, self._speed)
            self.child = EngineProcess(f"run-{self.id}", run_in_child, args, self._deliver, _terminal, self._ended)
            self.child.start(self.loop)
            return
        if self.body is None:  # a simulated run stopped while queued: it ends at once, no process needed
            self.body = self._new_body()
            self.body.request_stop(self._stop_reason or "stopped")
        self.thread = threading.Thread(target=self._run_thread, args=(self.body,), name=f"run-{self.id}", daemon=True)
        self.thread.start()

    def request_stop(self, reason: str = "stopped") -> None:
        if self._stop_reason is None:
            self._stop_reason = reason
        if self.body is not None:
            self.body.request_stop(reason)
        if self.child is not None:
            self.child.order("stop", reason)

    def set_speed(self, speed: float | None) -> None:
        self._speed = speed
        if self.body is not None:
            self.body.set_speed(speed)
        if self.child is not None:
            self.child.order("speed", speed)

    @property
    def stopping(self) -> bool:
        return self._stop_reason is not None

    def abandon(self) -> None:
        """The service leaves without waiting any longer: a child goes too, and the run stays as recorded."""
        if self.child is not None:
            self.child.abandon()

    # -- messages ----------------------------------------------------------------------------------
    def _run_thread(self, body: RunBody) -> None:
        body.run()
        self._post(("exit",))

    def _post(self, message: Message) -> None:
        with contextlib.suppress(RuntimeError):  # the loop has closed: the service is going away
            self.loop.call_soon_threadsafe(self._deliver, message)

    def _deliver(self, message: Message) -> None:
        kind = message[0]
        if kind == "step":
            _, msg, text, wall_time, rows = message
            self.trajectory.extend(rows)
            self.live.on_step(msg, text, wall_time)
        elif kind == "status":
            _, event, extra = message
            self.live.on_status(event, **extra)
        elif kind == "exit":
            self.on_exit(self)

    def _ended(self, reason: str | None) -> None:
        if reason is None:
            self.on_exit(self)
        else:
            self._dying = self.loop.create_task(self._died(f"the run's engine process {reason}"))

    async def _died(self, error: str) -> None:
        log.error("run %s: %s", self.id, error)
        metrics = await asyncio.to_thread(self._record_death, error)
        self.live.on_status("error", terminated_by="error", metrics=metrics, message=error)
        self.on_exit(self)

    def _record_death(self, error: str) -> dict[str, Any] | None:
        """What the child could not do: end the run in the store, scored from its last checkpoint."""
        metrics = None
        try:
            truncate_to_last_line(self.job.run_dir / "sensors.log")
            metrics = checkpoint_metrics(self.job.run_dir)
        except Exception:
            log.exception("run %s: could not score its last checkpoint", self.id)
        try:
            self.store.update(
                self.id,
                status="error",
                terminated_by="error",
                metrics=metrics,
                error=error,
                ended_at=time.time(),
                wall_time_s=round(time.monotonic() - self._started, 3),
            )
        except Exception:
            log.exception("run %s: could not record its end", self.id)
        return metrics
