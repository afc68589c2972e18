"""HC-SR04 sonars on GPIO: one trigger pulse, echo width timed from edge timestamps (gpiozero pins)."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from functools import partial
from typing import Any

from gpiozero import DigitalOutputDevice, InputDevice

from robot.pi.sonar import Ping

# Why not gpiozero's DistanceSensor: it starts a background thread per sensor that pings every
# 60 ms forever and reports a median of queued readings, and its class-level ECHO_LOCK only
# serialises pings back to back with no gap. The SLAM loop needs one fresh reading per sensor per
# sweep, in a staggered order, with a quiet gap between pings, and it must know "no echo" from
# "no sensor". So this bank drives the trigger with a DigitalOutputDevice and times the echo from
# the edge timestamps gpiozero hands to ``pin.when_changed`` (kernel timestamps under lgpio).

TRIGGER_PULSE_S = 10e-6  # datasheet minimum trigger width
ECHO_RISE_S = 0.005  # the echo line rises about 0.5 ms after the trigger; allow for slow modules


class HcSr04Bank:
    """Several HC-SR04s pinged one at a time. ``echo_pins[i]`` may all be the same pin (diode-OR)."""

    def __init__(
        self,
        trigger_pins: Sequence[int],
        echo_pins: Sequence[int],
        *,
        max_range_m: float,
        speed_of_sound_m_s: float = 343.0,
        pin_factory: Any = None,
    ) -> None:
        if len(trigger_pins) != len(echo_pins):
            raise ValueError("need one echo pin per trigger pin (repeat a shared echo pin)")
        self.max_range_m = max_range_m
        self.speed_of_sound_m_s = speed_of_sound_m_s
        # Waiting for the echo ends once the pulse is longer than max range: no need to sit out the
        # module's own 38 ms "nothing heard" pulse.
        self.echo_timeout_s = ECHO_RISE_S + 2.0 * max_range_m / speed_of_sound_m_s + 0.002
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._armed = False
        self._active_echo = -1
        self._rise: float | None = None
        self._fall: float | None = None
        self._triggers: list[Any] = []
        self._echoes: list[Any] = []
        self._echo_of: list[int] = []
        self._handlers: list[Any] = []  # gpiozero keeps only a weak reference to when_changed
        try:
            for pin in trigger_pins:
                self._triggers.append(DigitalOutputDevice(pin, initial_value=False, pin_factory=pin_factory))
            echo_index: dict[int, int] = {}
            for pin in echo_pins:
                if pin not in echo_index:
                    echo_index[pin] = len(self._echoes)
                    device = InputDevice(pin, pull_up=False, pin_factory=pin_factory)
                    device.pin.edges = "both"
                    device.pin.bounce = None
                    handler = partial(self._on_edge, echo_index[pin])
                    self._handlers.append(handler)
                    device.pin.when_changed = handler
                    self._echoes.append(device)
                self._echo_of.append(echo_index[pin])
        except BaseException:
            self.close()
            raise

    def __len__(self) -> int:
        return len(self._triggers)

    def _on_edge(self, echo: int, ticks: float, level: int) -> None:
        # Runs on gpiozero's callback thread; edges of other pins or stale pings are ignored.
        with self._lock:
            if not self._armed or echo != self._active_echo:
                return
            if level:
                self._rise = ticks
            elif self._rise is not None:
                self._fall = ticks
                self._armed = False
                self._done.set()

    def ping(self, index: int) -> Ping:
        echo = self._echoes[self._echo_of[index]]
        if echo.pin.state and not self._wait_low(echo):
            return Ping(self.max_range_m, "no-response")  # echo stuck high: broken module or wiring
        with self._lock:
            self._active_echo = self._echo_of[index]
            self._rise = self._fall = None
            self._done.clear()
            self._armed = True
        trigger = self._triggers[index]
        trigger.on()
        time.sleep(TRIGGER_PULSE_S)
        trigger.off()
        heard = self._done.wait(self.echo_timeout_s)
        with self._lock:
            self._armed = False
            rise, fall = self._rise, self._fall
        if not heard or rise is None or fall is None:
            # A live module always raises its echo line; one that never rose is not answering.
            return Ping(self.max_range_m, "no-echo" if rise is not None else "no-response")
        width_s = echo.pin_factory.ticks_diff(fall, rise)
        range_m = width_s * self.speed_of_sound_m_s / 2.0
        if range_m >= self.max_range_m:
            return Ping(self.max_range_m, "no-echo")
        return Ping(max(range_m, 0.0), "echo")

    def _wait_low(self, echo: Any) -> bool:
        """Some clones hold the echo high for up to 200 ms after a ping that heard nothing."""
        deadline = time.monotonic() + 0.25
        while echo.pin.state:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.001)
        return True

    def close(self) -> None:
        for device in (*self._triggers, *self._echoes):
            device.close()
        self._triggers.clear()
        self._echoes.clear()
