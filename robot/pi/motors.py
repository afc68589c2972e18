"""The two drive motors: gpiozero ``Robot`` of PWM ``Motor``s, commanded in metres per second."""

from __future__ import annotations

import math
import threading
from typing import Any

from gpiozero import Motor, Robot

from robot.pi.config import MotorPins


def speed_to_duty(speed_m_s: float, max_speed_m_s: float, min_duty: float = 0.0) -> float:
    """Open-loop map from rim speed [m/s] to signed PWM duty in [-1, 1].

    A motor stands still below some duty (friction, the H-bridge's voltage drop) and its speed grows
    roughly linearly above it, so speeds in (0, max] map linearly onto duties in (min_duty, 1];
    0 stays 0. With ``min_duty`` 0 this is plain ``speed / max_speed``.
    """
    fraction = min(1.0, abs(speed_m_s) / max_speed_m_s)
    if fraction == 0.0:
        return 0.0
    return math.copysign(min_duty + (1.0 - min_duty) * fraction, speed_m_s)


class DriveMotors:
    """Left and right motors behind H-bridges; every method is safe to call from any thread."""

    def __init__(
        self,
        left: MotorPins,
        right: MotorPins,
        *,
        max_wheel_speed_m_s: float,
        pwm_frequency_hz: float = 1000.0,
        min_duty: float = 0.0,
        pin_factory: Any = None,
    ) -> None:
        if not 0.0 <= min_duty < 1.0:
            raise ValueError(f"min_duty must be in [0, 1), got {min_duty}")
        self.max_wheel_speed_m_s = max_wheel_speed_m_s
        self.min_duty = min_duty  # dead-band compensation, see speed_to_duty
        self._lock = threading.RLock()  # re-entrant: a signal handler may stop the motors mid-command
        motors: list[Any] = []
        try:
            for pins in (left, right):
                motor = Motor(
                    pins.forward_pin, pins.backward_pin, enable=pins.enable_pin, pwm=True, pin_factory=pin_factory
                )
                motors.append(motor)
                motor.forward_device.frequency = pwm_frequency_hz
                motor.backward_device.frequency = pwm_frequency_hz
            self._robot: Any = Robot(left=motors[0], right=motors[1], pin_factory=pin_factory)
        except BaseException:
            for motor in motors:
                motor.close()
            raise
        self._closed = False

    def set_speeds(self, left_m_s: float, right_m_s: float) -> tuple[float, float]:
        """Command rim speeds [m/s]; returns the duties applied. Non-finite input stops and raises."""
        if not (math.isfinite(left_m_s) and math.isfinite(right_m_s)):
            self.stop()
            raise ValueError(f"wheel speeds must be finite, got ({left_m_s}, {right_m_s})")
        duties = (
            speed_to_duty(left_m_s, self.max_wheel_speed_m_s, self.min_duty),
            speed_to_duty(right_m_s, self.max_wheel_speed_m_s, self.min_duty),
        )
        with self._lock:
            if not self._closed:
                self._robot.value = duties
        return duties

    @property
    def duties(self) -> tuple[float, float]:
        with self._lock:
            if self._closed:
                return (0.0, 0.0)
            left, right = self._robot.value
            return (float(left), float(right))

    def stop(self) -> None:
        with self._lock:
            if not self._closed:
                self._robot.stop()

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            try:
                self._robot.stop()
            finally:
                self._closed = True
                self._robot.close()
