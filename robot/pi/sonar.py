"""The sonar ring: fires the sensors one at a time in the staggered order with a gap between pings."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

PingStatus = Literal["echo", "no-echo", "no-response"]


@dataclass(frozen=True)
class Ping:
    """One sonar reading. ``no-echo`` is a healthy sensor that heard nothing (reported as max range);
    ``no-response`` is a sensor that did not answer at all (wiring or a dead device)."""

    range_m: float
    status: PingStatus


class SonarBank(Protocol):
    """Sensors that can be pinged one at a time by index (mounting order)."""

    def __len__(self) -> int: ...

    def ping(self, index: int) -> Ping: ...

    def close(self) -> None: ...


class SonarRing:
    """Fires every sensor once per sweep in ``firing_order``; consecutive pings start at least
    ``ping_interval_s`` apart, across sweep boundaries too, so late echoes die out before the next ping."""

    def __init__(
        self,
        bank: SonarBank,
        firing_order: Sequence[int],
        ping_interval_s: float,
        max_range_m: float,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        on_ping: Callable[[], None] | None = None,
    ) -> None:
        if sorted(firing_order) != list(range(len(bank))):
            raise ValueError(f"firing order {list(firing_order)} must list each of the {len(bank)} sensors once")
        self._bank = bank
        self.firing_order = tuple(firing_order)
        self.ping_interval_s = ping_interval_s  # start-to-start [s]
        self.max_range_m = max_range_m
        self._clock = clock
        self._sleep = sleep
        self.on_ping = on_ping  # called after every ping (the watchdog feeds on it)
        self._last_ping_s: float | None = None
        self.last_status: list[PingStatus] = ["no-echo"] * len(bank)

    def __len__(self) -> int:
        return len(self._bank)

    def sweep(self) -> NDArray[np.float64]:
        """Ranges in mounting order [m]; a missing echo reads ``max_range_m``."""
        ranges = np.full(len(self._bank), self.max_range_m, dtype=np.float64)
        for index in self.firing_order:
            if self._last_ping_s is not None:
                wait_s = self._last_ping_s + self.ping_interval_s - self._clock()
                if wait_s > 0.0:
                    self._sleep(wait_s)
            self._last_ping_s = self._clock()
            ping = self._bank.ping(index)
            ranges[index] = min(max(ping.range_m, 0.0), self.max_range_m)
            self.last_status[index] = ping.status
            if self.on_ping is not None:
                self.on_ping()
        return ranges

    def close(self) -> None:
        self._bank.close()
