"""Motor safety for a run: stop on exit, on an exception, on SIGTERM/SIGINT and when the loop stalls."""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

from robot.hardware import Hardware

log = logging.getLogger(__name__)

DEFAULT_WATCHDOG_TIMEOUT_S = 0.5
HANDLED_SIGNALS = (signal.SIGTERM, signal.SIGINT)


class Watchdog:
    """Calls ``on_expire`` once when ``feed()`` has not been called for ``timeout_s``.

    It re-arms on the next feed: a loop that stalls briefly (a slow map update) stops the wheels,
    and the wheels move again only when the loop commands them again.
    """

    def __init__(
        self,
        timeout_s: float,
        on_expire: Callable[[], None],
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if timeout_s <= 0.0:
            raise ValueError("watchdog timeout must be positive")
        self.timeout_s = timeout_s
        self._on_expire = on_expire
        self._clock = clock
        self._lock = threading.Lock()
        self._last_feed_s = clock()
        self._expired = False
        self.trips = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> Watchdog:
        self.feed()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="sonarslam-watchdog", daemon=True)
            self._thread.start()
        return self

    def feed(self) -> None:
        with self._lock:
            self._last_feed_s = self._clock()
            self._expired = False

    @property
    def expired(self) -> bool:
        with self._lock:
            return self._expired

    def _run(self) -> None:
        while True:
            with self._lock:
                remaining_s = self._last_feed_s + self.timeout_s - self._clock()
                fire = remaining_s <= 0.0 and not self._expired
                if fire:
                    self._expired = True
                    self.trips += 1
                waiting_for_feed = self._expired
            if fire:
                log.warning("control loop stalled for more than %.2f s: motors stopped", self.timeout_s)
                try:
                    self._on_expire()
                except Exception:
                    log.exception("watchdog could not stop the motors")
            if waiting_for_feed:
                remaining_s = self.timeout_s  # nothing to do until the loop feeds again
            if self._stop.wait(max(remaining_s, 0.001)):
                return

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)
        self._thread = None

    def __enter__(self) -> Watchdog:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class SafetyGuard:
    """Keeps the wheels safe for the duration of a ``with`` block around a control loop.

    On entry it starts a watchdog, feeds it from every hardware call when the hardware offers
    ``add_activity_listener`` (``PiHardware`` does; otherwise call :meth:`feed` each loop), and,
    in the main thread, installs SIGTERM/SIGINT handlers. On exit, whatever the reason, the motors
    stop and the previous handlers come back. A signal halts the hardware (no further commands),
    then runs the previous handler, or raises KeyboardInterrupt (SIGINT) / SystemExit (SIGTERM).
    Signal handlers can only be installed from the main thread; a server running the loop in a
    worker thread must stop it from its own shutdown hook instead.
    """

    def __init__(
        self,
        hardware: Hardware,
        *,
        watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
        handle_signals: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.hardware = hardware
        self.watchdog = Watchdog(watchdog_timeout_s, hardware.stop, clock=clock)
        self.handle_signals = handle_signals
        self.stop_reason: str | None = None
        self._previous: dict[int, Any] = {}

    def feed(self) -> None:
        """Tell the watchdog the loop is alive (only needed for hardware without activity listeners)."""
        self.watchdog.feed()

    def halt(self, reason: str) -> None:
        """Stop the motors for good; the hardware refuses commands afterwards if it supports that."""
        self.stop_reason = reason
        halt = getattr(self.hardware, "halt", None)
        if callable(halt):
            halt(reason)
        else:
            self.hardware.stop()

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        self.halt(f"stopped by {name}")
        previous = self._previous.get(signum)
        if callable(previous):
            previous(signum, frame)
        elif previous == signal.SIG_IGN:
            return
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt
        else:
            raise SystemExit(128 + signum)

    def __enter__(self) -> SafetyGuard:
        if self.handle_signals and threading.current_thread() is threading.main_thread():
            for signum in HANDLED_SIGNALS:
                self._previous[signum] = signal.signal(signum, self._on_signal)
        add = getattr(self.hardware, "add_activity_listener", None)
        if callable(add):
            add(self.watchdog.feed)
        self.watchdog.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        try:
            self.hardware.stop()
        finally:
            if exc is not None and self.stop_reason is None:
                self.stop_reason = f"stopped by {type(exc).__name__}: {exc}"
                log.warning("run ended by an exception, motors stopped: %s", self.stop_reason)
            self.watchdog.close()
            remove = getattr(self.hardware, "remove_activity_listener", None)
            if callable(remove):
                remove(self.watchdog.feed)
            for signum, previous in self._previous.items():
                signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
            self._previous.clear()


def safe_hardware(
    hardware: Hardware,
    *,
    watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
    handle_signals: bool = True,
) -> SafetyGuard:
    """``with safe_hardware(hw) as guard:`` run the loop; the motors stop however the block ends."""
    return SafetyGuard(hardware, watchdog_timeout_s=watchdog_timeout_s, handle_signals=handle_signals)
