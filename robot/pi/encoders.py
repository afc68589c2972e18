"""Wheel encoders counted from GPIO edges (quadrature, or single channel signed by the motor command)."""

from __future__ import annotations

import threading
from typing import Any

from gpiozero import InputDevice

# Why not gpiozero's RotaryEncoder: it counts one step per full quadrature cycle (a quarter of
# the edges), clamps at max_steps=16 unless told otherwise, and has no single-channel mode.
# Counting edges here lets the config choose x1/x2/x4 so that one count is exactly
# 1/encoder_counts_per_rev of a wheel revolution.

# Quadrature state = (A << 1) | B. Driving forward, A leads B: 00 -> 10 -> 11 -> 01 -> 00.
_FORWARD = {(0b00, 0b10), (0b10, 0b11), (0b11, 0b01), (0b01, 0b00)}


class QuadratureDecoder:
    """Turns edges into signed counts. Pure logic, so it is tested without pins.

    x4 counts every edge of A and B; x2 every edge of A; x1 rising edges of A. Without B, the
    sign comes from ``direction`` (the sign of the last non-zero motor command).
    """

    def __init__(self, decoding: str, a: int, b: int | None) -> None:
        if decoding not in ("x1", "x2", "x4"):
            raise ValueError(f"unknown decoding {decoding!r}")
        if decoding == "x4" and b is None:
            raise ValueError("x4 decoding needs channel B")
        self.decoding = decoding
        self.a = int(bool(a))
        self.b = None if b is None else int(bool(b))
        self.direction = 1
        self.missed = 0  # an edge reported the level the pin already had: the opposite edge was lost

    def on_a(self, level: int) -> int:
        level = int(bool(level))
        if level == self.a:
            self.missed += 1
            return 0
        old = self._state()
        self.a = level
        if self.b is None:
            return self.direction if (self.decoding == "x2" or level) else 0
        if self.decoding == "x1":
            return (1 if self.b == 0 else -1) if level else 0
        return self._step(old)

    def on_b(self, level: int) -> int:
        level = int(bool(level))
        if self.b is None:
            return 0
        if level == self.b:
            self.missed += 1
            return 0
        old = self._state()
        self.b = level
        return self._step(old) if self.decoding == "x4" else 0

    def _state(self) -> int:
        return (self.a << 1) | (self.b or 0)

    def _step(self, old: int) -> int:
        # One pin changes per edge, so every transition is a Gray-code neighbour: forward or back.
        return 1 if (old, self._state()) in _FORWARD else -1


class WheelEncoder:
    """One wheel's encoder on gpiozero input pins; ``count`` is safe to read from any thread."""

    def __init__(
        self,
        a_pin: int,
        b_pin: int | None = None,
        *,
        decoding: str = "x4",
        reversed: bool = False,
        pull_up: bool = True,
        pin_factory: Any = None,
    ) -> None:
        self._lock = threading.Lock()
        self._count = 0
        self._sign = -1 if reversed else 1
        self._devices: list[Any] = []
        try:
            a = self._input(a_pin, pull_up, pin_factory)
            b = None if b_pin is None else self._input(b_pin, pull_up, pin_factory)
            self._decoder = QuadratureDecoder(decoding, a.pin.state, None if b is None else b.pin.state)
            a.pin.when_changed = self._on_a  # bound methods: gpiozero holds them weakly
            if b is not None:
                b.pin.when_changed = self._on_b
        except BaseException:
            self.close()
            raise

    def _input(self, pin: int, pull_up: bool, pin_factory: Any) -> Any:
        device = InputDevice(pin, pull_up=pull_up, pin_factory=pin_factory)
        self._devices.append(device)
        device.pin.edges = "both"
        device.pin.bounce = None
        return device

    def _on_a(self, ticks: float, level: int) -> None:
        with self._lock:
            self._count += self._sign * self._decoder.on_a(level)

    def _on_b(self, ticks: float, level: int) -> None:
        with self._lock:
            self._count += self._sign * self._decoder.on_b(level)

    @property
    def count(self) -> int:
        """Cumulative signed counts; positive = wheel driving forward."""
        with self._lock:
            return self._count

    @property
    def missed_edges(self) -> int:
        with self._lock:
            return self._decoder.missed

    def set_direction(self, wheel_sign: float) -> None:
        """Single-channel encoders: the sign of the wheel command. Zero keeps the last sign, since
        a wheel coasting to a stop still turns the way it was driven."""
        if wheel_sign:
            with self._lock:
                # The decoder counts in pin terms; undo the mounting sign so forward stays positive.
                self._decoder.direction = (1 if wheel_sign > 0 else -1) * self._sign

    def close(self) -> None:
        for device in self._devices:
            device.close()
        self._devices.clear()
